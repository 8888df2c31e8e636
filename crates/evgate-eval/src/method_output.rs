//! What each kind of method produces at one reference time: its current mask and one mask per
//! horizon, and what that cost.

use std::time::{Duration, Instant};

use evgate_core::{dilate_mask, DilationScratch, Event, SensorSize};

use crate::config::EvalConfig;
use crate::linear::extrapolate;
use crate::method::MethodKind;
use crate::oms::oms_mask;

/// The masks one method produced for one reference time.
pub(crate) struct MethodOutput {
    pub current: Vec<bool>,
    pub futures: Vec<Vec<bool>>,
    /// The pixels whose events the gate keeps at each horizon, where they are not `futures`.
    pub keep: Option<Vec<Vec<bool>>>,
    pub runtime: Duration,
}

impl MethodOutput {
    /// One keep region per horizon.
    pub fn keep_regions(&self) -> &[Vec<bool>] {
        self.keep.as_deref().unwrap_or(&self.futures)
    }
}

/// The current mask the baselines move, and what it cost.
pub(crate) struct BaselineSource {
    pub current: Vec<bool>,
    /// The same mask at the model's keep threshold, from which the baselines' keep regions
    /// start as the model's do (`None`: the thresholds agree, it is `current`).
    pub current_keep: Option<Vec<bool>>,
    pub runtime: Duration,
}

impl BaselineSource {
    /// The mask the baselines' keep regions start from.
    fn keep_mask(&self) -> &[bool] {
        self.current_keep.as_deref().unwrap_or(&self.current)
    }
}

/// Everything a method may look at for one reference time.
pub(crate) struct ReferenceInputs<'a> {
    pub config: &'a EvalConfig,
    pub size: SensorSize,
    pub reference_us: i64,
    pub horizons_us: &'a [i64],
    /// The events of the window that ends at the reference time.
    pub window: &'a [Event],
    /// What the baselines start from: the first model's current mask, or the true mask when
    /// no model runs, with what it cost.
    pub current: Option<&'a BaselineSource>,
    /// The first model's keep dilation, by which the baselines built on its current mask dilate
    /// their forecasts of `current_keep` into keep regions too, so that their gating compares
    /// with the model's on motion alone (without a model, the oracle's).
    pub baseline_dilation_px: u16,
    /// The previous reference time and its source, for linear extrapolation.
    pub previous: Option<&'a (i64, BaselineSource)>,
    /// Each model's output (None where the model sits the recording out).
    pub models: &'a [Option<MethodOutput>],
    /// The true object ids at the reference time and at each horizon, where known.
    pub truth_now: Option<&'a [u8]>,
    pub truth_at_horizon: &'a [Option<&'a [u8]>],
}

impl ReferenceInputs<'_> {
    /// A baseline's keep regions: `forecast` (how it moves a mask) applied to the current mask
    /// at the model's keep threshold, dilated as the model's keep regions are; `None` where
    /// they are the baseline's forecasts themselves.
    fn keep_regions(
        &self,
        source: &BaselineSource,
        forecast: impl FnOnce(&[bool]) -> Vec<Vec<bool>>,
    ) -> Option<Vec<Vec<bool>>> {
        if self.baseline_dilation_px == 0 && source.current_keep.is_none() {
            return None;
        }
        let undilated = forecast(source.keep_mask());
        if self.baseline_dilation_px == 0 {
            return Some(undilated);
        }
        Some(dilated(&undilated, self.size, self.baseline_dilation_px))
    }
}

/// Each mask dilated by `radius` pixels over the (2 radius + 1)-pixel square, as keep regions are.
fn dilated(masks: &[Vec<bool>], size: SensorSize, radius: u16) -> Vec<Vec<bool>> {
    let mut scratch = DilationScratch::default();
    masks
        .iter()
        .map(|mask| {
            let mut region = Vec::new();
            dilate_mask(
                mask,
                usize::from(size.width),
                usize::from(size.height),
                usize::from(radius),
                &mut scratch,
                &mut region,
            );
            region
        })
        .collect()
}

/// Object ids as a moving / static mask.
pub(crate) fn to_mask(ids: &[u8]) -> Vec<bool> {
    ids.iter().map(|&id| id != 0).collect()
}

impl MethodKind {
    /// This method's masks at the reference time; None where it has nothing to go on.
    pub(crate) fn output(self, inputs: &ReferenceInputs) -> Option<MethodOutput> {
        let horizons = inputs.horizons_us.len();
        match self {
            MethodKind::Oms(parameters) => {
                let started = Instant::now();
                let mask = oms_mask(inputs.window, inputs.size, &parameters);
                Some(MethodOutput {
                    futures: vec![mask.clone(); horizons],
                    current: mask,
                    keep: None,
                    runtime: started.elapsed(),
                })
            }
            MethodKind::NoForecast => inputs.current.map(|source| {
                let started = Instant::now();
                let hold = |mask: &[bool]| vec![mask.to_vec(); horizons];
                MethodOutput {
                    keep: inputs.keep_regions(source, hold),
                    futures: hold(&source.current),
                    current: source.current.clone(),
                    runtime: source.runtime + started.elapsed(),
                }
            }),
            MethodKind::Linear => inputs.current.map(|source| {
                let started = Instant::now();
                let (previous_us, previous) = inputs
                    .previous
                    .map_or((inputs.reference_us, source), |(t, previous)| {
                        (*t, previous)
                    });
                let extrapolate_from = |pick: fn(&BaselineSource) -> &[bool], now: &[bool]| {
                    extrapolate(
                        pick(previous),
                        now,
                        inputs.size,
                        inputs.reference_us - previous_us,
                        inputs.horizons_us,
                        inputs.config.linear_max_match_distance_px,
                    )
                };
                MethodOutput {
                    keep: inputs.keep_regions(source, |keep| {
                        extrapolate_from(BaselineSource::keep_mask, keep)
                    }),
                    futures: extrapolate_from(|s| &s.current, &source.current),
                    current: source.current.clone(),
                    runtime: source.runtime + started.elapsed(),
                }
            }),
            MethodKind::Model(index) => inputs.models[index].as_ref().map(|output| MethodOutput {
                current: output.current.clone(),
                futures: output.futures.clone(),
                keep: output.keep.clone(),
                runtime: output.runtime,
            }),
            MethodKind::Oracle => inputs.truth_now.map(|now| {
                let futures: Vec<Vec<bool>> = inputs
                    .truth_at_horizon
                    .iter()
                    .map(|truth| truth.map_or_else(|| vec![false; inputs.size.pixels()], to_mask))
                    .collect();
                let radius = inputs.config.oracle_keep_dilation_px;
                MethodOutput {
                    current: to_mask(now),
                    keep: (radius > 0).then(|| dilated(&futures, inputs.size, radius)),
                    futures,
                    runtime: Duration::ZERO,
                }
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    fn set_pixels(mask: &[bool], size: SensorSize) -> Vec<(usize, usize)> {
        let width = usize::from(size.width);
        (0..mask.len())
            .filter(|&i| mask[i])
            .map(|i| (i % width, i / width))
            .collect()
    }

    /// What the baselines see at 50 ms, at two horizons, without a model run or ground truth.
    fn baseline_inputs<'a>(
        config: &'a EvalConfig,
        size: SensorSize,
        horizons_us: &'a [i64; 2],
        current: &'a BaselineSource,
        previous: Option<&'a (i64, BaselineSource)>,
        baseline_dilation_px: u16,
    ) -> ReferenceInputs<'a> {
        ReferenceInputs {
            config,
            size,
            reference_us: 50_000,
            horizons_us,
            window: &[],
            current: Some(current),
            baseline_dilation_px,
            previous,
            models: &[],
            truth_now: None,
            truth_at_horizon: &[None, None],
        }
    }

    #[test]
    fn baselines_on_the_model_mask_keep_their_forecasts_dilated_as_the_model_does() {
        let size = SensorSize::new(8, 6);
        let config = EvalConfig::default();
        let mut current = vec![false; size.pixels()];
        current[2 * 8 + 4] = true;
        let current = BaselineSource {
            current,
            current_keep: None,
            runtime: Duration::ZERO,
        };
        let horizons_us = [50_000, 100_000];
        let inputs_with = |baseline_dilation_px| {
            baseline_inputs(
                &config,
                size,
                &horizons_us,
                &current,
                None,
                baseline_dilation_px,
            )
        };
        let square: Vec<(usize, usize)> =
            (1..4).flat_map(|y| (3..6).map(move |x| (x, y))).collect();
        for kind in [MethodKind::NoForecast, MethodKind::Linear] {
            let plain = kind.output(&inputs_with(0)).unwrap();
            let dilated = kind.output(&inputs_with(1)).unwrap();
            assert_eq!(
                dilated.current, current.current,
                "{kind:?}: the current mask changed"
            );
            assert_eq!(
                dilated.futures, plain.futures,
                "{kind:?}: the forecasts changed"
            );
            assert_eq!(plain.keep_regions(), plain.futures.as_slice(), "{kind:?}");
            for (future, region) in plain.futures.iter().zip(dilated.keep_regions()) {
                assert_eq!(set_pixels(future, size), vec![(4, 2)], "{kind:?}");
                assert_eq!(set_pixels(region, size), square, "{kind:?}");
            }
        }
    }

    #[test]
    fn the_oracle_gates_with_the_true_masks_dilated_as_configured() {
        let size = SensorSize::new(8, 6);
        let mut truth = vec![0u8; size.pixels()];
        truth[2 * 8 + 4] = 1;
        let horizons_us = [50_000];
        let truth_at_horizon = [Some(truth.as_slice())];
        let output_with = |oracle_keep_dilation_px| {
            let config = EvalConfig {
                oracle_keep_dilation_px,
                ..EvalConfig::default()
            };
            let inputs = ReferenceInputs {
                config: &config,
                size,
                reference_us: 50_000,
                horizons_us: &horizons_us,
                window: &[],
                current: None,
                baseline_dilation_px: 0,
                previous: None,
                models: &[],
                truth_now: Some(&truth),
                truth_at_horizon: &truth_at_horizon,
            };
            MethodKind::Oracle.output(&inputs).unwrap()
        };
        let plain = output_with(0);
        assert!(plain.keep.is_none());
        assert_eq!(set_pixels(&plain.keep_regions()[0], size), vec![(4, 2)]);
        let dilated = output_with(1);
        assert_eq!(dilated.futures, plain.futures, "the scored masks changed");
        assert_eq!(dilated.current, plain.current);
        let square: Vec<(usize, usize)> =
            (1..4).flat_map(|y| (3..6).map(move |x| (x, y))).collect();
        assert_eq!(set_pixels(&dilated.keep_regions()[0], size), square);
    }

    #[test]
    fn baselines_move_the_mask_at_the_models_keep_threshold_into_their_keep_regions() {
        let size = SensorSize::new(12, 4);
        let config = EvalConfig::default();
        let at = |pixels: &[usize]| {
            let mut mask = vec![false; size.pixels()];
            for &x in pixels {
                mask[12 + x] = true;
            }
            mask
        };
        // The object moves 1 px right per 50 ms window; at the keep threshold it is wider.
        let source_at = |x: usize| BaselineSource {
            current: at(&[x]),
            current_keep: Some(at(&[x, x + 1])),
            runtime: Duration::ZERO,
        };
        let previous = (0, source_at(1));
        let current = source_at(2);
        let horizons_us = [50_000, 100_000];
        let inputs = baseline_inputs(&config, size, &horizons_us, &current, Some(&previous), 0);
        let held = MethodKind::NoForecast.output(&inputs).unwrap();
        assert_eq!(held.futures, vec![at(&[2]); 2]);
        assert_eq!(held.keep_regions(), vec![at(&[2, 3]); 2].as_slice());
        let linear = MethodKind::Linear.output(&inputs).unwrap();
        assert_eq!(linear.futures, vec![at(&[3]), at(&[4])]);
        assert_eq!(
            linear.keep_regions(),
            vec![at(&[3, 4]), at(&[4, 5])].as_slice()
        );
    }
}
