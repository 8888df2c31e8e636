//! EVIMO recordings with their ground truth: the events, and per ground-truth frame its time,
//! the object id of every pixel and the depth, streamed one frame at a time.
//!
//! Three layouts are read ([`EvimoLayout`]):
//! - EVIMO2 v2 sequence folder: `dataset_events_{t,xy,p}.npy`, `dataset_info.npz` (`meta`: a
//!   pickled dict whose `frames` list gives each frame's `ts` in seconds), `dataset_mask.npz`
//!   and `dataset_depth.npz` with one `mask_<i>` / `depth_<i>` uint16 (H, W) array per frame
//!   `i` (index into `frames`, ten digits);
//! - EVIMO / EVIMO2 v1 single `.npz`: `events` (N, 4), `mask` and `depth` uint16 (F, H, W),
//!   `meta` as above;
//! - text folder (EVIMO's ground-truth tool output): `meta.txt` (the same dict as a Python
//!   literal), `events.txt` (`t x y p`, t in seconds) and one 16-bit RGB
//!   `depth_mask_<id>.png` per frame named by the frame's `gt_frame`.
//!
//! Mask values: EVIMO stores object id × 1000 per pixel (0 = background). [`GtFrame::mask`]
//! holds the object id, `(value + 500) / 1000`, so 0 stays background. Depth is stored in
//! millimetres; [`GtFrame::depth`] holds metres, 0 where nothing was rendered. In the PNGs
//! the mask is the red channel and the depth the blue one (EVIMO writes them with OpenCV,
//! which orders channels BGR).

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use evgate_core::SensorSize;

use crate::csv::CsvDecoder;
use crate::error::DecodeError;
use crate::evimo::{open_member, EvimoDecoder, MemberStream};
use crate::evimo2_events::Evimo2EventsDecoder;
use crate::npy::{read_header, read_pickled_object, DType};
use crate::npz::{NpzError, NpzReader};
use crate::pickle::{read_pickle, PickleError};
use crate::pyvalue::{parse_literal, LiteralError, PyValue};
use crate::reader::EventReader;
use crate::source::ByteSource;

/// The metadata pickle of a long sequence (200 Hz trajectories) is tens of MB; more is not
/// EVIMO metadata.
const MAX_META_BYTES: u64 = 1 << 30;

#[derive(Debug, thiserror::Error)]
pub enum EvimoError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error(transparent)]
    Npz(#[from] NpzError),
    #[error(transparent)]
    Decode(#[from] DecodeError),
    #[error("{path}: {source}")]
    Literal { path: PathBuf, source: LiteralError },
    #[error("{path}: the `meta` object: {source}")]
    Pickle { path: PathBuf, source: PickleError },
    #[error("{path}: metadata: {problem}")]
    Meta { path: PathBuf, problem: String },
    #[error("{path}: not an EVIMO recording: {problem} (accepted: an EVIMO2 sequence folder with dataset_info.npz, dataset_events_t/xy/p.npy and dataset_mask.npz; an EVIMO text folder with meta.txt, events.txt and depth_mask_*.png; an EVIMO .npz with events, mask and meta)")]
    Layout { path: PathBuf, problem: String },
    #[error("{path}: {problem}")]
    Frame { path: PathBuf, problem: String },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EvimoLayout {
    /// EVIMO2 v2: a folder of `.npy` / `.npz` files.
    Evimo2Folder,
    /// EVIMO / EVIMO2 v1: one `.npz`.
    SingleNpz,
    /// `meta.txt`, `events.txt` and PNGs.
    TextFolder,
}

/// A ground-truth frame as listed in the metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct GtFrameInfo {
    /// Position in the metadata's `frames` list (names the `mask_<index>` member).
    pub index: usize,
    pub t_us: i64,
    /// `gt_frame` of the metadata: the PNG of the text layout.
    pub gt_frame: Option<String>,
}

/// One ground-truth frame, row-major, `sensor.width * sensor.height` values.
#[derive(Clone, Debug, PartialEq)]
pub struct GtFrame {
    pub index: usize,
    pub t_us: i64,
    /// Object id per pixel, 0 = background.
    pub mask: Vec<u16>,
    /// Metres per pixel, 0 where nothing was rendered; `None` when the recording has no depth.
    pub depth: Option<Vec<f32>>,
}

pub struct EvimoRecording {
    path: PathBuf,
    layout: EvimoLayout,
    sensor_size: SensorSize,
    frames: Vec<GtFrameInfo>,
    has_depth: bool,
}

impl EvimoRecording {
    /// Opens any of the three layouts; reads only the metadata and array headers.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, EvimoError> {
        let path = path.as_ref();
        if path.is_dir() {
            if path.join("dataset_info.npz").is_file() {
                Self::open_evimo2(path)
            } else if path.join("meta.txt").is_file() {
                Self::open_text(path)
            } else {
                Err(EvimoError::Layout {
                    path: path.to_path_buf(),
                    problem: "the folder has neither dataset_info.npz nor meta.txt".into(),
                })
            }
        } else {
            Self::open_single_npz(path)
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn layout(&self) -> EvimoLayout {
        self.layout
    }

    pub fn sensor_size(&self) -> SensorSize {
        self.sensor_size
    }

    /// The ground-truth frames in recording order (only those with a mask).
    pub fn frame_infos(&self) -> &[GtFrameInfo] {
        &self.frames
    }

    pub fn has_depth(&self) -> bool {
        self.has_depth
    }

    /// A fresh streaming reader of the events (times in µs, same clock as the frames).
    pub fn events(&self) -> Result<Box<dyn EventReader>, EvimoError> {
        Ok(match self.layout {
            EvimoLayout::Evimo2Folder => {
                Box::new(Evimo2EventsDecoder::open(&self.path, self.sensor_size)?)
            }
            EvimoLayout::SingleNpz => {
                Box::new(EvimoDecoder::open(&self.path, Some(self.sensor_size))?)
            }
            EvimoLayout::TextFolder => {
                let events = self.path.join("events.txt");
                let file = File::open(&events).map_err(|source| DecodeError::Open {
                    path: events.clone(),
                    source,
                })?;
                Box::new(CsvDecoder::new(
                    ByteSource::new(events, Box::new(file)),
                    self.sensor_size,
                ))
            }
        })
    }

    /// Streams the ground-truth frames one at a time.
    pub fn frames(&self) -> Result<GtFrames, EvimoError> {
        let source = match self.layout {
            EvimoLayout::Evimo2Folder => {
                let depth_path = self.path.join("dataset_depth.npz");
                FrameSource::Evimo2 {
                    masks: NpzReader::open(self.path.join("dataset_mask.npz"))?,
                    depths: if self.has_depth {
                        Some(NpzReader::open(depth_path)?)
                    } else {
                        None
                    },
                }
            }
            EvimoLayout::SingleNpz => FrameSource::SingleNpz {
                masks: open_frame_stack(&self.path, "mask", Some(self.sensor_size))?.1,
                depths: if self.has_depth {
                    Some(open_frame_stack(&self.path, "depth", Some(self.sensor_size))?.1)
                } else {
                    None
                },
                consumed: 0,
            },
            EvimoLayout::TextFolder => FrameSource::Text,
        };
        Ok(GtFrames {
            path: self.path.clone(),
            sensor_size: self.sensor_size,
            infos: self.frames.clone().into_iter(),
            source,
        })
    }

    fn open_evimo2(folder: &Path) -> Result<Self, EvimoError> {
        let info_path = folder.join("dataset_info.npz");
        let meta = read_npz_meta(&info_path)?;
        let mask_path = folder.join("dataset_mask.npz");
        let masks = NpzReader::open(&mask_path)?;
        let all = frame_list(&meta, &info_path)?;
        let frames: Vec<GtFrameInfo> = all
            .into_iter()
            .filter(|f| masks.contains(&member_name("mask", f.index)))
            .collect();
        let sensor_size = match meta_resolution(&meta, &info_path)? {
            Some(size) => size,
            None => {
                let mut masks = masks;
                let first = frames.first().ok_or_else(|| EvimoError::Meta {
                    path: info_path.clone(),
                    problem: "no `res_x`/`res_y` and no mask frame to take the size from".into(),
                })?;
                let array = masks.read_array(&member_name("mask", first.index))?;
                size_of_shape(&array.shape, &mask_path)?
            }
        };
        Ok(Self {
            path: folder.to_path_buf(),
            layout: EvimoLayout::Evimo2Folder,
            sensor_size,
            frames,
            has_depth: folder.join("dataset_depth.npz").is_file(),
        })
    }

    fn open_single_npz(path: &Path) -> Result<Self, EvimoError> {
        let meta = read_npz_meta(path)?;
        let (mask_shape, _) = open_frame_stack(path, "mask", None)?;
        let frame_count = mask_shape[0];
        let mask_size = size_of_shape(&mask_shape[1..], path)?;
        let sensor_size = meta_resolution(&meta, path)?.unwrap_or(mask_size);
        if sensor_size != mask_size {
            return Err(EvimoError::Frame {
                path: path.to_path_buf(),
                problem: format!(
                    "`mask` frames are {}x{} but the metadata says res_x x res_y = {}x{}",
                    mask_size.width, mask_size.height, sensor_size.width, sensor_size.height
                ),
            });
        }
        let all = frame_list(&meta, path)?;
        if all.len() != frame_count {
            return Err(EvimoError::Frame {
                path: path.to_path_buf(),
                problem: format!(
                    "`mask` holds {frame_count} frames but the metadata lists {}",
                    all.len()
                ),
            });
        }
        let any_named = all.iter().any(|f| f.gt_frame.is_some());
        let frames = all
            .into_iter()
            .filter(|f| !any_named || f.gt_frame.is_some())
            .collect();
        let has_depth = match open_frame_stack(path, "depth", Some(sensor_size)) {
            Ok((shape, _)) if shape[0] == frame_count => true,
            Ok((shape, _)) => {
                return Err(EvimoError::Frame {
                    path: path.to_path_buf(),
                    problem: format!("`depth` holds {} frames, `mask` {frame_count}", shape[0]),
                })
            }
            Err(EvimoError::Layout { .. }) => false,
            Err(other) => return Err(other),
        };
        Ok(Self {
            path: path.to_path_buf(),
            layout: EvimoLayout::SingleNpz,
            sensor_size,
            frames,
            has_depth,
        })
    }

    fn open_text(folder: &Path) -> Result<Self, EvimoError> {
        let meta_path = folder.join("meta.txt");
        let text = std::fs::read_to_string(&meta_path).map_err(|source| EvimoError::Io {
            path: meta_path.clone(),
            action: "read",
            source,
        })?;
        let meta = parse_literal(&text).map_err(|source| EvimoError::Literal {
            path: meta_path.clone(),
            source,
        })?;
        let sensor_size = meta_resolution(&meta, &meta_path)?.ok_or_else(|| EvimoError::Meta {
            path: meta_path.clone(),
            problem: "`meta` has no `res_x` / `res_y` (the sensor size)".into(),
        })?;
        let frames = frame_list(&meta, &meta_path)?
            .into_iter()
            .filter(|f| f.gt_frame.is_some())
            .collect();
        Ok(Self {
            path: folder.to_path_buf(),
            layout: EvimoLayout::TextFolder,
            sensor_size,
            frames,
            has_depth: true,
        })
    }
}

fn member_name(prefix: &str, index: usize) -> String {
    format!("{prefix}_{index:010}")
}

fn member_error(path: &Path, key: &str, source: crate::npy::NpyError) -> EvimoError {
    EvimoError::Npz(NpzError::Array {
        path: path.to_path_buf(),
        key: key.to_owned(),
        source,
    })
}

/// The metadata dict out of the `meta` object array of an `.npz`.
fn read_npz_meta(path: &Path) -> Result<PyValue, EvimoError> {
    let mut stream = open_member(path, "meta.npy")?.ok_or_else(|| EvimoError::Layout {
        path: path.to_path_buf(),
        problem: "no `meta` array".into(),
    })?;
    let pickle = read_pickled_object(&mut stream, MAX_META_BYTES)
        .map_err(|e| member_error(path, "meta", e))?;
    let value = read_pickle(&pickle).map_err(|source| EvimoError::Pickle {
        path: path.to_path_buf(),
        source,
    })?;
    value
        .find_dict_with_key("frames")
        .cloned()
        .ok_or_else(|| EvimoError::Meta {
            path: path.to_path_buf(),
            problem: "no dict with a `frames` list inside `meta`".into(),
        })
}

/// Every entry of the metadata's `frames` list, with its time.
fn frame_list(meta: &PyValue, path: &Path) -> Result<Vec<GtFrameInfo>, EvimoError> {
    let meta_error = |problem: String| EvimoError::Meta {
        path: path.to_path_buf(),
        problem,
    };
    let frames = meta
        .get("frames")
        .and_then(PyValue::as_list)
        .ok_or_else(|| meta_error("no `frames` list".into()))?;
    let mut out = Vec::with_capacity(frames.len());
    for (index, frame) in frames.iter().enumerate() {
        let ts = frame.get("ts").and_then(PyValue::as_f64);
        let t_us = match ts {
            Some(ts) if (ts * 1e6).is_finite() && (ts * 1e6).abs() < 9e18 => {
                (ts * 1e6).round() as i64
            }
            _ => {
                return Err(meta_error(format!(
                    "frame {index}: `ts` is {:?}, expected a finite number of seconds",
                    frame.get("ts")
                )))
            }
        };
        if let Some(previous) = out.last().map(|f: &GtFrameInfo| f.t_us) {
            if t_us < previous {
                return Err(meta_error(format!(
                    "frame {index}: `ts` {t_us} µs is earlier than the frame before ({previous} µs)"
                )));
            }
        }
        out.push(GtFrameInfo {
            index,
            t_us,
            gt_frame: frame
                .get("gt_frame")
                .and_then(PyValue::as_str)
                .map(str::to_owned),
        });
    }
    Ok(out)
}

/// `meta.res_x` × `meta.res_y` when the metadata has them.
fn meta_resolution(meta: &PyValue, path: &Path) -> Result<Option<SensorSize>, EvimoError> {
    let Some(camera) = meta.get("meta") else {
        return Ok(None);
    };
    let side = |key: &str| camera.get(key).and_then(PyValue::as_f64);
    match (side("res_x"), side("res_y")) {
        (Some(w), Some(h)) => {
            let valid = |v: f64| v.fract() == 0.0 && (1.0..=65535.0).contains(&v);
            if valid(w) && valid(h) {
                Ok(Some(SensorSize::new(w as u16, h as u16)))
            } else {
                Err(EvimoError::Meta {
                    path: path.to_path_buf(),
                    problem: format!("`res_x` {w} / `res_y` {h} is not a sensor size in 1..=65535"),
                })
            }
        }
        _ => Ok(None),
    }
}

fn size_of_shape(shape: &[usize], path: &Path) -> Result<SensorSize, EvimoError> {
    match shape {
        [h, w] => u16::try_from(*w)
            .ok()
            .zip(u16::try_from(*h).ok())
            .filter(|&(w, h)| w > 0 && h > 0)
            .map(|(w, h)| SensorSize::new(w, h)),
        _ => None,
    }
    .ok_or_else(|| EvimoError::Frame {
        path: path.to_path_buf(),
        problem: format!("a frame of shape {shape:?} is not (H, W) with sides in 1..=65535"),
    })
}

/// Opens the `key` (F, H, W) uint16 stack of a single `.npz` and returns its shape and the
/// stream at the first frame; `size` checks (H, W).
fn open_frame_stack(
    path: &Path,
    key: &str,
    size: Option<SensorSize>,
) -> Result<(Vec<usize>, MemberStream), EvimoError> {
    let mut stream =
        open_member(path, &format!("{key}.npy"))?.ok_or_else(|| EvimoError::Layout {
            path: path.to_path_buf(),
            problem: format!("no `{key}` array"),
        })?;
    let header = read_header(&mut stream).map_err(|e| member_error(path, key, e))?;
    let dtype_ok = matches!(&header.dtype, DType::Scalar(d) if d == "<u2");
    let shape_ok = match (header.shape.as_slice(), size) {
        ([_, h, w], Some(size)) => *h == size.height as usize && *w == size.width as usize,
        ([_, _, _], None) => true,
        _ => false,
    };
    if !dtype_ok || !shape_ok {
        return Err(EvimoError::Npz(NpzError::Shape {
            path: path.to_path_buf(),
            key: key.to_owned(),
            found: header.shape.clone(),
            expected: match size {
                Some(s) => format!(
                    "<u2 of shape (F, {}, {}) (dtype found: {})",
                    s.height, s.width, header.dtype
                ),
                None => format!("<u2 of shape (F, H, W) (dtype found: {})", header.dtype),
            },
        }));
    }
    Ok((header.shape, stream))
}

enum FrameSource {
    Evimo2 {
        masks: NpzReader,
        depths: Option<NpzReader>,
    },
    SingleNpz {
        masks: MemberStream,
        depths: Option<MemberStream>,
        /// Frames of the stacks read so far.
        consumed: usize,
    },
    Text,
}

/// The ground-truth frames of a recording, one in memory at a time.
pub struct GtFrames {
    path: PathBuf,
    sensor_size: SensorSize,
    infos: std::vec::IntoIter<GtFrameInfo>,
    source: FrameSource,
}

fn ids_from_mask(raw: impl Iterator<Item = u16>) -> Vec<u16> {
    raw.map(|v| ((v as u32 + 500) / 1000) as u16).collect()
}

fn metres_from_mm(raw: impl Iterator<Item = u16>) -> Vec<f32> {
    raw.map(|mm| mm as f32 * 1e-3).collect()
}

impl GtFrames {
    fn next_frame(&mut self, info: GtFrameInfo) -> Result<GtFrame, EvimoError> {
        let (w, h) = (
            self.sensor_size.width as usize,
            self.sensor_size.height as usize,
        );
        let (mask, depth) = match &mut self.source {
            FrameSource::Evimo2 { masks, depths } => {
                let expected = [Some(h), Some(w)];
                let (_, mask) =
                    masks.read_typed::<u16>(&member_name("mask", info.index), &expected)?;
                let depth = match depths {
                    Some(depths) if depths.contains(&member_name("depth", info.index)) => Some(
                        depths
                            .read_typed::<u16>(&member_name("depth", info.index), &expected)?
                            .1,
                    ),
                    _ => None,
                };
                (mask, depth)
            }
            FrameSource::SingleNpz {
                masks,
                depths,
                consumed,
            } => {
                let bytes = w * h * 2;
                let mut frame = Vec::new();
                let mut depth_frame = depths.as_ref().map(|_| Vec::new());
                while *consumed <= info.index {
                    read_frame(masks, bytes, &mut frame).map_err(|source| EvimoError::Io {
                        path: self.path.join("mask"),
                        action: "read a mask frame",
                        source,
                    })?;
                    if let (Some(stream), Some(buffer)) = (depths.as_mut(), depth_frame.as_mut()) {
                        read_frame(stream, bytes, buffer).map_err(|source| EvimoError::Io {
                            path: self.path.join("depth"),
                            action: "read a depth frame",
                            source,
                        })?;
                    }
                    *consumed += 1;
                }
                let words = |raw: &[u8]| -> Vec<u16> {
                    raw.chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]]))
                        .collect()
                };
                (words(&frame), depth_frame.as_deref().map(words))
            }
            FrameSource::Text => {
                let name = info
                    .gt_frame
                    .as_deref()
                    .expect("text frames are listed by gt_frame");
                let png = [self.path.join(name), self.path.join("img").join(name)]
                    .into_iter()
                    .find(|p| p.is_file())
                    .ok_or_else(|| EvimoError::Frame {
                        path: self.path.join(name),
                        problem: format!("frame {}: the ground-truth PNG is missing (looked in the folder and img/)", info.index),
                    })?;
                let (mask, depth) = read_depth_mask_png(&png, self.sensor_size)?;
                (mask, Some(depth))
            }
        };
        Ok(GtFrame {
            index: info.index,
            t_us: info.t_us,
            mask: ids_from_mask(mask.into_iter()),
            depth: depth.map(|d| metres_from_mm(d.into_iter())),
        })
    }
}

impl Iterator for GtFrames {
    type Item = Result<GtFrame, EvimoError>;

    fn next(&mut self) -> Option<Self::Item> {
        let info = self.infos.next()?;
        Some(self.next_frame(info))
    }
}

/// Reads the next `bytes` bytes of a frame stack into `frame`. The buffer grows with the data
/// that arrives, so a header claiming huge frames cannot make us allocate for the claim.
fn read_frame(stream: &mut MemberStream, bytes: usize, frame: &mut Vec<u8>) -> std::io::Result<()> {
    frame.clear();
    stream.take(bytes as u64).read_to_end(frame)?;
    if frame.len() < bytes {
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            format!(
                "the stack ends {} bytes into a frame of {bytes} bytes",
                frame.len()
            ),
        ));
    }
    Ok(())
}

/// (mask, depth) raw channels of an EVIMO `depth_mask_*.png` (16-bit RGB or RGBA).
fn read_depth_mask_png(path: &Path, size: SensorSize) -> Result<(Vec<u16>, Vec<u16>), EvimoError> {
    let fail = |problem: String| EvimoError::Frame {
        path: path.to_path_buf(),
        problem,
    };
    let file = File::open(path).map_err(|source| EvimoError::Io {
        path: path.to_path_buf(),
        action: "open",
        source,
    })?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder
        .read_info()
        .map_err(|e| fail(format!("not a readable PNG: {e}")))?;
    // The size is checked before the image buffer is allocated: a PNG header may claim any
    // size.
    let header = reader.info();
    if (header.width, header.height) != (size.width as u32, size.height as u32) {
        return Err(fail(format!(
            "{}x{} pixels, the sensor is {}x{}",
            header.width, header.height, size.width, size.height
        )));
    }
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buffer)
        .map_err(|e| fail(format!("PNG data does not decode: {e}")))?;
    let channels = match (info.color_type, info.bit_depth) {
        (png::ColorType::Rgb, png::BitDepth::Sixteen) => 3,
        (png::ColorType::Rgba, png::BitDepth::Sixteen) => 4,
        (color, depth) => {
            return Err(fail(format!(
                "{color:?} with {depth:?}-bit samples; expected 16-bit RGB (mask, -, depth)"
            )))
        }
    };
    let pixels = &buffer[..info.buffer_size()];
    let sample = |pixel: &[u8], channel: usize| {
        u16::from_be_bytes([pixel[2 * channel], pixel[2 * channel + 1]])
    };
    let stride = 2 * channels;
    let mask = pixels.chunks_exact(stride).map(|p| sample(p, 0)).collect();
    let depth = pixels.chunks_exact(stride).map(|p| sample(p, 2)).collect();
    Ok((mask, depth))
}
