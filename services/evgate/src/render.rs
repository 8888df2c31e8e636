//! `evgate render`: draw an event file (optionally with labels, ground-truth masks or a gate's
//! suppressed stream) as PNG frames or an animated GIF.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use evgate_core::{Event, SensorSize};
use evgate_io::LabelledSequence;
use serde::Serialize;

/// Render events as images: one frame per time window, ON blue and OFF red (or coloured by the
/// object that caused them), with ground-truth mask outlines in green.
#[derive(Args)]
pub struct RenderArgs {
    /// Event file of any supported format, or a labelled sequence `.npz` (then `--labels` works).
    pub input: PathBuf,
    /// `.gif` for an animation; any other path is a directory that receives frame-NNNNN.png.
    pub output: PathBuf,
    /// Length of the time window drawn in each frame, milliseconds.
    #[arg(long, default_value_t = 20.0)]
    pub window_ms: f64,
    /// Colour events by label (grey = static world or noise, a colour per object) instead of
    /// by polarity; needs a labelled sequence `.npz` as input.
    #[arg(long)]
    pub labels: bool,
    /// Labelled sequence whose ground-truth masks are outlined (the mask nearest each window's end).
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Event file of a gate's suppressed stream, drawn in light grey under the input's events.
    #[arg(long)]
    pub suppressed: Option<PathBuf>,
    /// Skip this much of the recording first, milliseconds.
    #[arg(long, default_value_t = 0.0)]
    pub start_ms: f64,
    /// Stop after this many frames.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Enlarge every pixel to a SCALE×SCALE block.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=8))]
    pub scale: u32,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Palette shared by PNG and GIF output (GIF frames are indexed into it).
const BACKGROUND: u8 = 0;
const ON: u8 = 1;
const OFF: u8 = 2;
const SUPPRESSED: u8 = 3;
const OUTLINE: u8 = 4;
const STATIC_WORLD: u8 = 5;
const FIRST_OBJECT_COLOUR: u8 = 6;
const PALETTE: [[u8; 3]; 14] = [
    [255, 255, 255],
    [30, 90, 230],
    [220, 40, 40],
    [215, 215, 215],
    [0, 170, 60],
    [110, 110, 110],
    [230, 120, 0],
    [150, 50, 200],
    [0, 160, 170],
    [200, 170, 0],
    [230, 60, 150],
    [90, 140, 40],
    [120, 80, 40],
    [40, 40, 160],
];

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct RenderSummary {
    frames: usize,
    events_drawn: u64,
    suppressed_drawn: u64,
    width: u32,
    height: u32,
    output: PathBuf,
}

struct Stream {
    events: Vec<Event>,
    labels: Option<Vec<u16>>,
    sensor: SensorSize,
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    if args.window_ms.is_nan() || args.window_ms <= 0.0 {
        bail!("--window-ms {} must be positive", args.window_ms);
    }
    let stream = load(&args.input)?;
    if args.labels && stream.labels.is_none() {
        bail!(
            "--labels needs a labelled sequence .npz as input; {} has no labels",
            args.input.display()
        );
    }
    let suppressed = args.suppressed.as_deref().map(load).transpose()?;
    let masks = match &args.masks {
        Some(path) => {
            let sequence = LabelledSequence::read(path)
                .with_context(|| format!("cannot read masks from {}", path.display()))?;
            if sequence.sensor_size != stream.sensor {
                bail!(
                    "masks in {} are {} but the events are {}",
                    path.display(),
                    sequence.sensor_size,
                    stream.sensor
                );
            }
            Some(sequence)
        }
        None => None,
    };
    let sensor = stream.sensor;
    let Some(first) = stream.events.first().map(|e| e.t) else {
        bail!("{} holds no events", args.input.display());
    };
    let last = stream.events.last().map(|e| e.t).unwrap_or(first);
    let window_us = (args.window_ms * 1000.0).round().max(1.0) as i64;
    let start = first + (args.start_ms * 1000.0).round() as i64;
    let frame_count = ((last - start) / window_us + 1).max(0) as usize;
    let frame_count = args.max_frames.map_or(frame_count, |m| m.min(frame_count));
    let scale = args.scale as usize;
    let (width, height) = (
        sensor.width as usize * scale,
        sensor.height as usize * scale,
    );
    let mut sink = FrameSink::create(&args.output, width, height, args.window_ms)?;
    let mut summary = RenderSummary {
        frames: 0,
        events_drawn: 0,
        suppressed_drawn: 0,
        width: width as u32,
        height: height as u32,
        output: args.output.clone(),
    };
    let mut pixels = vec![BACKGROUND; sensor.pixels()];
    for frame in 0..frame_count {
        let (t0, t1) = (
            start + frame as i64 * window_us,
            start + (frame as i64 + 1) * window_us,
        );
        pixels.fill(BACKGROUND);
        if let Some(suppressed) = &suppressed {
            for event in window(&suppressed.events, t0, t1) {
                if sensor.contains(event) {
                    pixels[sensor.index(event.x, event.y)] = SUPPRESSED;
                    summary.suppressed_drawn += 1;
                }
            }
        }
        let range = window_range(&stream.events, t0, t1);
        for i in range {
            let event = &stream.events[i];
            if !sensor.contains(event) {
                continue;
            }
            let colour = match (&stream.labels, args.labels) {
                (Some(labels), true) => label_colour(labels[i]),
                _ if event.is_on() => ON,
                _ => OFF,
            };
            pixels[sensor.index(event.x, event.y)] = colour;
            summary.events_drawn += 1;
        }
        if let Some(sequence) = &masks {
            if let Some(index) = nearest_frame(&sequence.gt_ts, t1) {
                draw_outlines(&mut pixels, sequence.mask_frame(index), sensor);
            }
        }
        sink.push(&upscale(&pixels, sensor, scale))?;
        summary.frames += 1;
    }
    sink.finish()?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "rendered {} frames ({}×{}, {} ms each) with {} events{} to {}",
            summary.frames,
            width,
            height,
            args.window_ms,
            summary.events_drawn,
            if suppressed.is_some() {
                format!(" and {} suppressed", summary.suppressed_drawn)
            } else {
                String::new()
            },
            summary.output.display()
        );
    }
    Ok(())
}

/// Reads a labelled sequence (events with labels) or, failing that, any event file.
fn load(path: &Path) -> anyhow::Result<Stream> {
    if path.extension().is_some_and(|e| e == "npz") {
        if let Ok(sequence) = LabelledSequence::read(path) {
            return Ok(Stream {
                events: sequence.events,
                labels: Some(sequence.labels),
                sensor: sequence.sensor_size,
            });
        }
    }
    let mut reader = evgate_io::open(path)
        .with_context(|| format!("cannot open event file {}", path.display()))?;
    let sensor = reader.sensor_size();
    let events = evgate_io::read_all(reader.as_mut())
        .with_context(|| format!("cannot decode {}", path.display()))?;
    Ok(Stream {
        events,
        labels: None,
        sensor,
    })
}

fn window_range(events: &[Event], t0: i64, t1: i64) -> std::ops::Range<usize> {
    let begin = events.partition_point(|e| e.t < t0);
    let end = events.partition_point(|e| e.t < t1);
    begin..end.max(begin)
}

fn window(events: &[Event], t0: i64, t1: i64) -> &[Event] {
    &events[window_range(events, t0, t1)]
}

fn label_colour(label: u16) -> u8 {
    if label == 0 {
        return STATIC_WORLD;
    }
    let colours = PALETTE.len() as u16 - FIRST_OBJECT_COLOUR as u16;
    FIRST_OBJECT_COLOUR + ((label - 1) % colours) as u8
}

fn nearest_frame(times: &[i64], t: i64) -> Option<usize> {
    (0..times.len()).min_by_key(|&i| (times[i] - t).abs())
}

/// Marks object pixels that touch a pixel of another id (4-neighbourhood).
fn draw_outlines(pixels: &mut [u8], mask: &[u8], sensor: SensorSize) {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    for y in 0..h {
        for x in 0..w {
            let id = mask[y * w + x];
            if id == 0 {
                continue;
            }
            let differs = |nx: usize, ny: usize| mask[ny * w + nx] != id;
            let edge = x == 0
                || y == 0
                || x + 1 == w
                || y + 1 == h
                || differs(x - 1, y)
                || differs(x + 1, y)
                || differs(x, y - 1)
                || differs(x, y + 1);
            if edge {
                pixels[y * w + x] = OUTLINE;
            }
        }
    }
}

fn upscale(pixels: &[u8], sensor: SensorSize, scale: usize) -> Vec<u8> {
    if scale == 1 {
        return pixels.to_vec();
    }
    let w = sensor.width as usize;
    let mut out = Vec::with_capacity(pixels.len() * scale * scale);
    for row in pixels.chunks(w) {
        let wide: Vec<u8> = row
            .iter()
            .flat_map(|&p| std::iter::repeat_n(p, scale))
            .collect();
        for _ in 0..scale {
            out.extend_from_slice(&wide);
        }
    }
    out
}

/// Where frames go: an animated GIF or a directory of PNGs.
enum FrameSink {
    Gif {
        path: PathBuf,
        encoder: gif::Encoder<std::io::BufWriter<fs::File>>,
        width: u16,
        height: u16,
        delay_cs: u16,
    },
    Png {
        dir: PathBuf,
        width: u32,
        height: u32,
        next: usize,
    },
}

impl FrameSink {
    fn create(
        path: &Path,
        width: usize,
        height: usize,
        window_ms: f64,
    ) -> anyhow::Result<FrameSink> {
        if path.extension().is_some_and(|e| e == "gif") {
            let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
                bail!("{width}×{height} is too large for a GIF (at most 65535 per side); lower --scale");
            };
            let file = fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?;
            let palette: Vec<u8> = PALETTE.iter().flatten().copied().collect();
            let mut encoder = gif::Encoder::new(std::io::BufWriter::new(file), w, h, &palette)
                .with_context(|| format!("cannot start GIF {}", path.display()))?;
            encoder
                .set_repeat(gif::Repeat::Infinite)
                .with_context(|| format!("cannot write {}", path.display()))?;
            Ok(FrameSink::Gif {
                path: path.to_path_buf(),
                encoder,
                width: w,
                height: h,
                // GIF delays are centiseconds; 2 cs is the shortest most viewers honour.
                delay_cs: (window_ms / 10.0).round().clamp(2.0, 65535.0) as u16,
            })
        } else {
            fs::create_dir_all(path)
                .with_context(|| format!("cannot create frame directory {}", path.display()))?;
            Ok(FrameSink::Png {
                dir: path.to_path_buf(),
                width: width as u32,
                height: height as u32,
                next: 0,
            })
        }
    }

    fn push(&mut self, indexed: &[u8]) -> anyhow::Result<()> {
        match self {
            FrameSink::Gif {
                path,
                encoder,
                width,
                height,
                delay_cs,
            } => {
                let mut frame =
                    gif::Frame::from_indexed_pixels(*width, *height, indexed.to_vec(), None);
                frame.delay = *delay_cs;
                encoder
                    .write_frame(&frame)
                    .with_context(|| format!("cannot write a frame to {}", path.display()))
            }
            FrameSink::Png {
                dir,
                width,
                height,
                next,
            } => {
                let path = dir.join(format!("frame-{next:05}.png"));
                *next += 1;
                let file = fs::File::create(&path)
                    .with_context(|| format!("cannot create {}", path.display()))?;
                let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), *width, *height);
                encoder.set_color(png::ColorType::Rgb);
                encoder.set_depth(png::BitDepth::Eight);
                let rgb: Vec<u8> = indexed.iter().flat_map(|&i| PALETTE[i as usize]).collect();
                encoder
                    .write_header()
                    .and_then(|mut writer| writer.write_image_data(&rgb))
                    .with_context(|| format!("cannot write {}", path.display()))
            }
        }
    }

    fn finish(self) -> anyhow::Result<()> {
        if let FrameSink::Gif { path, encoder, .. } = self {
            encoder
                .into_inner()
                .with_context(|| format!("cannot finish {}", path.display()))?
                .into_inner()
                .map_err(|e| anyhow::anyhow!("cannot flush {}: {}", path.display(), e.error()))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outlines_mark_object_borders_only() {
        let sensor = SensorSize::new(5, 5);
        let mut mask = vec![0u8; 25];
        for y in 1..4 {
            for x in 1..4 {
                mask[y * 5 + x] = 1;
            }
        }
        let mut pixels = vec![BACKGROUND; 25];
        draw_outlines(&mut pixels, &mask, sensor);
        assert_eq!(
            pixels[2 * 5 + 2],
            BACKGROUND,
            "the centre is inside the object"
        );
        assert_eq!(pixels[5 + 1], OUTLINE);
        assert_eq!(pixels[0], BACKGROUND);
    }

    #[test]
    fn label_colours_cycle_and_keep_world_grey() {
        assert_eq!(label_colour(0), STATIC_WORLD);
        assert_eq!(label_colour(1), FIRST_OBJECT_COLOUR);
        assert_eq!(
            label_colour(1 + (PALETTE.len() - FIRST_OBJECT_COLOUR as usize) as u16),
            FIRST_OBJECT_COLOUR
        );
    }

    #[test]
    fn windows_select_half_open_ranges() {
        let events: Vec<Event> = [0, 5, 10, 15]
            .iter()
            .map(|&t| Event::new(t, 0, 0, true))
            .collect();
        assert_eq!(window_range(&events, 5, 15), 1..3);
        assert_eq!(window_range(&events, 20, 30), 4..4);
    }
}
