//! From a window of events to forecast masks, the one way `evgate-infer` and `evgate eval` both
//! take: voxelise the window (binned `downsample`×`downsample` when asked), pad it into the
//! model's input, run the network with its carried state, and threshold the current and future
//! mask logits at the model's threshold into full-resolution bit masks.

use std::time::{Duration, Instant};

use evgate_core::{BitMask, Event, MaskError, SensorSize, TimeSpan, VoxelError, VoxelGrid};

use crate::runtime::{ModelError, ModelRuntime};

/// Why a window could not be forecast.
#[derive(Debug, thiserror::Error)]
pub enum ForecastError {
    #[error("cannot build the voxel grid of a {sensor} stream: {source}")]
    Voxel {
        sensor: SensorSize,
        source: VoxelError,
    },
    #[error("model {model}: {source}")]
    InputTooSmall { model: String, source: VoxelError },
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("cannot threshold the logits into a {sensor} mask: {source}")]
    Mask {
        sensor: SensorSize,
        source: MaskError,
    },
}

/// The masks of one window, borrowed from the [`Forecaster`] until its next forecast.
pub struct Forecast<'a> {
    /// The mask at the window's end.
    pub current: &'a BitMask,
    /// One mask per requested horizon, in order.
    pub futures: &'a [BitMask],
    pub voxelisation: Duration,
    pub inference: Duration,
    pub thresholding: Duration,
}

impl Forecast<'_> {
    /// Everything the forecast cost, from events to masks.
    pub fn processing(&self) -> Duration {
        self.voxelisation + self.inference + self.thresholding
    }
}

pub struct Forecaster {
    runtime: ModelRuntime,
    threshold_logit: f32,
    downsample: u16,
    grid: Option<VoxelGrid>,
    /// The current mask, then one per horizon.
    masks: Vec<BitMask>,
}

impl Forecaster {
    /// `threshold_logit`: above it a pixel is moving (the model's own is
    /// `runtime.metadata().threshold_logit`); `downsample`: the side of the square of sensor
    /// pixels one input cell bins (1: none).
    pub fn new(runtime: ModelRuntime, threshold_logit: f32, downsample: u16) -> Self {
        Self {
            runtime,
            threshold_logit,
            downsample,
            grid: None,
            masks: Vec::new(),
        }
    }

    pub fn runtime(&self) -> &ModelRuntime {
        &self.runtime
    }

    pub fn threshold_logit(&self) -> f32 {
        self.threshold_logit
    }

    /// Forgets the recurrent state: the next window starts a new stream.
    pub fn reset_state(&mut self) -> Result<(), ModelError> {
        self.runtime.reset_state()
    }

    /// Checks that a `sensor` stream fits the model's input, binned as set, before any window.
    pub fn check_sensor(&mut self, sensor: SensorSize) -> Result<(), ForecastError> {
        grid_for(&mut self.grid, &self.runtime, sensor, self.downsample).map(|_| ())
    }

    /// Forecasts from the `events` of `window` on a `sensor` stream at `horizons_ms`.
    pub fn forecast(
        &mut self,
        sensor: SensorSize,
        events: &[Event],
        window: TimeSpan,
        horizons_ms: &[f32],
    ) -> Result<Forecast<'_>, ForecastError> {
        let started = Instant::now();
        let grid = grid_for(&mut self.grid, &self.runtime, sensor, self.downsample)?;
        grid.clear();
        grid.accumulate(events, window);
        grid.normalise();
        let voxelisation = started.elapsed();
        let input = grid.as_input(self.runtime.input_size()).map_err(|source| {
            ForecastError::InputTooSmall {
                model: self.runtime.model_path().display().to_string(),
                source,
            }
        })?;
        let output = self.runtime.forecast(&input, horizons_ms)?;
        let inference = output.inference_time();

        let started = Instant::now();
        let mask_error = |source| ForecastError::Mask { sensor, source };
        if self.masks.len() != 1 + output.horizon_count()
            || self.masks.first().map(BitMask::size) != Some(sensor)
        {
            self.masks = (0..=output.horizon_count())
                .map(|_| BitMask::new(sensor))
                .collect::<Result<_, _>>()
                .map_err(mask_error)?;
        }
        let row_stride = output.width();
        let logits = std::iter::once(output.mask_logits()).chain(output.future_mask_logits());
        for (mask, logits) in self.masks.iter_mut().zip(logits) {
            mask.fill_from_binned_logits(logits, row_stride, self.threshold_logit, self.downsample)
                .map_err(mask_error)?;
        }
        let thresholding = started.elapsed();
        let (current, futures) = self.masks.split_first().expect("1 + K masks");
        Ok(Forecast {
            current,
            futures,
            voxelisation,
            inference,
            thresholding,
        })
    }
}

/// The reusable grid for `sensor`, rebuilt (and checked against the model's input) when the
/// sensor changes.
fn grid_for<'a>(
    cached: &'a mut Option<VoxelGrid>,
    runtime: &ModelRuntime,
    sensor: SensorSize,
    downsample: u16,
) -> Result<&'a mut VoxelGrid, ForecastError> {
    let grid = match cached.take() {
        Some(grid) if grid.sensor() == sensor => grid,
        _ => {
            let bins = runtime.metadata().bins as usize;
            let grid = VoxelGrid::downsampled(sensor, bins, downsample)
                .map_err(|source| ForecastError::Voxel { sensor, source })?;
            grid.as_input(runtime.input_size())
                .map_err(|source| ForecastError::InputTooSmall {
                    model: runtime.model_path().display().to_string(),
                    source,
                })?;
            grid
        }
    };
    Ok(cached.insert(grid))
}
