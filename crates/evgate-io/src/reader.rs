//! One entry point for every input format: [`open`] returns a streaming [`EventReader`].

use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};

use crate::aedat4::Aedat4Decoder;
use crate::csv::CsvDecoder;
use crate::dat::DatDecoder;
use crate::error::DecodeError;
use crate::evimo::EvimoDecoder;
use crate::evimo2_events::Evimo2EventsDecoder;
use crate::evimo_recording::{EvimoError, EvimoRecording};
use crate::evt2::Evt2Decoder;
use crate::evt3::{Evt3Decoder, Evt3TimeLow};
use crate::format::{detect, Format};
use crate::header::PropheseeHeader;
use crate::native::NativeDecoder;
use crate::report::DecodeReport;
use crate::source::ByteSource;

/// A decoder that streams events in bounded chunks.
pub trait EventReader: Send {
    fn format(&self) -> Format;
    fn sensor_size(&self) -> SensorSize;
    /// Clears `out` and fills it with the next chunk of events (at most a few hundred thousand);
    /// returns how many; 0 means the end of the stream.
    fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError>;
    /// What was dropped, skipped or found out of order so far (see [`crate::report`]).
    fn report(&self) -> &DecodeReport;
    /// Bytes of the input consumed so far (for progress).
    fn bytes_read(&self) -> u64;
}

macro_rules! event_reader {
    ($decoder:ty, $format:expr) => {
        impl EventReader for $decoder {
            fn format(&self) -> Format {
                $format
            }
            fn sensor_size(&self) -> SensorSize {
                <$decoder>::sensor_size(self)
            }
            fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError> {
                <$decoder>::read_chunk(self, out)
            }
            fn report(&self) -> &DecodeReport {
                <$decoder>::report(self)
            }
            fn bytes_read(&self) -> u64 {
                <$decoder>::bytes_read(self)
            }
        }
    };
}

// The byte-stream decoders get theirs from `StreamDecoder`.
event_reader!(Evimo2EventsDecoder, Format::Evimo2Folder);
#[cfg(feature = "dsec")]
event_reader!(crate::dsec::DsecReader, Format::Dsec);

/// Header key of the time offset our EVT 3.0 encoder declares (see `evt3_writer`).
const EVT3_TIME_OFFSET_KEY: &str = "evgate_time_offset_us";

/// The size text inputs get when none is given: every coordinate fits, nothing is dropped.
pub const UNBOUNDED_SENSOR: SensorSize = SensorSize::new(u16::MAX, u16::MAX);

#[derive(Clone, Debug, Default)]
pub struct OpenOptions {
    /// Skip detection and decode as this format.
    pub format: Option<Format>,
    /// The sensor size: required for RAW/DAT files whose header gives none; overrides the
    /// header otherwise. Text inputs without it get [`UNBOUNDED_SENSOR`].
    pub sensor_size: Option<SensorSize>,
}

/// Opens an event file of any supported format, detected from its content and extension.
pub fn open(path: impl AsRef<Path>) -> Result<Box<dyn EventReader>, DecodeError> {
    open_with(path, &OpenOptions::default())
}

pub fn open_with(
    path: impl AsRef<Path>,
    options: &OpenOptions,
) -> Result<Box<dyn EventReader>, DecodeError> {
    open_with_time_low_rule(path, options, Evt3TimeLow::default())
}

/// [`open_with`], reading EVT 3.0 `TIME_LOW` steps back by `time_low_rule` (other formats
/// ignore it).
pub fn open_with_time_low_rule(
    path: impl AsRef<Path>,
    options: &OpenOptions,
    time_low_rule: Evt3TimeLow,
) -> Result<Box<dyn EventReader>, DecodeError> {
    let path = path.as_ref();
    let format = match options.format {
        Some(format) => format,
        None => detect(path)?,
    };
    match format {
        // A zip is read by member, a folder by file, HDF5 by dataset: not as one byte stream.
        Format::EvimoNpz => return Ok(Box::new(EvimoDecoder::open(path, options.sensor_size)?)),
        Format::Evimo2Folder => return open_evimo2_folder(path, options),
        Format::Dsec => return open_dsec(path, options),
        _ => {}
    }
    let file = std::fs::File::open(path).map_err(|source| DecodeError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let source = ByteSource::new(path.to_path_buf(), Box::new(file));
    from_source(format, source, options, time_low_rule)
}

/// Decodes `bytes` held in memory as `format`; `name` is used in error messages.
pub fn from_bytes(
    name: impl Into<PathBuf>,
    bytes: Vec<u8>,
    format: Format,
    sensor_size: Option<SensorSize>,
) -> Result<Box<dyn EventReader>, DecodeError> {
    let source = ByteSource::new(name.into(), Box::new(std::io::Cursor::new(bytes)));
    let options = OpenOptions {
        format: Some(format),
        sensor_size,
    };
    from_source(format, source, &options, Evt3TimeLow::default())
}

fn from_source(
    format: Format,
    mut source: ByteSource,
    options: &OpenOptions,
    time_low_rule: Evt3TimeLow,
) -> Result<Box<dyn EventReader>, DecodeError> {
    Ok(match format {
        Format::Evt2 | Format::Evt3 | Format::Dat => {
            let header = PropheseeHeader::read(&mut source)?;
            let sensor_size = options
                .sensor_size
                .or_else(|| header.sensor_size())
                .ok_or_else(|| DecodeError::BadHeader {
                    path: source.path().to_path_buf(),
                    offset: 0,
                    problem: "the header gives no sensor size (no `% format ...;width=W;height=H`, `% geometry WxH`, `% width`/`% height`, nor a known `% plugin_name`); pass it explicitly".into(),
                })?;
            match format {
                Format::Evt2 => Box::new(Evt2Decoder::new(source, sensor_size)),
                Format::Evt3 => {
                    let time_offset = match header.get(EVT3_TIME_OFFSET_KEY) {
                        Some(text) => text.parse().map_err(|_| DecodeError::BadHeader {
                            path: source.path().to_path_buf(),
                            offset: 0,
                            problem: format!(
                                "`% {EVT3_TIME_OFFSET_KEY} {text}` is not an integer number of µs"
                            ),
                        })?,
                        None => 0,
                    };
                    Box::new(
                        Evt3Decoder::new(source, sensor_size, time_offset)
                            .with_time_low_rule(time_low_rule),
                    )
                }
                _ => Box::new(DatDecoder::new(source, sensor_size)?),
            }
        }
        Format::Aedat4 => Box::new(Aedat4Decoder::new(source, options.sensor_size)?),
        Format::Csv => Box::new(CsvDecoder::new(
            source,
            options.sensor_size.unwrap_or(UNBOUNDED_SENSOR),
        )),
        Format::Native => Box::new(NativeDecoder::new(source)?),
        Format::EvimoNpz | Format::Evimo2Folder | Format::Dsec => {
            return Err(DecodeError::Unrecognised {
                path: source.path().to_path_buf(),
                problem: format!(
                    "{format} inputs are read from a path (zip members, files of a folder, HDF5 datasets), not from a byte stream"
                ),
            })
        }
    })
}

/// The events of an EVIMO2 sequence folder; the sensor size comes from its metadata unless
/// given.
fn open_evimo2_folder(
    path: &Path,
    options: &OpenOptions,
) -> Result<Box<dyn EventReader>, DecodeError> {
    let sensor_size = match options.sensor_size {
        Some(size) => size,
        None => EvimoRecording::open(path)
            .map_err(|e| match e {
                EvimoError::Decode(decode) => decode,
                other => {
                    let message = other.to_string();
                    let prefix = format!("{}: ", path.display());
                    DecodeError::Unrecognised {
                        path: path.to_path_buf(),
                        problem: message.strip_prefix(&prefix).unwrap_or(&message).to_owned(),
                    }
                }
            })?
            .sensor_size(),
    };
    Ok(Box::new(Evimo2EventsDecoder::open(path, sensor_size)?))
}

#[cfg(feature = "dsec")]
fn open_dsec(path: &Path, options: &OpenOptions) -> Result<Box<dyn EventReader>, DecodeError> {
    Ok(Box::new(crate::dsec::DsecReader::open(
        path,
        options.sensor_size,
    )?))
}

#[cfg(not(feature = "dsec"))]
fn open_dsec(path: &Path, _options: &OpenOptions) -> Result<Box<dyn EventReader>, DecodeError> {
    Err(DecodeError::Unrecognised {
        path: path.to_path_buf(),
        problem: "an HDF5 (DSEC events.h5) file, but this build has no HDF5 support: rebuild with `--features dsec` (evgate-io) or `cargo build -p evgate --features dsec`, after `bash scripts/setup-hdf5.sh`".into(),
    })
}

/// Reads a whole input into memory (for tests and small files; streaming code should loop on
/// [`EventReader::read_chunk`]).
pub fn read_all(reader: &mut dyn EventReader) -> Result<Vec<Event>, DecodeError> {
    let (mut all, mut chunk) = (Vec::new(), Vec::new());
    while reader.read_chunk(&mut chunk)? > 0 {
        all.extend_from_slice(&chunk);
    }
    Ok(all)
}
