//! The inference thread: voxelises a closed window, runs the network with its carried state and
//! thresholds the current mask and each horizon's keep region into bit masks ready to publish.

use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::time::{Duration, Instant};

use evgate_core::SensorSize;
use evgate_model::{ForecastError, Forecaster, ModelError};

use crate::window_handover::WindowHandover;
use crate::windowing::ClosedWindow;

#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Forecast(#[from] ForecastError),
}

/// A window to forecast from.
pub struct WindowJob {
    pub window: ClosedWindow,
    pub stream_id: u64,
    pub sensor: SensorSize,
    /// Stream epoch (new stream or restart) the window belongs to; the recurrent state is reset
    /// whenever it changes.
    pub stream_epoch: u64,
    /// When the receiving thread saw the window close.
    pub closed_at: Instant,
}

/// A finished forecast, in the layout of the forecast stream's payload.
pub struct ForecastReady {
    pub stream_id: u64,
    pub sensor: SensorSize,
    pub reference_time_us: i64,
    pub window_start_us: i64,
    pub closed_at: Instant,
    /// `1 + K` masks of `words_for(sensor.pixels())` words: current, then one per horizon.
    pub mask_words: Vec<u64>,
    pub events_in_window: usize,
    /// Pixels set in the current mask.
    pub current_mask_pixels: usize,
    pub voxelisation: Duration,
    pub inference: Duration,
    pub thresholding: Duration,
}

impl ForecastReady {
    /// Everything the forecast cost from closed window to masks: the header's model runtime.
    pub fn processing(&self) -> Duration {
        self.voxelisation + self.inference + self.thresholding
    }
}

pub struct Worker {
    forecaster: Forecaster,
    horizons_ms: Vec<f32>,
    stream_epoch: Option<u64>,
}

impl Worker {
    pub fn new(forecaster: Forecaster, horizons_ms: Vec<f32>) -> Self {
        Self {
            forecaster,
            horizons_ms,
            stream_epoch: None,
        }
    }

    /// Takes windows until the hand-over closes, sending one result per window; stops at the first
    /// error, after sending it.
    pub fn run(
        mut self,
        slot: Arc<WindowHandover<WindowJob>>,
        results: Sender<Result<ForecastReady, WorkerError>>,
    ) {
        while let Some(job) = slot.take() {
            let result = self.forecast(job);
            let failed = result.is_err();
            if results.send(result).is_err() || failed {
                return;
            }
        }
    }

    pub fn forecast(&mut self, job: WindowJob) -> Result<ForecastReady, WorkerError> {
        if self.stream_epoch != Some(job.stream_epoch) {
            if self.stream_epoch.is_some() {
                self.forecaster.reset_state()?;
            }
            self.stream_epoch = Some(job.stream_epoch);
        }
        let forecast = self.forecaster.forecast(
            job.sensor,
            &job.window.events,
            job.window.span,
            &self.horizons_ms,
        )?;
        // The gate judges a horizon's events by its keep region, so that is what goes out.
        let mut mask_words =
            Vec::with_capacity((1 + forecast.keep.len()) * forecast.current.as_words().len());
        for mask in std::iter::once(forecast.current).chain(forecast.keep) {
            mask_words.extend_from_slice(mask.as_words());
        }
        Ok(ForecastReady {
            stream_id: job.stream_id,
            sensor: job.sensor,
            reference_time_us: job.window.reference_time_us(),
            window_start_us: job.window.span.start,
            closed_at: job.closed_at,
            mask_words,
            events_in_window: job.window.events.len(),
            current_mask_pixels: forecast.current.count_ones(),
            voxelisation: forecast.voxelisation,
            inference: forecast.inference,
            thresholding: forecast.thresholding,
        })
    }
}
