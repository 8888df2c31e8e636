//! Domain randomisation of suite version 5: each sequence draws its textures, its sensor, its
//! objects' silhouettes and paths (`crate::variation`) and the speed of its motion from ranges,
//! so a network cannot learn the look of one simulator setting instead of motion.
//!
//! The training, validation and test splits draw from the same in-domain ranges with procedural
//! textures only. The out-of-domain test split puts photographs on every surface and draws the
//! sensor outside the training ranges (thresholds, their spread, refractory period, noise, hot
//! pixels, timestamp jitter), so its score measures generalisation. The draws use their own
//! generator, seeded from the sequence seed, so the layout built from the same seed is the
//! preset's.

use std::ops::Range;
use std::path::PathBuf;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::{ObjectVariation, SceneParams, SimConfig};
use crate::event_model::EventModel;
use crate::preset::Preset;
use crate::texture::TextureStyle;

/// Where a sequence's appearance and sensor come from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Domain {
    /// Procedural textures and sensors from the training ranges.
    InDomain,
    /// These photographs on every surface and sensors outside the training ranges.
    OutOfDomain { photographs: Vec<PathBuf> },
}

/// Decorrelates the randomisation's generator from the scene's, which uses the seed as is.
const DRAW_SALT: u64 = 0x9e37_79b9_7f4a_7c15;

/// The training ranges of the sensor: (field, range). Out-of-domain draws avoid all of them.
pub mod ranges {
    use std::ops::Range;

    pub const THRESHOLD: Range<f32> = 0.12..0.35;
    /// ON and OFF thresholds of the fastest motion stratum, drawn log-uniformly.
    pub const BUSY_THRESHOLD: Range<f32> = 0.07..0.12;
    pub const THRESHOLD_SIGMA: Range<f32> = 0.01..0.06;
    pub const REFRACTORY_US: Range<i64> = 100..1_500;
    pub const SHOT_NOISE_HZ: Range<f32> = 0.05..2.0;
    pub const LEAK_NOISE_HZ: Range<f32> = 0.01..0.5;
    pub const HOT_PIXEL_FRACTION: Range<f32> = 0.0..5e-4;
    pub const TIMESTAMP_JITTER_US: Range<f32> = 0.0..60.0;
}

/// Factor on the preset's camera and object speeds, drawn log-uniformly in every split.
const MOTION_SCALE: Range<f32> = 0.5..8.0;

/// The motion draw is stratified: a sequence's stratum picks one of this many equal parts of
/// the log range, so a split with this many sequences per preset holds slow and fast ones alike
/// instead of leaving the busiest windows to chance. The fastest stratum also gets the most
/// sensitive sensors ([`ranges::BUSY_THRESHOLD`]): together they carry the events per 50 ms
/// window from 10^3 to 10^6.
pub const MOTION_STRATA: u64 = 4;

fn log_uniform(rng: &mut impl Rng, range: Range<f32>) -> f32 {
    rng.gen_range(range.start.ln()..range.end.ln()).exp()
}

fn stratified_log_uniform(rng: &mut impl Rng, range: Range<f32>, stratum: u64) -> f32 {
    let (low, high) = (range.start.ln(), range.end.ln());
    let width = (high - low) / MOTION_STRATA as f32;
    let start = low + width * stratum as f32;
    rng.gen_range(start..start + width).exp()
}

/// A value from `low` or `high`, each half the time: the out-of-domain draws lie on both
/// sides of a training range.
fn either(rng: &mut impl Rng, low: Range<f32>, high: Range<f32>) -> f32 {
    if rng.gen_bool(0.5) {
        rng.gen_range(low)
    } else {
        rng.gen_range(high)
    }
}

/// A procedural texture style from the v5 ranges; `weak_edges` allows the faint objects
/// (low contrast) the suite asks for.
fn texture_style(rng: &mut impl Rng, weak_edges: bool) -> TextureStyle {
    let optional = |rng: &mut ChaCha8Rng, share: f64, range: Range<f32>| {
        if rng.gen_bool(share) {
            rng.gen_range(range)
        } else {
            0.0
        }
    };
    let mut own = ChaCha8Rng::seed_from_u64(rng.gen());
    let contrast_floor = if weak_edges && own.gen_bool(0.25) {
        0.12
    } else {
        0.35
    };
    TextureStyle {
        mean: own.gen_range(0.25..0.65),
        contrast: own.gen_range(contrast_floor..0.95),
        noise: optional(&mut own, 0.7, 0.1..1.2),
        shape_density: optional(&mut own, 0.6, 0.2..2.5),
        stripes: optional(&mut own, 0.25, 0.1..0.8),
        spectral: optional(&mut own, 0.6, 0.2..1.5),
        strokes: optional(&mut own, 0.4, 0.3..3.0),
        gradient: optional(&mut own, 0.4, 0.1..1.0),
        flat_share: optional(&mut own, 0.35, 0.1..0.6),
    }
}

fn in_domain_threshold(rng: &mut impl Rng, busy: bool) -> f32 {
    if busy {
        log_uniform(rng, ranges::BUSY_THRESHOLD)
    } else {
        rng.gen_range(ranges::THRESHOLD)
    }
}

fn in_domain_sensor(rng: &mut impl Rng, base: &EventModel, busy: bool) -> EventModel {
    EventModel {
        threshold_on: in_domain_threshold(rng, busy),
        threshold_off: in_domain_threshold(rng, busy),
        threshold_sigma: rng.gen_range(ranges::THRESHOLD_SIGMA),
        refractory_us: rng.gen_range(ranges::REFRACTORY_US),
        shot_noise_hz: rng.gen_range(ranges::SHOT_NOISE_HZ),
        leak_noise_hz: rng.gen_range(ranges::LEAK_NOISE_HZ),
        hot_pixel_fraction: if rng.gen_bool(0.5) {
            rng.gen_range(ranges::HOT_PIXEL_FRACTION)
        } else {
            0.0
        },
        hot_pixel_hz: rng.gen_range(20.0..300.0),
        ..*base
    }
}

/// Silhouettes on a share of the objects, turning paths, and an occluder in half the
/// sequences (all splits: shapes and paths are not appearance).
fn object_variation(rng: &mut impl Rng) -> ObjectVariation {
    ObjectVariation {
        cutout_share: rng.gen_range(0.0..0.6),
        turn_rate_rad_s: rng.gen_range(0.0..1.2),
        occluder_chance: 0.5,
    }
}

fn scale_motion(scene: &mut SceneParams, factor: f32) {
    scene.ego_rotation_rad_s *= factor;
    scene.ego_translation_mps *= factor;
    scene.object_speed_mps *= factor;
}

fn out_of_domain_sensor(rng: &mut impl Rng, base: &EventModel) -> EventModel {
    EventModel {
        threshold_on: either(rng, 0.05..0.065, 0.38..0.55),
        threshold_off: either(rng, 0.05..0.065, 0.38..0.55),
        threshold_sigma: rng.gen_range(0.065..0.1),
        refractory_us: if rng.gen_bool(0.5) {
            rng.gen_range(20..90)
        } else {
            rng.gen_range(1_700..4_000)
        },
        shot_noise_hz: rng.gen_range(2.5..6.0),
        leak_noise_hz: rng.gen_range(0.6..1.2),
        hot_pixel_fraction: rng.gen_range(8e-4..3e-3),
        hot_pixel_hz: rng.gen_range(300.0..1_000.0),
        ..*base
    }
}

/// The configuration of one suite-v5 sequence: `preset`'s scene and camera with textures and
/// sensor drawn for `seed` from `domain`, and its motion from stratum `motion_stratum` (taken
/// modulo [`MOTION_STRATA`]).
pub fn randomised_config(
    preset: Preset,
    seed: u64,
    motion_stratum: u64,
    domain: &Domain,
) -> SimConfig {
    let mut config = preset.config();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ DRAW_SALT);
    let stratum = motion_stratum % MOTION_STRATA;
    match domain {
        Domain::InDomain => {
            config.scene.world_texture = texture_style(&mut rng, false);
            config.scene.object_texture = texture_style(&mut rng, true);
            let busy = stratum == MOTION_STRATA - 1;
            config.events = in_domain_sensor(&mut rng, &config.events, busy);
            config.events.timestamp_jitter_us = rng.gen_range(ranges::TIMESTAMP_JITTER_US);
        }
        Domain::OutOfDomain { photographs } => {
            config.scene.photographs = photographs.clone();
            config.events = out_of_domain_sensor(&mut rng, &config.events);
            config.events.timestamp_jitter_us = rng.gen_range(90.0..300.0);
        }
    }
    config.scene.variation = object_variation(&mut rng);
    let factor = stratified_log_uniform(&mut rng, MOTION_SCALE, stratum);
    scale_motion(&mut config.scene, factor);
    config
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_reproducible_and_differ_between_seeds() {
        let a = randomised_config(Preset::Boxes, 7, 0, &Domain::InDomain);
        assert_eq!(a, randomised_config(Preset::Boxes, 7, 0, &Domain::InDomain));
        assert_ne!(a, randomised_config(Preset::Boxes, 8, 0, &Domain::InDomain));
        assert_eq!(a.scene.layout, Preset::Boxes.config().scene.layout);
        let preset = Preset::Boxes.config().scene;
        let factor = a.scene.object_speed_mps / preset.object_speed_mps;
        assert!(
            (MOTION_SCALE.start..=MOTION_SCALE.end).contains(&factor),
            "{factor}"
        );
        assert!((a.scene.ego_rotation_rad_s / preset.ego_rotation_rad_s - factor).abs() < 1e-5);
        assert!(a.events.invalid_field().is_none());
    }

    #[test]
    fn out_of_domain_sensors_lie_outside_every_training_range() {
        let domain = Domain::OutOfDomain {
            photographs: vec![PathBuf::from("photo.png")],
        };
        for seed in 0..200 {
            let config = randomised_config(Preset::Wall, seed, seed, &domain);
            let events = config.events;
            assert!(events.invalid_field().is_none(), "{events:?}");
            for training in [ranges::THRESHOLD, ranges::BUSY_THRESHOLD] {
                assert!(!training.contains(&events.threshold_on));
                assert!(!training.contains(&events.threshold_off));
            }
            assert!(!ranges::THRESHOLD_SIGMA.contains(&events.threshold_sigma));
            assert!(!ranges::REFRACTORY_US.contains(&events.refractory_us));
            assert!(!ranges::SHOT_NOISE_HZ.contains(&events.shot_noise_hz));
            assert!(!ranges::LEAK_NOISE_HZ.contains(&events.leak_noise_hz));
            assert!(events.hot_pixel_fraction >= ranges::HOT_PIXEL_FRACTION.end);
            assert!(!ranges::TIMESTAMP_JITTER_US.contains(&events.timestamp_jitter_us));
            assert_eq!(config.scene.photographs, vec![PathBuf::from("photo.png")]);
        }
    }

    #[test]
    fn in_domain_draws_stay_in_range_and_use_the_new_texture_families() {
        let mut families_seen = [false; 4];
        for seed in 0..100 {
            let config = randomised_config(Preset::Table, seed, seed, &Domain::InDomain);
            let events = config.events;
            let thresholds = if seed % MOTION_STRATA == MOTION_STRATA - 1 {
                ranges::BUSY_THRESHOLD
            } else {
                ranges::THRESHOLD
            };
            assert!(thresholds.contains(&events.threshold_on));
            assert!(ranges::REFRACTORY_US.contains(&events.refractory_us));
            assert!(ranges::TIMESTAMP_JITTER_US.contains(&events.timestamp_jitter_us));
            assert!(config.scene.variation.cutout_share > 0.0);
            assert!(config.scene.photographs.is_empty());
            for style in [config.scene.world_texture, config.scene.object_texture] {
                families_seen[0] |= style.spectral > 0.0;
                families_seen[1] |= style.strokes > 0.0;
                families_seen[2] |= style.gradient > 0.0;
                families_seen[3] |= style.flat_share > 0.0;
            }
        }
        assert_eq!(families_seen, [true; 4]);
    }

    #[test]
    fn each_motion_stratum_draws_from_its_own_part_of_the_range() {
        let preset = Preset::Fast.config().scene;
        let (low, high) = (MOTION_SCALE.start.ln(), MOTION_SCALE.end.ln());
        let width = (high - low) / MOTION_STRATA as f32;
        for stratum in 0..MOTION_STRATA {
            for seed in 0..50 {
                let config = randomised_config(Preset::Fast, seed, stratum, &Domain::InDomain);
                let factor = config.scene.ego_translation_mps / preset.ego_translation_mps;
                let start = low + width * stratum as f32;
                assert!(
                    (start - 1e-4..=start + width + 1e-4).contains(&factor.ln()),
                    "stratum {stratum}, seed {seed}: factor {factor}"
                );
                let busy = ranges::BUSY_THRESHOLD.contains(&config.events.threshold_on);
                assert_eq!(busy, stratum == MOTION_STRATA - 1, "stratum {stratum}");
            }
        }
    }
}
