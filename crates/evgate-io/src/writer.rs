//! One entry point for every output format: [`create`] returns an [`EventWriter`] chosen by the
//! file extension (`.csv`/`.txt`, `.raw` = EVT 3.0, `.evg`).

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};

use crate::csv_writer::CsvWriter;
use crate::evt3_writer::Evt3Writer;
use crate::format::Format;
use crate::native_writer::NativeWriter;

#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error(
        "{path}: no encoder for {what} (accepted extensions: .csv, .txt, .raw (EVT 3.0), .evg)"
    )]
    UnsupportedFormat { path: PathBuf, what: String },
    #[error("{path}: event {index} ({event:?}) cannot be written: {problem}")]
    Unencodable {
        path: PathBuf,
        index: u64,
        event: Event,
        problem: String,
    },
    #[error("{path}: sensor size {sensor_size} cannot be written: {problem}")]
    UnsupportedSensor {
        path: PathBuf,
        sensor_size: SensorSize,
        problem: String,
    },
}

/// An encoder; call [`EventWriter::finish`] at the end (dropping without it may leave an
/// incomplete file).
pub trait EventWriter {
    fn format(&self) -> Format;
    fn write(&mut self, events: &[Event]) -> Result<(), EncodeError>;
    /// Flushes and completes the file (the `.evg` event count is written here).
    fn finish(self: Box<Self>) -> Result<(), EncodeError>;
}

/// Creates `path` for writing events of a sensor of `sensor_size`, the format chosen by the
/// extension.
pub fn create(
    path: impl AsRef<Path>,
    sensor_size: SensorSize,
) -> Result<Box<dyn EventWriter>, EncodeError> {
    let path = path.as_ref();
    let format = Format::for_output(path).ok_or_else(|| EncodeError::UnsupportedFormat {
        path: path.to_path_buf(),
        what: format!(
            "extension {:?}",
            path.extension().unwrap_or_default().to_string_lossy()
        ),
    })?;
    create_as(path, format, sensor_size)
}

pub fn create_as(
    path: impl AsRef<Path>,
    format: Format,
    sensor_size: SensorSize,
) -> Result<Box<dyn EventWriter>, EncodeError> {
    let path = path.as_ref();
    let open = || {
        File::create(path)
            .map(BufWriter::new)
            .map_err(|source| EncodeError::Io {
                path: path.to_path_buf(),
                action: "create",
                source,
            })
    };
    Ok(match format {
        Format::Csv => Box::new(CsvWriter::new(path.to_path_buf(), open()?)?),
        Format::Evt3 => Box::new(Evt3Writer::new(path.to_path_buf(), open()?, sensor_size)?),
        Format::Native => Box::new(NativeWriter::new(path.to_path_buf(), open()?, sensor_size)?),
        other => {
            return Err(EncodeError::UnsupportedFormat {
                path: path.to_path_buf(),
                what: format!("format {other}"),
            })
        }
    })
}

pub(crate) fn io_error<'a>(
    path: &'a Path,
    action: &'static str,
) -> impl FnOnce(std::io::Error) -> EncodeError + 'a {
    move |source| EncodeError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
}
