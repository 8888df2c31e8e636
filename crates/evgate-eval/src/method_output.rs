//! What each kind of method produces at one reference time: its current mask and one mask per
//! horizon, and what that cost.

use std::time::{Duration, Instant};

use evgate_core::{Event, SensorSize};

use crate::config::EvalConfig;
use crate::linear::extrapolate;
use crate::method::MethodKind;
use crate::oms::oms_mask;

/// The masks one method produced for one reference time.
pub(crate) struct MethodOutput {
    pub current: Vec<bool>,
    pub futures: Vec<Vec<bool>>,
    pub runtime: Duration,
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
    pub current: Option<&'a (Vec<bool>, Duration)>,
    /// The previous reference time's current mask, for linear extrapolation.
    pub previous: Option<&'a (i64, Vec<bool>)>,
    /// Each model's output (None where the model sits the recording out).
    pub models: &'a [Option<MethodOutput>],
    /// The true object ids at the reference time and at each horizon, where known.
    pub truth_now: Option<&'a [u8]>,
    pub truth_at_horizon: &'a [Option<&'a [u8]>],
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
                    runtime: started.elapsed(),
                })
            }
            MethodKind::NoForecast => inputs.current.map(|(current, runtime)| MethodOutput {
                futures: vec![current.clone(); horizons],
                current: current.clone(),
                runtime: *runtime,
            }),
            MethodKind::Linear => inputs.current.map(|(current, runtime)| {
                let started = Instant::now();
                let (previous_us, previous) = inputs
                    .previous
                    .map_or((inputs.reference_us, current), |(t, mask)| (*t, mask));
                let futures = extrapolate(
                    previous,
                    current,
                    inputs.size,
                    inputs.reference_us - previous_us,
                    inputs.horizons_us,
                    inputs.config.linear_max_match_distance_px,
                );
                MethodOutput {
                    futures,
                    current: current.clone(),
                    runtime: *runtime + started.elapsed(),
                }
            }),
            MethodKind::Model(index) => inputs.models[index].as_ref().map(|output| MethodOutput {
                current: output.current.clone(),
                futures: output.futures.clone(),
                runtime: output.runtime,
            }),
            MethodKind::Oracle => inputs.truth_now.map(|now| MethodOutput {
                current: to_mask(now),
                futures: inputs
                    .truth_at_horizon
                    .iter()
                    .map(|truth| truth.map_or_else(|| vec![false; inputs.size.pixels()], to_mask))
                    .collect(),
                runtime: Duration::ZERO,
            }),
        }
    }
}
