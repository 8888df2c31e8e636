//! `evgate convert IN OUT`: re-encode an event file; the output format comes from OUT's
//! extension (`.csv`/`.txt`: `t,x,y,p` with t in µs and p in {0,1}; `.raw`: EVT 3.0; `.evg`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use evgate_core::SensorSize;
use evgate_io::reader::UNBOUNDED_SENSOR;
use evgate_io::{create, open_with_time_low_rule, DecodeReport, Evt3TimeLow, Format, OpenOptions};
use serde::Serialize;

use crate::info::{byte_progress, inspect};

#[derive(Args)]
pub struct ConvertArgs {
    /// Input event file (any format `evgate info` reads).
    pub input: PathBuf,
    /// Output file: .csv/.txt, .raw (EVT 3.0) or .evg.
    pub output: PathBuf,
    /// Sensor size WxH: required context for text inputs (otherwise the extent of the events is
    /// used) and old headers without geometry; overrides the input's size otherwise.
    #[arg(long, value_parser = evgate_io::header::parse_sensor_flag)]
    pub sensor: Option<SensorSize>,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
    /// EVT 3.0 input only: how a TIME_LOW smaller than the previous one is read: `evt3` (the
    /// format's rule: a step back) or `carry-on-step-back` (adds 4096 µs, as expelliarmus does).
    #[arg(long, default_value = "evt3")]
    pub evt3_time_low: Evt3TimeLow,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct ConvertSummary {
    input: PathBuf,
    input_format: String,
    output: PathBuf,
    output_format: String,
    sensor_width: u16,
    sensor_height: u16,
    events: u64,
    input_report: DecodeReport,
    seconds: f64,
    events_per_s: f64,
}

pub fn run(args: ConvertArgs) -> anyhow::Result<()> {
    let output_format = Format::for_output(&args.output).with_context(|| {
        format!(
            "{}: no encoder for this extension (accepted: .csv, .txt, .raw (EVT 3.0), .evg)",
            args.output.display()
        )
    })?;
    let started = Instant::now();
    let options = OpenOptions {
        sensor_size: args.sensor,
        ..OpenOptions::default()
    };
    let mut reader = open_with_time_low_rule(&args.input, &options, args.evt3_time_low)?;
    let mut sensor_size = reader.sensor_size();
    if sensor_size == UNBOUNDED_SENSOR && output_format != Format::Csv {
        // Text carries no sensor size: a first pass measures the extent of the events.
        tracing::info!(
            "{}: no --sensor given; measuring the event extent first",
            args.input.display()
        );
        let info = inspect(&args.input, None, args.evt3_time_low)?;
        sensor_size = SensorSize::new(
            info.max_x.map_or(1, |x| x.saturating_add(1)),
            info.max_y.map_or(1, |y| y.saturating_add(1)),
        );
    }
    let bytes = std::fs::metadata(&args.input)
        .with_context(|| format!("{}: cannot read metadata", args.input.display()))?
        .len();
    let mut writer = create(&args.output, sensor_size)?;
    let progress = byte_progress(&args.input, bytes);
    let mut chunk = Vec::new();
    let mut events = 0u64;
    while reader.read_chunk(&mut chunk)? > 0 {
        writer.write(&chunk)?;
        events += chunk.len() as u64;
        progress.set_position(reader.bytes_read());
    }
    writer.finish()?;
    progress.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    let summary = ConvertSummary {
        input: args.input.clone(),
        input_format: reader.format().to_string(),
        output: args.output.clone(),
        output_format: output_format.to_string(),
        sensor_width: sensor_size.width,
        sensor_height: sensor_size.height,
        events,
        input_report: reader.report().clone(),
        seconds,
        events_per_s: if seconds > 0.0 {
            events as f64 / seconds
        } else {
            0.0
        },
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let report = &summary.input_report;
        println!(
            "{} ({}) -> {} ({}): {} events, sensor {}x{}, {:.3} s ({:.0} events/s); input repairs: {} dropped outside the sensor, {} dropped outside the time range, {} time regressions, {} skipped words",
            summary.input.display(),
            summary.input_format,
            summary.output.display(),
            summary.output_format,
            summary.events,
            summary.sensor_width,
            summary.sensor_height,
            summary.seconds,
            summary.events_per_s,
            report.dropped_out_of_sensor,
            report.dropped_out_of_time_range,
            report.time_regressions,
            report.skipped_words
        );
    }
    Ok(())
}
