//! Turns an `evgate eval` input path into a recording to score: a simulator sequence
//! (labelled `.npz`, every metric), or any event file evgate-io decodes (DSEC `events.h5`
//! when built with the `dsec` feature, RAW, AEDAT 4, …) as an events-only recording.

use std::path::Path;

use anyhow::Context;
use evgate_core::{Event, SensorSize};
use evgate_eval::recording::parent_name;
use evgate_eval::{EvalConfig, Recording};
use evgate_io::npz::NpzReader;
use evgate_io::sequence::LabelledSequence;
use evgate_io::{open_with, OpenOptions};

/// How an input is read, beyond the file itself.
#[derive(Clone, Debug, Default)]
pub struct InputOptions {
    /// Averaging group of every input (default: the parent folder's name, or the simulator
    /// preset of a labelled sequence).
    pub group: Option<String>,
    /// Sensor size for event files whose header gives none.
    pub sensor_size: Option<SensorSize>,
}

/// True for the simulator's labelled sequences (docs/sequence-format.md), which hold `ref_ts`.
fn is_labelled_sequence(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "npz")
        && NpzReader::open(path).is_ok_and(|npz| npz.contains("ref_ts"))
}

/// Reads one input; with `max-seconds-per-sequence` set, events past what the scored span
/// needs (its last reference time plus the longest horizon) are not read.
pub fn load_recording(
    path: &Path,
    config: &EvalConfig,
    options: &InputOptions,
) -> anyhow::Result<Recording> {
    if is_labelled_sequence(path) {
        let sequence = LabelledSequence::read(path)
            .with_context(|| format!("cannot read labelled sequence {}", path.display()))?;
        let mut recording = Recording::from_labelled(sequence, path)?;
        if let Some(group) = &options.group {
            recording.group = group.clone();
        }
        return Ok(recording);
    }
    let (sensor_size, events) = read_events(path, config, options)?;
    tracing::info!(
        input = %path.display(),
        events = events.len(),
        sensor = %sensor_size,
        "no ground truth in this recording: scoring kept ratio, event rates, runtime and \
         prediction age only"
    );
    let group = options.group.clone().unwrap_or_else(|| parent_name(path));
    let period_us = i64::from(config.window_ms) * 1000;
    Ok(Recording::events_only(
        path,
        group,
        sensor_size,
        events,
        period_us,
    )?)
}

fn read_events(
    path: &Path,
    config: &EvalConfig,
    options: &InputOptions,
) -> anyhow::Result<(SensorSize, Vec<Event>)> {
    let open_options = OpenOptions {
        format: None,
        sensor_size: options.sensor_size,
    };
    let mut reader = open_with(path, &open_options)
        .with_context(|| format!("cannot open event file {}", path.display()))?;
    let last_horizon_ms = config.horizons_ms.last().copied().unwrap_or(0);
    let span_limit_us = config.max_seconds_per_sequence.map(|seconds| {
        (seconds * 1e6) as i64 + i64::from(last_horizon_ms.max(config.gate_span_ms)) * 1000
    });
    let mut events: Vec<Event> = Vec::new();
    let mut chunk = Vec::new();
    loop {
        let read = reader
            .read_chunk(&mut chunk)
            .with_context(|| format!("cannot decode {}", path.display()))?;
        if read == 0 {
            break;
        }
        let first = events.first().or(chunk.first()).map_or(0, |e| e.t);
        match span_limit_us {
            Some(limit) if chunk.last().is_some_and(|e| e.t > first + limit) => {
                events.extend(chunk.iter().filter(|e| e.t <= first + limit));
                break;
            }
            _ => events.extend_from_slice(&chunk),
        }
    }
    let report = reader.report();
    tracing::debug!(input = %path.display(), ?report, "decoded");
    // Decoders pass small timestamp regressions through (and count them); windows need order.
    if events.windows(2).any(|pair| pair[1].t < pair[0].t) {
        events.sort_by_key(|e| e.t);
    }
    Ok((reader.sensor_size(), events))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_files_become_events_only_recordings_limited_to_the_scored_span() {
        let folder = tempfile::tempdir().unwrap();
        let path = folder.path().join("drive").join("events.csv");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let text: String = (0..400)
            .map(|k| format!("{} {} {} {}\n", 1_000 + k * 1_000, k % 20, k % 10, k % 2))
            .collect();
        std::fs::write(&path, text).unwrap();
        let options = InputOptions {
            group: None,
            sensor_size: Some(SensorSize::new(20, 10)),
        };
        let config = EvalConfig::default();
        let recording = load_recording(&path, &config, &options).unwrap();
        assert_eq!(recording.group, "drive");
        assert_eq!(recording.events.len(), 400);
        assert_eq!(recording.sensor_size, SensorSize::new(20, 10));
        assert_eq!(
            recording.ground_truth(),
            evgate_eval::GroundTruth::EventsOnly
        );
        // Every 50 ms from the first event; the first full window ends at 51 ms.
        assert_eq!(recording.reference_times_us.first(), Some(&51_000));

        let limited = EvalConfig {
            max_seconds_per_sequence: Some(0.1),
            ..EvalConfig::default()
        };
        let recording = load_recording(&path, &limited, &options).unwrap();
        // 100 ms scored plus the 100 ms horizon after it.
        assert_eq!(recording.events.last().unwrap().t, 201_000);
    }

    #[test]
    fn unreadable_inputs_name_the_file() {
        let error = load_recording(
            Path::new("/nonexistent/run.raw"),
            &EvalConfig::default(),
            &InputOptions::default(),
        )
        .unwrap_err();
        assert!(
            format!("{error:#}").contains("/nonexistent/run.raw"),
            "{error:#}"
        );
    }
}
