//! The versioned benchmark suite: which sequences (preset, seed, duration) form the train,
//! validation and test splits. Seeds of different splits never overlap, so a model is never
//! evaluated on a scene it was trained on.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::preset::Preset;

/// Bumped whenever the plan or the simulator's output for a given seed changes.
pub const SUITE_VERSION: &str = "evgate-sim-suite/4";

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    Train,
    Val,
    Test,
}

impl Split {
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    /// Seeds of a split start here; presets take consecutive blocks of 1000 within it.
    fn seed_base(self) -> u64 {
        match self {
            Split::Train => 100_000,
            Split::Val => 200_000,
            Split::Test => 300_000,
        }
    }
}

/// How large a suite to generate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SuiteScale {
    /// A few minutes of data for a quick training run and CI-sized evaluations.
    Small,
    /// The documented benchmark.
    Full,
}

#[derive(Debug, thiserror::Error)]
#[error("unknown suite scale {name:?}; accepted: small, full")]
pub struct UnknownScale {
    pub name: String,
}

impl FromStr for SuiteScale {
    type Err = UnknownScale;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "small" => Ok(SuiteScale::Small),
            "full" => Ok(SuiteScale::Full),
            _ => Err(UnknownScale {
                name: s.to_string(),
            }),
        }
    }
}

impl fmt::Display for SuiteScale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SuiteScale::Small => "small",
            SuiteScale::Full => "full",
        })
    }
}

/// One sequence of the suite.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct SuiteEntry {
    /// Relative directory of the sequence, e.g. `train/boxes-100003`.
    pub name: String,
    pub split: Split,
    pub preset: Preset,
    pub seed: u64,
    pub duration_us: i64,
}

/// Sequences per split and their duration, for one group of presets.
struct Counts {
    train: u64,
    val: u64,
    test: u64,
    duration_us: i64,
}

impl SuiteScale {
    fn counts(self, preset: Preset) -> Counts {
        let driving = preset == Preset::Driving;
        match (self, driving) {
            (SuiteScale::Small, false) => Counts {
                train: 2,
                val: 1,
                test: 1,
                duration_us: 3_000_000,
            },
            (SuiteScale::Small, true) => Counts {
                train: 1,
                val: 1,
                test: 1,
                duration_us: 2_000_000,
            },
            (SuiteScale::Full, false) => Counts {
                train: 8,
                val: 2,
                test: 2,
                duration_us: 5_000_000,
            },
            (SuiteScale::Full, true) => Counts {
                train: 4,
                val: 1,
                test: 1,
                duration_us: 5_000_000,
            },
        }
    }
}

/// Every sequence of the suite at `scale`, in generation order.
pub fn suite_plan(scale: SuiteScale) -> Vec<SuiteEntry> {
    let mut entries = Vec::new();
    for split in [Split::Train, Split::Val, Split::Test] {
        for (preset_index, preset) in Preset::ALL.into_iter().enumerate() {
            let counts = scale.counts(preset);
            let count = match split {
                Split::Train => counts.train,
                Split::Val => counts.val,
                Split::Test => counts.test,
            };
            for i in 0..count {
                let seed = split.seed_base() + preset_index as u64 * 1000 + i;
                entries.push(SuiteEntry {
                    name: format!("{}/{}-{seed}", split.name(), preset.name()),
                    split,
                    preset,
                    seed,
                    duration_us: counts.duration_us,
                });
            }
        }
    }
    entries
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn splits_never_share_a_seed_and_cover_every_preset() {
        for scale in [SuiteScale::Small, SuiteScale::Full] {
            let plan = suite_plan(scale);
            let seeds: HashSet<u64> = plan.iter().map(|e| e.seed).collect();
            assert_eq!(
                seeds.len(),
                plan.len(),
                "a seed repeats in the {scale} suite"
            );
            for split in [Split::Train, Split::Val, Split::Test] {
                let presets: HashSet<Preset> = plan
                    .iter()
                    .filter(|e| e.split == split)
                    .map(|e| e.preset)
                    .collect();
                assert_eq!(
                    presets.len(),
                    Preset::ALL.len(),
                    "{scale} {split:?} misses a preset"
                );
            }
        }
    }

    #[test]
    fn scale_names_parse_and_reject_unknown() {
        assert_eq!("small".parse::<SuiteScale>().unwrap(), SuiteScale::Small);
        assert!("huge"
            .parse::<SuiteScale>()
            .unwrap_err()
            .to_string()
            .contains("small, full"));
    }
}
