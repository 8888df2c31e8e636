//! The gate's counters, published on the stats stream.

use iceoryx2::prelude::ZeroCopySend;
use serde::Serialize;

/// Sentinel of the `latest_*` fields before the first measurement.
pub const NOT_MEASURED: i64 = i64::MIN;

/// Everything the gate counts, as totals since the gate started (or since the input stream last
/// changed id).
///
/// Accounting identity, always true at publication:
/// `input_events = kept_events + suppressed_events + unjudged_passed_events + unjudged_dropped_events + dropped_events`.
///
/// `input_events` counts the events the ingest published from `joined_at_event_index` on (known
/// from each batch's `first_event_index + event_count`), `dropped_events` those the gate never received
/// (discarded by back-pressure, seen as holes in `first_event_index`). Unjudged events had no
/// usable forecast; the policy passed them (published on the kept stream) or dropped them
/// (published on the suppressed stream).
#[repr(C)]
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    bytemuck::Pod,
    bytemuck::Zeroable,
    ZeroCopySend,
    Serialize,
)]
#[serde(rename_all = "kebab-case")]
#[type_name("evgate::PipelineStats/v1")]
pub struct PipelineStats {
    /// Publication number from 0.
    pub sequence: u64,
    /// CLOCK_MONOTONIC of the publication, microseconds.
    pub published_at_monotonic_us: u64,
    /// `stream_id` of the input stream counted.
    pub stream_id: u64,
    /// Index of the first event of the stream this gate counts: 0 when it was listening before
    /// the stream began, else the first event of the first batch it received (a gate started
    /// mid-stream does not count what was published before it).
    pub joined_at_event_index: u64,
    /// Events the source published since `joined_at_event_index`.
    pub input_events: u64,
    /// Events a forecast judged and the mode passed.
    pub kept_events: u64,
    /// Events a forecast judged and the mode held back.
    pub suppressed_events: u64,
    /// Events no valid forecast judged, passed under `--no-forecast pass` (or `last-mask`).
    pub unjudged_passed_events: u64,
    /// Events no valid forecast judged, held back under `--no-forecast drop`.
    pub unjudged_dropped_events: u64,
    /// Events published by the ingest that never reached the gate (back-pressure discards).
    pub dropped_events: u64,
    /// Input batches gated.
    pub input_batches: u64,
    /// Holes detected in the input stream.
    pub gaps_detected: u64,
    /// Forecasts received from the inference service.
    pub forecasts_received: u64,
    /// Forecasts that judged at least one event.
    pub forecasts_used: u64,
    /// Forecasts ignored because their header did not describe their payload.
    pub forecasts_rejected: u64,
    /// Output samples (kept, suppressed, keep-bitmap) that some subscriber did not get because its
    /// buffer was full under the drop-and-count policy.
    pub output_samples_undelivered: u64,
    /// Time of the last input event gated, microseconds.
    pub latest_event_time_us: i64,
    /// Model runtime of the latest forecast, microseconds ([`NOT_MEASURED`] before the first).
    #[serde(serialize_with = "measured_or_null")]
    pub latest_model_runtime_us: i64,
    /// Age of the forecast that judged the latest batch: batch end time − forecast reference
    /// time, microseconds ([`NOT_MEASURED`] when the latest batch had no forecast).
    #[serde(serialize_with = "measured_or_null")]
    pub latest_prediction_age_us: i64,
    /// Input batch published → its outputs published, nanoseconds.
    #[serde(serialize_with = "measured_or_null")]
    pub latest_gate_latency_ns: i64,
    /// Time the gating kernel took on the latest batch, nanoseconds.
    #[serde(serialize_with = "measured_or_null")]
    pub latest_kernel_ns: i64,
    /// 1 once the end-of-stream batch has been gated.
    pub end_of_stream: u32,
    /// Keeps the record free of implicit padding; always zero.
    #[serde(skip)]
    pub reserved: u32,
}

/// Writes [`NOT_MEASURED`] as JSON `null`.
fn measured_or_null<S: serde::Serializer>(value: &i64, serializer: S) -> Result<S::Ok, S::Error> {
    if *value == NOT_MEASURED {
        serializer.serialize_none()
    } else {
        serializer.serialize_i64(*value)
    }
}

impl PipelineStats {
    /// Fresh counters for a stream.
    pub fn new(stream_id: u64) -> Self {
        Self {
            stream_id,
            latest_model_runtime_us: NOT_MEASURED,
            latest_prediction_age_us: NOT_MEASURED,
            latest_gate_latency_ns: NOT_MEASURED,
            latest_kernel_ns: NOT_MEASURED,
            ..Default::default()
        }
    }

    /// Events with a known fate.
    pub const fn accounted_events(&self) -> u64 {
        self.kept_events
            + self.suppressed_events
            + self.unjudged_passed_events
            + self.unjudged_dropped_events
            + self.dropped_events
    }

    /// True when every published event is accounted for.
    pub const fn is_balanced(&self) -> bool {
        self.accounted_events() == self.input_events
    }

    /// Events published downstream on the kept stream.
    pub const fn passed_events(&self) -> u64 {
        self.kept_events + self.unjudged_passed_events
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balance_counts_every_fate() {
        let mut stats = PipelineStats::new(1);
        stats.input_events = 15;
        stats.kept_events = 5;
        stats.suppressed_events = 4;
        stats.unjudged_passed_events = 3;
        stats.unjudged_dropped_events = 2;
        assert!(!stats.is_balanced());
        stats.dropped_events = 1;
        assert!(stats.is_balanced());
        assert_eq!(stats.passed_events(), 8);
    }
}
