//! From a window of events to forecast masks, the one way `evgate-infer` and `evgate eval` both
//! take: voxelise the window (binned `downsample`×`downsample` when asked), pad it into the
//! model's input, run the network with its carried state, threshold the current and future
//! mask logits at the model's threshold into full-resolution bit masks, and derive each
//! horizon's keep region (the events the gate keeps) by the model's keep rule.

use std::time::{Duration, Instant};

use evgate_core::{
    dilate_logits, BitMask, DilationScratch, Event, MaskError, SensorSize, TimeSpan, VoxelError,
    VoxelGrid,
};

use crate::metadata::ModelMetadata;
use crate::runtime::{ModelError, ModelRuntime};

/// How mask logits become bit masks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskRule {
    /// Above it a pixel of the current or a forecast mask is moving.
    pub threshold_logit: f32,
    /// Above it a pixel of a dilated forecast is in the keep region.
    pub keep_threshold_logit: f32,
    /// A keep region takes, at each model pixel, the maximum of the forecast logits over the
    /// (2r + 1)-pixel square around it before its threshold, so that the gate keeps the events
    /// just outside a forecast that lags or undershoots the object.
    pub keep_dilation_px: u16,
}

impl MaskRule {
    /// The rule the model's metadata declares (`evgate.threshold-logit`,
    /// `evgate.keep-threshold-logit`, `evgate.keep-dilation-px`).
    pub fn of(metadata: &ModelMetadata) -> Self {
        Self {
            threshold_logit: metadata.threshold_logit,
            keep_threshold_logit: metadata.keep_threshold_logit,
            keep_dilation_px: metadata.keep_dilation_px,
        }
    }

    /// Whether keep regions are the forecast masks themselves.
    pub fn keeps_the_forecast(&self) -> bool {
        self.keep_dilation_px == 0 && self.keeps_at_the_mask_threshold()
    }

    /// Whether keep regions are thresholded where the masks are.
    pub fn keeps_at_the_mask_threshold(&self) -> bool {
        self.keep_threshold_logit == self.threshold_logit
    }
}

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
    /// The current mask's logits thresholded at the keep threshold, undilated: what a baseline
    /// that moves the current mask starts its keep regions from. `current` itself where the
    /// thresholds agree or the forecaster was made [`Forecaster::keep_regions_only`].
    pub current_keep: &'a BitMask,
    /// One mask per requested horizon, in order; empty from a forecaster made
    /// [`Forecaster::keep_regions_only`] whose rule dilates.
    pub futures: &'a [BitMask],
    /// One keep region per horizon: the pixels whose events the gate keeps.
    pub keep: &'a [BitMask],
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
    rule: MaskRule,
    downsample: u16,
    /// Whether the forecast masks are thresholded where the keep regions are not them.
    forecast_masks: bool,
    grid: Option<VoxelGrid>,
    /// The current mask, then one per horizon (the current mask alone without `forecast_masks`).
    masks: Vec<BitMask>,
    /// One keep region per horizon, where the rule does not keep the forecast itself.
    keep: Vec<BitMask>,
    /// The current mask at the keep threshold, where it differs from the mask threshold.
    current_keep: Option<BitMask>,
    /// One dilated logit plane (the dilation's own buffers are in `dilation_scratch`).
    dilated: Vec<f32>,
    dilation_scratch: DilationScratch<f32>,
}

impl Forecaster {
    /// `rule`: how logits become masks (the model's own is [`MaskRule::of`] its metadata);
    /// `downsample`: the side of the square of sensor pixels one input cell bins (1: none).
    pub fn new(runtime: ModelRuntime, rule: MaskRule, downsample: u16) -> Self {
        Self {
            runtime,
            rule,
            downsample,
            forecast_masks: true,
            grid: None,
            masks: Vec::new(),
            keep: Vec::new(),
            current_keep: None,
            dilated: Vec::new(),
            dilation_scratch: DilationScratch::default(),
        }
    }

    /// Thresholds only the current mask and the keep regions, for a consumer that gates and
    /// never scores the forecast masks (the infer service): the masks would cost a second pass
    /// over every horizon's logits.
    pub fn keep_regions_only(mut self) -> Self {
        self.forecast_masks = false;
        self
    }

    pub fn runtime(&self) -> &ModelRuntime {
        &self.runtime
    }

    pub fn rule(&self) -> MaskRule {
        self.rule
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
        let keeps_the_forecast = self.rule.keeps_the_forecast();
        let mask_count = if self.forecast_masks || keeps_the_forecast {
            1 + output.horizon_count()
        } else {
            1
        };
        reuse_or_allocate(&mut self.masks, mask_count, sensor).map_err(mask_error)?;
        let (row_stride, height) = (output.width(), output.height());
        let (rule, downsample) = (self.rule, self.downsample);
        let logits = std::iter::once(output.mask_logits()).chain(output.future_mask_logits());
        for (mask, logits) in self.masks.iter_mut().zip(logits) {
            mask.fill_from_binned_logits(logits, row_stride, rule.threshold_logit, downsample)
                .map_err(mask_error)?;
        }
        if self.forecast_masks && !rule.keeps_at_the_mask_threshold() {
            let current_keep = match self.current_keep.take() {
                Some(mask) if mask.size() == sensor => mask,
                _ => BitMask::new(sensor).map_err(mask_error)?,
            };
            let current_keep = self.current_keep.insert(current_keep);
            current_keep
                .fill_from_binned_logits(
                    output.mask_logits(),
                    row_stride,
                    rule.keep_threshold_logit,
                    downsample,
                )
                .map_err(mask_error)?;
        } else {
            self.current_keep = None;
        }
        if keeps_the_forecast {
            self.keep.clear();
        } else {
            reuse_or_allocate(&mut self.keep, output.horizon_count(), sensor)
                .map_err(mask_error)?;
            for (region, logits) in self.keep.iter_mut().zip(output.future_mask_logits()) {
                dilate_logits(
                    logits,
                    row_stride,
                    height,
                    usize::from(rule.keep_dilation_px),
                    &mut self.dilation_scratch,
                    &mut self.dilated,
                );
                region
                    .fill_from_binned_logits(
                        &self.dilated,
                        row_stride,
                        rule.keep_threshold_logit,
                        downsample,
                    )
                    .map_err(mask_error)?;
            }
        }
        let thresholding = started.elapsed();
        let (current, futures) = self.masks.split_first().expect("1 + K masks");
        Ok(Forecast {
            current,
            current_keep: self.current_keep.as_ref().unwrap_or(current),
            futures,
            keep: if self.keep.is_empty() {
                futures
            } else {
                &self.keep
            },
            voxelisation,
            inference,
            thresholding,
        })
    }
}

/// Keeps `masks` when they are `count` masks of `sensor`, else replaces them with blank ones:
/// a window allocates only when the sensor or the number of horizons changes.
fn reuse_or_allocate(
    masks: &mut Vec<BitMask>,
    count: usize,
    sensor: SensorSize,
) -> Result<(), MaskError> {
    if masks.len() != count || masks.first().map(BitMask::size) != Some(sensor) {
        *masks = (0..count)
            .map(|_| BitMask::new(sensor))
            .collect::<Result<_, _>>()?;
    }
    Ok(())
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
