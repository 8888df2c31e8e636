//! The inference thread: voxelises a closed window, runs the network with its carried state and
//! thresholds the current and forecast logits into bit masks ready to publish.

use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::time::{Duration, Instant};

use evgate_core::{words_for, BitMask, MaskError, SensorSize, VoxelError, VoxelGrid};
use evgate_model::{ModelError, ModelRuntime};

use crate::latest_slot::LatestSlot;
use crate::windowing::ClosedWindow;

#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("cannot build the voxel grid of a {sensor} stream: {source}")]
    Voxel {
        sensor: SensorSize,
        source: VoxelError,
    },
    #[error("cannot threshold the logits into a {sensor} mask: {source}")]
    Mask {
        sensor: SensorSize,
        source: MaskError,
    },
    #[error(
        "the stream's sensor {sensor} pads to {padded}, but model {model} was exported for a \
         {input} input; use a model exported for this sensor size"
    )]
    SensorMismatch {
        sensor: SensorSize,
        padded: SensorSize,
        input: SensorSize,
        model: String,
    },
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
    /// `1 + K` masks of `words_for(sensor)` words: current, then one per horizon.
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
    runtime: ModelRuntime,
    horizons_ms: Vec<f32>,
    threshold_logit: f32,
    grid: Option<VoxelGrid>,
    mask: Option<BitMask>,
    stream_epoch: Option<u64>,
}

impl Worker {
    pub fn new(runtime: ModelRuntime, horizons_ms: Vec<f32>, threshold_logit: f32) -> Self {
        Self {
            runtime,
            horizons_ms,
            threshold_logit,
            grid: None,
            mask: None,
            stream_epoch: None,
        }
    }

    /// Takes windows until the slot closes, sending one result per window; stops at the first
    /// error, after sending it.
    pub fn run(
        mut self,
        slot: Arc<LatestSlot<WindowJob>>,
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
                self.runtime.reset_state()?;
            }
            self.stream_epoch = Some(job.stream_epoch);
        }
        let started = Instant::now();
        let grid = grid_for(&mut self.grid, &self.runtime, job.sensor)?;
        grid.clear();
        grid.accumulate(&job.window.events, job.window.span);
        grid.normalise();
        let voxelisation = started.elapsed();

        let output = self.runtime.forecast(grid.as_slice(), &self.horizons_ms)?;
        let inference = output.inference_time();

        let started = Instant::now();
        let row_stride = output.width();
        let threshold = self.threshold_logit;
        let mask = mask_for(&mut self.mask, job.sensor)?;
        let words = words_for(job.sensor);
        let mut mask_words = Vec::with_capacity((1 + output.horizon_count()) * words);
        let mask_error = |source| WorkerError::Mask {
            sensor: job.sensor,
            source,
        };
        mask.fill_from_logits(output.mask_logits(), row_stride, threshold)
            .map_err(mask_error)?;
        let current_mask_pixels = mask.count_ones();
        mask_words.extend_from_slice(mask.as_words());
        for logits in output.future_mask_logits() {
            mask.fill_from_logits(logits, row_stride, threshold)
                .map_err(mask_error)?;
            mask_words.extend_from_slice(mask.as_words());
        }
        let thresholding = started.elapsed();

        Ok(ForecastReady {
            stream_id: job.stream_id,
            sensor: job.sensor,
            reference_time_us: job.window.reference_time_us(),
            window_start_us: job.window.span.start,
            closed_at: job.closed_at,
            mask_words,
            events_in_window: job.window.events.len(),
            current_mask_pixels,
            voxelisation,
            inference,
            thresholding,
        })
    }
}

/// The reusable grid for `sensor`, rebuilt when the sensor changes; the padded sensor must be
/// the model's input size.
fn grid_for<'a>(
    cached: &'a mut Option<VoxelGrid>,
    runtime: &ModelRuntime,
    sensor: SensorSize,
) -> Result<&'a mut VoxelGrid, WorkerError> {
    let grid = match cached.take() {
        Some(grid) if grid.sensor() == sensor => grid,
        _ => {
            let bins = runtime.metadata().bins as usize;
            let grid = VoxelGrid::new(sensor, bins)
                .map_err(|source| WorkerError::Voxel { sensor, source })?;
            let input = runtime.input_size();
            if grid.padded() != input {
                return Err(WorkerError::SensorMismatch {
                    sensor,
                    padded: grid.padded(),
                    input,
                    model: runtime.model_path().display().to_string(),
                });
            }
            grid
        }
    };
    Ok(cached.insert(grid))
}

/// The reusable mask for `sensor`, rebuilt when the sensor changes.
fn mask_for(cached: &mut Option<BitMask>, sensor: SensorSize) -> Result<&mut BitMask, WorkerError> {
    let mask = match cached.take() {
        Some(mask) if mask.size() == sensor => mask,
        _ => BitMask::new(sensor).map_err(|source| WorkerError::Mask { sensor, source })?,
    };
    Ok(cached.insert(mask))
}
