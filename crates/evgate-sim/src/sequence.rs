//! Runs a simulation for a fixed duration and gathers a labelled sequence in the format of
//! docs/sequence-format.md: events with labels, masks and depth every 10 ms, and forecasting
//! targets (future masks and flow at sampled horizons) every 50 ms.

use evgate_io::LabelledSequence;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::SimConfig;
use crate::simulator::{SimStats, Simulator, SimulatorError};

/// Spacing of ground-truth frames (`gt_ts`).
pub const GT_PERIOD_US: i64 = 10_000;
/// Spacing of reference times (`ref_ts`), also the length of the event window ending there.
pub const REFERENCE_PERIOD_US: i64 = 50_000;
/// Largest forecasting horizon.
pub const MAX_HORIZON_US: i64 = 100_000;
/// Events are generated in slices of this length (progress granularity).
const SLICE_US: i64 = 10_000;
/// Mixed into the seed for the horizon draws, so they do not correlate with the scene.
const HORIZON_SEED_SALT: u64 = 0x686f_7269_7a6f_6e73;

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default)]
pub struct SequenceOptions {
    pub duration_us: i64,
    /// Horizons sampled per reference time (K).
    pub horizons_per_reference: usize,
}

impl Default for SequenceOptions {
    fn default() -> Self {
        Self {
            duration_us: 2_000_000,
            horizons_per_reference: 2,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SequenceBuildError {
    #[error(transparent)]
    Simulator(#[from] SimulatorError),
    #[error("sequence duration {duration_us} µs is too short; accepted: at least {minimum} µs (one 50 ms window plus the 100 ms horizon)")]
    TooShort { duration_us: i64, minimum: i64 },
    #[error(
        "scene has {count} moving objects but masks are stored as uint8; accepted: at most 255"
    )]
    TooManyObjects { count: usize },
}

/// What [`simulate_sequence`] did, beside the sequence itself.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct SequenceReport {
    pub stats: SimStats,
    pub object_count: usize,
}

/// Simulates `options.duration_us` of `config` with `seed`. `progress(done_us, total_us)` is
/// called as simulated time advances (ground-truth rendering counts as the last 20 %).
pub fn simulate_sequence(
    config: &SimConfig,
    seed: u64,
    options: &SequenceOptions,
    progress: &mut dyn FnMut(i64, i64),
) -> Result<(LabelledSequence, SequenceReport), SequenceBuildError> {
    let minimum = REFERENCE_PERIOD_US + MAX_HORIZON_US;
    if options.duration_us < minimum {
        return Err(SequenceBuildError::TooShort {
            duration_us: options.duration_us,
            minimum,
        });
    }
    let mut simulator = Simulator::new(config.clone(), seed)?;
    if simulator.object_count() > 255 {
        return Err(SequenceBuildError::TooManyObjects {
            count: simulator.object_count(),
        });
    }
    let duration = options.duration_us;
    let total_work = duration + duration / 4;
    let mut labelled = Vec::new();
    let mut t = 0;
    while t < duration {
        t = (t + SLICE_US).min(duration);
        simulator.advance(t, &mut labelled);
        progress(t, total_work);
    }
    let start = labelled.first().map(|e| e.event.t).unwrap_or(0);
    let gt_ts: Vec<i64> = (0..)
        .map(|i| start + i * GT_PERIOD_US)
        .take_while(|&t| t <= duration)
        .collect();
    let ref_ts: Vec<i64> = (1..)
        .map(|i| start + i * REFERENCE_PERIOD_US)
        .take_while(|&t| t + MAX_HORIZON_US <= duration)
        .collect();
    let mut horizon_rng = ChaCha8Rng::seed_from_u64(seed ^ HORIZON_SEED_SALT);
    let k = options.horizons_per_reference;
    let mut horizon_us = Vec::with_capacity(ref_ts.len() * k);
    for _ in &ref_ts {
        let mut draws: Vec<i64> = (0..k)
            .map(|_| horizon_rng.gen_range(0..=MAX_HORIZON_US))
            .collect();
        draws.sort_unstable();
        horizon_us.extend(draws);
    }
    let pixels = config.sensor.pixels();
    let gt_work = (gt_ts.len() + ref_ts.len() * k).max(1) as i64;
    let mut gt_done = 0i64;
    let report_gt = |done: &mut i64, progress: &mut dyn FnMut(i64, i64)| {
        *done += 1;
        progress(duration + (duration / 4) * *done / gt_work, total_work);
    };
    let mut masks = Vec::with_capacity(gt_ts.len() * pixels);
    let mut depth = Vec::with_capacity(gt_ts.len() * pixels);
    for &t in &gt_ts {
        let surfaces = simulator.surfaces_at(t);
        masks.extend(surfaces.id.iter().map(|&id| id as u8));
        depth.extend_from_slice(&surfaces.depth);
        report_gt(&mut gt_done, progress);
    }
    let mut future_mask = Vec::with_capacity(ref_ts.len() * k * pixels);
    let mut future_flow = Vec::with_capacity(ref_ts.len() * k * pixels * 2);
    for (r, &t) in ref_ts.iter().enumerate() {
        for &h in &horizon_us[r * k..(r + 1) * k] {
            future_mask.extend(simulator.mask_at(t + h).iter().map(|&id| id as u8));
            future_flow.extend(simulator.flow(t, h).iter().flat_map(|f| [f[0], f[1]]));
            report_gt(&mut gt_done, progress);
        }
    }
    let report = SequenceReport {
        stats: simulator.stats(),
        object_count: simulator.object_count(),
    };
    let meta = serde_json::json!({
        "generator": "evgate-sim",
        "version": env!("CARGO_PKG_VERSION"),
        "preset": config.preset,
        "seed": seed,
        "duration-us": duration,
        "object-count": report.object_count,
        "stats": report.stats,
        "simulator": config,
    });
    let (events, labels) = labelled.iter().map(|l| (l.event, l.label)).unzip();
    let sequence = LabelledSequence {
        events,
        labels,
        sensor_size: config.sensor,
        intrinsics: config.intrinsics.matrix(),
        gt_ts,
        masks,
        depth,
        ref_ts,
        horizons_per_reference: k,
        horizon_us,
        future_mask,
        future_flow,
        meta: meta.to_string(),
    };
    Ok((sequence, report))
}
