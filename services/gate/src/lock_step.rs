//! `--lock-step`: each batch waits, copied out of shared memory, until every forecast that
//! judges its events is in, and each event is judged by the forecast of the newest window that
//! ended at or before it, as `evgate eval` judges the events of [t, next t) with the forecast
//! of t. The live gate instead judges a batch at once with the newest forecast it has.
//!
//! Forecasts of one stream arrive in time order (the inference service's `--every-window`), so
//! a batch's forecasts are all in once a forecast of its stream passes its last event, or once a
//! forecast of another stream arrives. At the end of a stream the inference service forecasts
//! the window ending at the stream's end, which passes every event.

use std::collections::VecDeque;

use evgate_core::{Event, Forecast};
use evgate_ipc::BatchHeader;

use crate::forecast_store::StoredForecast;

/// A batch waiting for its forecasts.
pub struct HeldBatch {
    pub header: BatchHeader,
    pub events: Vec<Event>,
}

#[derive(Default)]
pub struct LockStep {
    held: VecDeque<HeldBatch>,
    /// In arrival order; only those that may still judge a held or later batch.
    forecasts: VecDeque<StoredForecast>,
}

impl LockStep {
    pub fn hold(&mut self, header: BatchHeader, events: &[Event]) {
        self.held.push_back(HeldBatch {
            header,
            events: events.to_vec(),
        });
    }

    pub fn add_forecast(&mut self, forecast: StoredForecast) {
        self.forecasts.push_back(forecast);
    }

    /// Batches waiting for forecasts.
    pub fn held_batches(&self) -> usize {
        self.held.len()
    }

    /// The oldest held batch if its forecasts are all in (any held batch when `flush`).
    pub fn next_ready(&mut self, flush: bool) -> Option<HeldBatch> {
        let batch = self.held.front()?;
        let ready = flush
            || batch.events.last().is_none_or(|last| {
                self.forecasts.back().is_some_and(|newest| {
                    !newest.describes(&batch.header) || newest.header.reference_time_us > last.t
                })
            });
        if ready {
            self.held.pop_front()
        } else {
            None
        }
    }

    /// The forecasts that judge `batch`, oldest first.
    pub fn forecasts_for(&self, batch: &HeldBatch) -> Vec<Forecast<'_>> {
        self.forecasts
            .iter()
            .filter(|forecast| forecast.describes(&batch.header))
            .map(StoredForecast::forecast)
            .collect()
    }

    /// Forgets the forecasts that no batch after `judged` can need: every one before the
    /// newest of its stream at or before its last event.
    pub fn judged(&mut self, judged: &HeldBatch) {
        let Some(last) = judged.events.last() else {
            return;
        };
        if let Some(newest_used) = self.forecasts.iter().rposition(|forecast| {
            forecast.describes(&judged.header) && forecast.header.reference_time_us <= last.t
        }) {
            self.forecasts.drain(..newest_used);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use evgate_ipc::ForecastHeader;

    const STREAM: u64 = 7;

    fn batch(stream_id: u64, times: &[i64]) -> (BatchHeader, Vec<Event>) {
        let header = BatchHeader {
            stream_id,
            event_count: times.len() as u64,
            width: 8,
            height: 4,
            ..BatchHeader::default()
        };
        (
            header,
            times.iter().map(|&t| Event::new(t, 1, 1, true)).collect(),
        )
    }

    fn forecast(stream_id: u64, reference_time_us: i64) -> StoredForecast {
        let mut horizons_us = [0; evgate_ipc::MAX_HORIZONS];
        horizons_us[0] = 10_000;
        let header = ForecastHeader {
            source_stream_id: stream_id,
            reference_time_us,
            window_start_us: reference_time_us - 50_000,
            horizons_us,
            width: 8,
            height: 4,
            horizon_count: 1,
            words_per_mask: 1,
            ..ForecastHeader::default()
        };
        StoredForecast::copy_from(header, &[0, 0]).unwrap()
    }

    fn references(lock_step: &LockStep, batch: &HeldBatch) -> Vec<i64> {
        lock_step
            .forecasts_for(batch)
            .iter()
            .map(|forecast| forecast.horizons.reference_time_us())
            .collect()
    }

    #[test]
    fn a_batch_waits_until_a_forecast_of_its_stream_passes_its_last_event() {
        let mut lock_step = LockStep::default();
        for times in [&[100_000, 200_000][..], &[250_000, 300_000]] {
            let (header, events) = batch(STREAM, times);
            lock_step.hold(header, &events);
        }
        assert!(lock_step.next_ready(false).is_none(), "no forecast yet");
        lock_step.add_forecast(forecast(STREAM, 50_000));
        assert!(
            lock_step.next_ready(false).is_none(),
            "50 ms does not pass 200 ms"
        );
        lock_step.add_forecast(forecast(STREAM, 210_000));
        let first = lock_step.next_ready(false).expect("210 ms passes 200 ms");
        assert_eq!(references(&lock_step, &first), vec![50_000, 210_000]);
        lock_step.judged(&first);
        assert!(
            lock_step.next_ready(false).is_none(),
            "210 ms does not pass 300 ms"
        );
        // Forecasts of one stream come in time order, so another stream's ends this one's.
        lock_step.add_forecast(forecast(STREAM + 1, 20_000));
        let second = lock_step
            .next_ready(false)
            .expect("another stream's forecast");
        // 50 ms stays: events of (200, 210) ms would still be its.
        assert_eq!(references(&lock_step, &second), vec![50_000, 210_000]);
        lock_step.judged(&second);
        assert_eq!(references(&lock_step, &second), vec![210_000]);
        assert_eq!(lock_step.held_batches(), 0);
    }

    #[test]
    fn an_empty_batch_and_a_flush_need_no_forecast() {
        let mut lock_step = LockStep::default();
        let (header, events) = batch(STREAM, &[]);
        lock_step.hold(header, &events);
        let (header, events) = batch(STREAM, &[5_000]);
        lock_step.hold(header, &events);
        assert!(
            lock_step.next_ready(false).is_some(),
            "the end-of-stream marker"
        );
        assert!(lock_step.next_ready(false).is_none());
        assert!(lock_step.next_ready(true).is_some(), "flushed at a stop");
    }
}
