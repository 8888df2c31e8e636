//! `.npz` archives: a zip of `.npy` members, as written by `np.savez` / `np.savez_compressed`.

use std::fs::File;
use std::io::{BufReader, BufWriter, Cursor, Read, Seek, Write};
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::npy::{NpyArray, NpyElement, NpyError};

#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{path}: not a readable zip archive: {source}")]
    Zip {
        path: PathBuf,
        source: zip::result::ZipError,
    },
    #[error("{path}: key `{key}` is missing (present: {present})")]
    MissingKey {
        path: PathBuf,
        key: String,
        present: String,
    },
    #[error("{path}: key `{key}`: {source}")]
    Array {
        path: PathBuf,
        key: String,
        source: NpyError,
    },
    #[error("{path}: key `{key}` has shape {found:?}, expected {expected}")]
    Shape {
        path: PathBuf,
        key: String,
        found: Vec<usize>,
        expected: String,
    },
}

/// Reads named arrays out of an `.npz` file.
pub struct NpzReader<R: Read + Seek = BufReader<File>> {
    path: PathBuf,
    archive: zip::ZipArchive<R>,
}

impl NpzReader {
    pub fn open(path: impl AsRef<Path>) -> Result<Self, NpzError> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|source| NpzError::Io {
            path: path.clone(),
            action: "open",
            source,
        })?;
        Self::new(path, BufReader::new(file))
    }
}

impl<R: Read + Seek> NpzReader<R> {
    /// Wraps any seekable reader; `path` is only used in error messages.
    pub fn new(path: PathBuf, reader: R) -> Result<Self, NpzError> {
        let archive = zip::ZipArchive::new(reader).map_err(|source| NpzError::Zip {
            path: path.clone(),
            source,
        })?;
        Ok(Self { path, archive })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Array names (member names without the `.npy` suffix), in archive order.
    pub fn keys(&self) -> Vec<String> {
        self.archive
            .file_names()
            .map(|name| name.strip_suffix(".npy").unwrap_or(name).to_owned())
            .collect()
    }

    pub fn contains(&self, key: &str) -> bool {
        self.archive.index_for_name(&format!("{key}.npy")).is_some()
    }

    /// Reads one whole array.
    pub fn read_array(&mut self, key: &str) -> Result<NpyArray, NpzError> {
        let member = format!("{key}.npy");
        let Some(index) = self.archive.index_for_name(&member) else {
            let mut present = self.keys();
            present.sort();
            return Err(NpzError::MissingKey {
                path: self.path.clone(),
                key: key.to_owned(),
                present: present.join(", "),
            });
        };
        let mut entry = self
            .archive
            .by_index(index)
            .map_err(|source| NpzError::Zip {
                path: self.path.clone(),
                source,
            })?;
        NpyArray::read(&mut entry).map_err(|source| NpzError::Array {
            path: self.path.clone(),
            key: key.to_owned(),
            source,
        })
    }

    /// Reads an array of scalars `T` and checks its shape against `expected`, where `None`
    /// accepts any length on that axis. Returns the shape found and the values.
    pub fn read_typed<T: NpyElement>(
        &mut self,
        key: &str,
        expected: &[Option<usize>],
    ) -> Result<(Vec<usize>, Vec<T>), NpzError> {
        let array = self.read_array(key)?;
        let matches = array.shape.len() == expected.len()
            && array
                .shape
                .iter()
                .zip(expected)
                .all(|(&found, want)| want.is_none_or(|want| want == found));
        if !matches {
            return Err(NpzError::Shape {
                path: self.path.clone(),
                key: key.to_owned(),
                found: array.shape,
                expected: describe_shape(expected),
            });
        }
        let values = array.to_vec::<T>().map_err(|source| NpzError::Array {
            path: self.path.clone(),
            key: key.to_owned(),
            source,
        })?;
        Ok((array.shape, values))
    }
}

/// `(N, 2)`-style text for an expected shape; `None` axes are printed as `any`.
pub fn describe_shape(expected: &[Option<usize>]) -> String {
    let dims: Vec<String> = expected
        .iter()
        .map(|d| d.map_or_else(|| "any".to_owned(), |d| d.to_string()))
        .collect();
    match dims.as_slice() {
        [single] => format!("({single},)"),
        _ => format!("({})", dims.join(", ")),
    }
}

/// How members are stored in the zip.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NpzCompression {
    /// Like `np.savez`: fastest, largest.
    Stored,
    /// Like `np.savez_compressed`: masks and labels shrink many times over.
    #[default]
    Deflated,
}

/// Writes named arrays into a new `.npz` file; call [`NpzWriter::finish`] at the end.
pub struct NpzWriter<W: Write + Seek = BufWriter<File>> {
    path: PathBuf,
    zip: zip::ZipWriter<W>,
    compression: NpzCompression,
}

impl NpzWriter {
    pub fn create(path: impl AsRef<Path>, compression: NpzCompression) -> Result<Self, NpzError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path).map_err(|source| NpzError::Io {
            path: path.clone(),
            action: "create",
            source,
        })?;
        Ok(Self::new(path, BufWriter::new(file), compression))
    }
}

impl<W: Write + Seek> NpzWriter<W> {
    /// Wraps any seekable writer; `path` is only used in error messages.
    pub fn new(path: PathBuf, writer: W, compression: NpzCompression) -> Self {
        Self {
            path,
            zip: zip::ZipWriter::new(writer),
            compression,
        }
    }

    pub fn add_array(&mut self, key: &str, array: &NpyArray) -> Result<(), NpzError> {
        write_member(&mut self.zip, &self.path, self.compression, key, array)
    }

    /// Adds `arrays` in order, compressing up to one per core at once: the archive is the same,
    /// byte for byte, as from [`NpzWriter::add_array`] on each in turn. Deflate runs at tens of
    /// MB/s, so large arrays written one after another leave all but one core idle.
    pub fn add_arrays(&mut self, arrays: &[(&str, NpyArray)]) -> Result<(), NpzError> {
        let threads = std::thread::available_parallelism()
            .map(NonZeroUsize::get)
            .unwrap_or(1)
            .min(arrays.len());
        if self.compression == NpzCompression::Stored || threads < 2 {
            for (key, array) in arrays {
                self.add_array(key, array)?;
            }
            return Ok(());
        }
        // Largest first, so that no large member starts last.
        let mut order: Vec<usize> = (0..arrays.len()).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(arrays[i].1.data.len()));
        let next = AtomicUsize::new(0);
        let (path, compression) = (&self.path, self.compression);
        let mut members: Vec<Option<Result<Vec<u8>, NpzError>>> =
            arrays.iter().map(|_| None).collect();
        std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads)
                .map(|_| {
                    scope.spawn(|| {
                        let mut compressed = Vec::new();
                        while let Some(&i) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                            let (key, array) = &arrays[i];
                            compressed
                                .push((i, single_member_archive(path, compression, key, array)));
                        }
                        compressed
                    })
                })
                .collect();
            for worker in workers {
                let compressed = worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                for (i, member) in compressed {
                    members[i] = Some(member);
                }
            }
        });
        for member in members {
            let archive = member.expect("every member is compressed before the scope ends")?;
            let archive =
                zip::ZipArchive::new(Cursor::new(archive)).map_err(|source| NpzError::Zip {
                    path: self.path.clone(),
                    source,
                })?;
            self.zip
                .merge_archive(archive)
                .map_err(|source| NpzError::Zip {
                    path: self.path.clone(),
                    source,
                })?;
        }
        Ok(())
    }

    /// Adds an array of scalars with the given shape (its product must equal `values.len()`).
    pub fn add<T: NpyElement>(
        &mut self,
        key: &str,
        shape: &[usize],
        values: &[T],
    ) -> Result<(), NpzError> {
        if shape.iter().product::<usize>() != values.len() {
            return Err(NpzError::Shape {
                path: self.path.clone(),
                key: key.to_owned(),
                found: shape.to_vec(),
                expected: format!("a shape with {} elements", values.len()),
            });
        }
        self.add_array(key, &NpyArray::from_slice(shape, values))
    }

    /// Writes the zip directory and flushes; returns the inner writer.
    pub fn finish(self) -> Result<W, NpzError> {
        let path = self.path;
        let mut inner = self.zip.finish().map_err(|source| NpzError::Zip {
            path: path.clone(),
            source,
        })?;
        inner.flush().map_err(|source| NpzError::Io {
            path,
            action: "flush",
            source,
        })?;
        Ok(inner)
    }
}

/// Starts member `key` in `zip` and writes `array` into it.
fn write_member<W: Write + Seek>(
    zip: &mut zip::ZipWriter<W>,
    path: &Path,
    compression: NpzCompression,
    key: &str,
    array: &NpyArray,
) -> Result<(), NpzError> {
    let method = match compression {
        NpzCompression::Stored => zip::CompressionMethod::Stored,
        NpzCompression::Deflated => zip::CompressionMethod::Deflated,
    };
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(method)
        // Zip64 only where needed: NumPy reads both, other tools prefer plain entries.
        .large_file(array.data.len() as u64 + 4096 >= u32::MAX as u64);
    zip.start_file(format!("{key}.npy"), options)
        .map_err(|source| NpzError::Zip {
            path: path.to_path_buf(),
            source,
        })?;
    array.write(zip).map_err(|source| NpzError::Array {
        path: path.to_path_buf(),
        key: key.to_owned(),
        source,
    })
}

/// A zip in memory holding only member `key`, for [`NpzWriter::add_arrays`] to merge.
fn single_member_archive(
    path: &Path,
    compression: NpzCompression,
    key: &str,
    array: &NpyArray,
) -> Result<Vec<u8>, NpzError> {
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    write_member(&mut zip, path, compression, key, array)?;
    let archive = zip.finish().map_err(|source| NpzError::Zip {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(archive.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_compressed_at_once_give_the_archive_of_one_after_another() {
        // Sizes around the compressor's block and the zip64 threshold's neighbours do not
        // matter here; mixed sizes and dtypes and a compressible and an incompressible member do.
        let noise: Vec<u16> = (0..300_000u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u16)
            .collect();
        let arrays = [
            ("small", NpyArray::from_slice(&[3], &[1i64, 2, 3])),
            ("noise", NpyArray::from_slice(&[1000, 300], &noise)),
            (
                "runs",
                NpyArray::from_slice(&[500_000], &vec![7u8; 500_000]),
            ),
            ("empty", NpyArray::from_slice::<f32>(&[0], &[])),
            ("text", NpyArray::from_slice(&[5], b"hello")),
        ];
        for compression in [NpzCompression::Deflated, NpzCompression::Stored] {
            let mut one_by_one =
                NpzWriter::new("mem.npz".into(), Cursor::new(Vec::new()), compression);
            for (key, array) in &arrays {
                one_by_one.add_array(key, array).unwrap();
            }
            let mut at_once =
                NpzWriter::new("mem.npz".into(), Cursor::new(Vec::new()), compression);
            at_once.add_arrays(&arrays).unwrap();
            at_once.add("after", &[1], &[9u8]).unwrap();
            one_by_one.add("after", &[1], &[9u8]).unwrap();
            let expected = one_by_one.finish().unwrap().into_inner();
            assert_eq!(
                at_once.finish().unwrap().into_inner(),
                expected,
                "{compression:?}"
            );
        }
    }

    fn archive(compression: NpzCompression) -> Vec<u8> {
        let mut writer = NpzWriter::new("mem.npz".into(), Cursor::new(Vec::new()), compression);
        writer.add("a", &[2, 3], &[1i64, 2, 3, 4, 5, 6]).unwrap();
        writer.add("b", &[4], &[1u8, 0, 1, 1]).unwrap();
        writer.finish().unwrap().into_inner()
    }

    #[test]
    fn arrays_round_trip_in_both_compressions() {
        for compression in [NpzCompression::Stored, NpzCompression::Deflated] {
            let bytes = archive(compression);
            let mut reader = NpzReader::new("mem.npz".into(), Cursor::new(bytes)).unwrap();
            assert_eq!(reader.keys(), vec!["a", "b"]);
            let (shape, a) = reader.read_typed::<i64>("a", &[None, Some(3)]).unwrap();
            assert_eq!((shape, a), (vec![2, 3], vec![1, 2, 3, 4, 5, 6]));
            let (_, b) = reader.read_typed::<u8>("b", &[Some(4)]).unwrap();
            assert_eq!(b, vec![1, 0, 1, 1]);
        }
    }

    #[test]
    fn missing_key_wrong_shape_and_wrong_dtype_are_named() {
        let bytes = archive(NpzCompression::Stored);
        let mut reader = NpzReader::new("mem.npz".into(), Cursor::new(bytes)).unwrap();
        let err = reader.read_array("c").unwrap_err().to_string();
        assert!(
            err.contains("mem.npz") && err.contains("`c`") && err.contains("a, b"),
            "{err}"
        );
        let err = reader
            .read_typed::<i64>("a", &[Some(3), Some(2)])
            .unwrap_err()
            .to_string();
        assert!(err.contains("[2, 3]") && err.contains("(3, 2)"), "{err}");
        let err = reader
            .read_typed::<u16>("b", &[None])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`b`") && err.contains("<u2") && err.contains("|u1"),
            "{err}"
        );
    }

    #[test]
    fn not_a_zip_is_an_error() {
        let err = NpzReader::new("junk.npz".into(), Cursor::new(b"hello".to_vec()))
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("junk.npz"), "{err}");
    }
}
