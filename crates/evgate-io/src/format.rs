//! Event file formats and their detection from the first bytes and the extension.

use std::io::Read;
use std::path::Path;

use serde::Serialize;

use crate::error::DecodeError;
use crate::header::PropheseeHeader;
use crate::source::ByteSource;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Format {
    /// Prophesee RAW, EVT 2.0.
    Evt2,
    /// Prophesee RAW, EVT 3.0.
    Evt3,
    /// Prophesee DAT (CD events).
    Dat,
    /// iniVation AEDAT 4.0.
    Aedat4,
    /// Text: `t x y p` per line.
    Csv,
    /// evgate's own `.evg`.
    Native,
    /// EVIMO `.npz` (`events` array of `[t s, x, y, p]` rows).
    EvimoNpz,
    /// EVIMO2 v2 sequence folder (`dataset_events_t.npy`, `_xy`, `_p`).
    Evimo2Folder,
    /// DSEC `events.h5` (HDF5; read when built with the `dsec` feature).
    Dsec,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Evt2 => "evt2",
            Format::Evt3 => "evt3",
            Format::Dat => "dat",
            Format::Aedat4 => "aedat4",
            Format::Csv => "csv",
            Format::Native => "evg",
            Format::EvimoNpz => "evimo-npz",
            Format::Evimo2Folder => "evimo2-folder",
            Format::Dsec => "dsec-h5",
        }
    }

    /// The format an output file gets from its extension: `.csv`/`.txt`, `.raw` (EVT 3.0),
    /// `.evg`. Only these have encoders.
    pub fn for_output(path: &Path) -> Option<Format> {
        match extension(path).as_deref() {
            Some("csv" | "txt") => Some(Format::Csv),
            Some("raw") => Some(Format::Evt3),
            Some("evg") => Some(Format::Native),
            _ => None,
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The HDF5 superblock signature (at byte 0: DSEC files have no user block).
pub const HDF5_MAGIC: [u8; 8] = *b"\x89HDF\r\n\x1a\n";

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// Detects the format from the magic bytes, then the `%` header, then the extension.
pub fn detect(path: &Path) -> Result<Format, DecodeError> {
    if path.is_dir() {
        return if path.join(crate::evimo2_events::TIMES_FILE).is_file() {
            Ok(Format::Evimo2Folder)
        } else {
            Err(DecodeError::Unrecognised {
                path: path.to_path_buf(),
                problem: format!(
                    "a folder, and not an EVIMO2 sequence (no {})",
                    crate::evimo2_events::TIMES_FILE
                ),
            })
        };
    }
    let file = std::fs::File::open(path).map_err(|source| DecodeError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    // The header is read from a bounded prefix: detection must not scan a whole binary file.
    let prefix = file.take(256 * 1024);
    let mut source = ByteSource::new(path.to_path_buf(), Box::new(prefix));
    detect_from(path, &mut source)
}

fn detect_from(path: &Path, source: &mut ByteSource) -> Result<Format, DecodeError> {
    let unrecognised = |problem: String| DecodeError::Unrecognised {
        path: path.to_path_buf(),
        problem,
    };
    let first = source.peek()?;
    if first == Some(b'#') || first == Some(crate::native::MAGIC[0]) {
        let magic = source
            .read_exact(8, "a magic number")
            .ok()
            .map(<[u8]>::to_vec);
        match magic.as_deref() {
            Some(m) if m == crate::native::MAGIC => return Ok(Format::Native),
            Some(m) if m == HDF5_MAGIC => return Ok(Format::Dsec),
            Some(m) if m == &crate::aedat4::MAGIC[..8] => return Ok(Format::Aedat4),
            _ => {}
        }
        if first == Some(b'#') && matches!(extension(path).as_deref(), Some("csv" | "txt")) {
            return Ok(Format::Csv);
        }
    }
    if first == Some(b'%') {
        let header = PropheseeHeader::read(source)?;
        return match header.evt_version().as_deref() {
            Some("2.0" | "2") => Ok(Format::Evt2),
            Some("3.0" | "3") => Ok(Format::Evt3),
            Some(other) => Err(unrecognised(format!(
                "RAW event format `{other}` is not supported (accepted: EVT 2.0, EVT 3.0)"
            ))),
            None if extension(path).as_deref() == Some("raw") => Err(unrecognised(
                "the RAW header declares no event format (`% evt 3.0` or `% format EVT3;...`)"
                    .into(),
            )),
            None => Ok(Format::Dat),
        };
    }
    match extension(path).as_deref() {
        Some("csv" | "txt") => Ok(Format::Csv),
        Some("dat") => Ok(Format::Dat),
        Some("npz") if first == Some(b'P') => Ok(Format::EvimoNpz),
        Some("raw") => Err(unrecognised("a RAW file must start with a `%` header".into())),
        Some("aedat4") => Err(unrecognised("an AEDAT 4 file must start with `#!AER-DAT4.0`".into())),
        Some("evg") => Err(unrecognised("an .evg file must start with the .evg magic".into())),
        Some("h5" | "hdf5") => Err(unrecognised("an HDF5 file must start with the HDF5 signature \\x89HDF\\r\\n\\x1a\\n".into())),
        _ if first.is_none() => Err(unrecognised("the file is empty and its extension names no format".into())),
        other => Err(unrecognised(format!(
            "format not recognised from the first bytes nor the extension {:?} (accepted: .raw EVT 2.0/3.0, .dat, .aedat4, .csv/.txt, .evg, EVIMO .npz, EVIMO2 folder, DSEC .h5)",
            other.unwrap_or_default()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn detect_bytes(name: &str, bytes: &[u8]) -> Result<Format, DecodeError> {
        let mut source = ByteSource::new(name.into(), Box::new(Cursor::new(bytes.to_vec())));
        detect_from(Path::new(name), &mut source)
    }

    #[test]
    fn magic_beats_extension() {
        assert_eq!(
            detect_bytes("a.bin", b"#!AER-DAT4.0\r\n").unwrap(),
            Format::Aedat4
        );
        assert_eq!(
            detect_bytes("a.csv", &crate::native::MAGIC).unwrap(),
            Format::Native
        );
        assert_eq!(detect_bytes("a.dat", b"% evt 3.0\n").unwrap(), Format::Evt3);
        assert_eq!(
            detect_bytes("a", b"% format EVT2;width=1;height=1\n").unwrap(),
            Format::Evt2
        );
        assert_eq!(
            detect_bytes("a.dat", b"% Version 2\n\x0c\x08").unwrap(),
            Format::Dat
        );
        assert_eq!(detect_bytes("a.txt", b"0.1 1 2 0\n").unwrap(), Format::Csv);
        assert_eq!(
            detect_bytes("events.h5", b"\x89HDF\r\n\x1a\n\x00\x00").unwrap(),
            Format::Dsec
        );
        assert_eq!(
            detect_bytes("a.csv", b"# comment\n1,2,3,1\n").unwrap(),
            Format::Csv
        );
    }

    #[test]
    fn unknown_and_empty_inputs_are_named() {
        let err = detect_bytes("a.raw", b"% evt 4.0\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("`4.0`") && err.contains("a.raw"), "{err}");
        let err = detect_bytes("a.raw", b"% date today\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("declares no event format"), "{err}");
        let err = detect_bytes("a.xyz", b"").unwrap_err().to_string();
        assert!(err.contains("empty"), "{err}");
        let err = detect_bytes("a.xyz", b"\x01\x02").unwrap_err().to_string();
        assert!(err.contains("accepted"), "{err}");
    }
}
