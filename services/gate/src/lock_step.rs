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

fn describes(forecast: &StoredForecast, header: &BatchHeader) -> bool {
    forecast.header.source_stream_id == header.stream_id && forecast.sensor() == header.sensor()
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
                    !describes(newest, &batch.header) || newest.header.reference_time_us > last.t
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
            .filter(|forecast| describes(forecast, &batch.header))
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
            describes(forecast, &judged.header) && forecast.header.reference_time_us <= last.t
        }) {
            self.forecasts.drain(..newest_used);
        }
    }
}
