//! `evgate info FILE`: what an event file holds (format, sensor, counts, times, rate, polarity
//! balance, ordering problems and repairs), as text or JSON.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use evgate_core::SensorSize;
use evgate_io::reader::UNBOUNDED_SENSOR;
use evgate_io::{open_with_time_low_rule, DecodeReport, EventReader, Evt3TimeLow, OpenOptions};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

#[derive(Args)]
pub struct InfoArgs {
    /// Event file: .raw (EVT 2.0/3.0), .dat, .aedat4, .csv/.txt, .evg, EVIMO .npz, an EVIMO2
    /// sequence folder, DSEC .h5 (builds with `--features dsec`); detected from content.
    pub file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Sensor size as WxH, for files whose header has none (text, old RAW/DAT); overrides the
    /// header otherwise.
    #[arg(long, value_parser = evgate_io::header::parse_sensor_flag)]
    pub sensor: Option<SensorSize>,
    /// EVT 3.0 only: how a TIME_LOW smaller than the previous one is read: `evt3` (the format's
    /// rule: a step back) or `carry-on-step-back` (adds 4096 µs, as expelliarmus does).
    #[arg(long, default_value = "evt3")]
    pub evt3_time_low: Evt3TimeLow,
}

/// Everything `info` reports; the JSON keys are these fields in kebab-case.
#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct FileInfo {
    pub path: PathBuf,
    pub format: String,
    pub bytes: u64,
    /// `None` for text files read without `--sensor`.
    pub sensor_width: Option<u16>,
    pub sensor_height: Option<u16>,
    pub events: u64,
    pub first_t_us: Option<i64>,
    pub last_t_us: Option<i64>,
    pub duration_s: f64,
    pub rate_events_per_s: f64,
    pub on_events: u64,
    pub off_events: u64,
    /// ON events / all events.
    pub on_fraction: f64,
    /// Largest column and row seen (the extent of text files).
    pub max_x: Option<u16>,
    pub max_y: Option<u16>,
    pub min_t_us: Option<i64>,
    pub max_t_us: Option<i64>,
    pub report: DecodeReport,
    pub evt3_time_low: Evt3TimeLow,
    pub decode_seconds: f64,
}

/// A progress bar over the bytes of `path`, shown when stderr is a terminal.
pub fn byte_progress(path: &Path, bytes: u64) -> ProgressBar {
    let bar = ProgressBar::new(bytes);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{bar:40}] {bytes}/{total_bytes} ({bytes_per_sec}, eta {eta})",
        )
        .expect("valid progress template")
        .progress_chars("=> "),
    );
    bar.set_message(path.display().to_string());
    bar
}

pub fn inspect(
    file: &Path,
    sensor: Option<SensorSize>,
    evt3_time_low: Evt3TimeLow,
) -> anyhow::Result<FileInfo> {
    let bytes = std::fs::metadata(file)
        .with_context(|| format!("{}: cannot read metadata", file.display()))?
        .len();
    let options = OpenOptions {
        sensor_size: sensor,
        ..OpenOptions::default()
    };
    let started = Instant::now();
    let mut reader: Box<dyn EventReader> = open_with_time_low_rule(file, &options, evt3_time_low)?;
    let progress = byte_progress(file, bytes);
    let mut chunk = Vec::new();
    let (mut on, mut count) = (0u64, 0u64);
    let (mut first_t, mut last_t, mut min_t, mut max_t) = (None, None, None, None);
    let (mut max_x, mut max_y): (Option<u16>, Option<u16>) = (None, None);
    while reader.read_chunk(&mut chunk)? > 0 {
        first_t = first_t.or(chunk.first().map(|e| e.t));
        last_t = chunk.last().map(|e| e.t);
        for event in &chunk {
            on += event.is_on() as u64;
            min_t = Some(min_t.map_or(event.t, |m: i64| m.min(event.t)));
            max_t = Some(max_t.map_or(event.t, |m: i64| m.max(event.t)));
            max_x = Some(max_x.map_or(event.x, |m| m.max(event.x)));
            max_y = Some(max_y.map_or(event.y, |m| m.max(event.y)));
        }
        count += chunk.len() as u64;
        progress.set_position(reader.bytes_read());
    }
    progress.finish_and_clear();
    let duration_s = match (min_t, max_t) {
        // In f64: the difference of extreme i64 times overflows i64.
        (Some(a), Some(b)) => (b as f64 - a as f64) * 1e-6,
        _ => 0.0,
    };
    let sensor_size = Some(reader.sensor_size()).filter(|&s| s != UNBOUNDED_SENSOR);
    Ok(FileInfo {
        path: file.to_path_buf(),
        format: reader.format().to_string(),
        bytes,
        sensor_width: sensor_size.map(|s| s.width),
        sensor_height: sensor_size.map(|s| s.height),
        events: count,
        first_t_us: first_t,
        last_t_us: last_t,
        duration_s,
        rate_events_per_s: if duration_s > 0.0 {
            count as f64 / duration_s
        } else {
            0.0
        },
        on_events: on,
        off_events: count - on,
        on_fraction: if count > 0 {
            on as f64 / count as f64
        } else {
            0.0
        },
        max_x,
        max_y,
        min_t_us: min_t,
        max_t_us: max_t,
        report: reader.report().clone(),
        evt3_time_low,
        decode_seconds: started.elapsed().as_secs_f64(),
    })
}

pub fn run(args: InfoArgs) -> anyhow::Result<()> {
    let info = inspect(&args.file, args.sensor, args.evt3_time_low)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    let show = |v: Option<i64>| v.map_or("-".to_owned(), |v| v.to_string());
    println!("file            {}", info.path.display());
    println!("format          {}", info.format);
    println!("bytes           {}", info.bytes);
    match (info.sensor_width, info.sensor_height) {
        (Some(w), Some(h)) => println!("sensor          {w}x{h}"),
        _ => println!(
            "sensor          not given (text file; pass --sensor WxH to check coordinates)"
        ),
    }
    if let (Some(x), Some(y)) = (info.max_x, info.max_y) {
        println!("extent          x 0..={x}, y 0..={y}");
    }
    println!("events          {}", info.events);
    println!("first t         {} us", show(info.first_t_us));
    println!("last t          {} us", show(info.last_t_us));
    println!("duration        {:.6} s", info.duration_s);
    println!("rate            {:.0} events/s", info.rate_events_per_s);
    println!(
        "polarity        {} ON, {} OFF ({:.1} % ON)",
        info.on_events,
        info.off_events,
        info.on_fraction * 100.0
    );
    let report = &info.report;
    println!(
        "time order      {} regressions{}",
        report.time_regressions,
        report
            .first_time_regression_index
            .map_or(String::new(), |i| format!(
                " (first at event {i}, largest {} us back)",
                report.largest_time_regression_us
            ))
    );
    println!(
        "dropped         {} outside the sensor{}",
        report.dropped_out_of_sensor,
        report
            .first_out_of_sensor_offset
            .map_or(String::new(), |o| format!(" (first at byte {o})"))
    );
    println!(
        "dropped         {} outside ±2^60 us{}",
        report.dropped_out_of_time_range,
        report
            .first_out_of_time_range_offset
            .map_or(String::new(), |o| format!(" (first at byte {o})"))
    );
    println!(
        "skipped words   {}{}",
        report.skipped_words,
        report
            .first_skipped_word_offset
            .map_or(String::new(), |o| format!(" (first at byte {o})"))
    );
    println!(
        "time jumps      {} TIME_HIGH words ignored as corrupt{}",
        report.implausible_time_jumps,
        report
            .first_implausible_time_jump_offset
            .map_or(String::new(), |o| format!(" (first at byte {o})"))
    );
    println!("decode time     {:.3} s", info.decode_seconds);
    Ok(())
}
