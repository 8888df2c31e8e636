//! The versioned benchmark suite: which sequences (preset, seed, duration) form the train,
//! validation, test and out-of-domain test splits. Seeds of different splits never overlap, so a
//! model is never evaluated on a scene it was trained on. Version 5 randomises every sequence's
//! textures, sensor, object silhouettes and paths, and motion speed (`crate::domain`); its
//! `test-ood` split uses photographs and sensors outside the training ranges and is never used
//! to choose anything.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use std::path::PathBuf;

use crate::config::SimConfig;
use crate::domain::{randomised_config, Domain};
use crate::preset::Preset;

/// Bumped whenever the plan or the simulator's output for a given seed changes.
pub const SUITE_VERSION: &str = "evgate-sim-suite/5";

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    Train,
    Val,
    Test,
    /// Photographs and sensors outside the training ranges: for reporting generalisation only.
    TestOod,
}

impl Split {
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
            Split::TestOod => "test-ood",
        }
    }

    /// Every split, in generation order.
    pub const ALL: [Split; 4] = [Split::Train, Split::Val, Split::Test, Split::TestOod];

    /// Seeds of a split start here; presets take consecutive blocks of 1000 within it.
    fn seed_base(self) -> u64 {
        match self {
            Split::Train => 100_000,
            Split::Val => 200_000,
            Split::Test => 300_000,
            Split::TestOod => 400_000,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[error("unknown split {name:?}; accepted: train, val, test, test-ood")]
pub struct UnknownSplit {
    pub name: String,
}

impl FromStr for Split {
    type Err = UnknownSplit;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Split::ALL
            .into_iter()
            .find(|split| split.name() == s)
            .ok_or_else(|| UnknownSplit { name: s.to_owned() })
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
    /// Position among its split's sequences of the same preset; picks the motion stratum.
    pub index: u64,
    pub duration_us: i64,
}

/// Sequences per split and their duration, for one preset.
struct Counts {
    train: u64,
    val: u64,
    test: u64,
    test_ood: u64,
    duration_us: i64,
}

impl SuiteScale {
    fn counts(self) -> Counts {
        match self {
            // One sequence per preset and split: the same code paths in minutes.
            SuiteScale::Small => Counts {
                train: 2,
                val: 1,
                test: 1,
                test_ood: 1,
                duration_us: 3_000_000,
            },
            // Test large enough for an interval within ±2 points on S's mIoU (±2.05 over the
            // 72 sequences of 12 per preset that S's 352×272 input takes), val for paired
            // comparisons, train ten times val, and at least 12 out-of-domain sequences.
            SuiteScale::Full => Counts {
                train: 40,
                val: 4,
                test: 16,
                test_ood: 2,
                duration_us: 3_000_000,
            },
        }
    }
}

/// Every sequence of the suite at `scale`, in generation order.
pub fn suite_plan(scale: SuiteScale) -> Vec<SuiteEntry> {
    let mut entries = Vec::new();
    for split in Split::ALL {
        for (preset_index, preset) in Preset::ALL.into_iter().enumerate() {
            let counts = scale.counts();
            let count = match split {
                Split::Train => counts.train,
                Split::Val => counts.val,
                Split::Test => counts.test,
                Split::TestOod => counts.test_ood,
            };
            for i in 0..count {
                let seed = split.seed_base() + preset_index as u64 * 1000 + i;
                entries.push(SuiteEntry {
                    name: format!("{}/{}-{seed}", split.name(), preset.name()),
                    split,
                    preset,
                    seed,
                    index: i,
                    duration_us: counts.duration_us,
                });
            }
        }
    }
    entries
}

impl SuiteEntry {
    /// The simulator configuration of this sequence: its preset with textures and sensor drawn
    /// for its seed, in-domain, or with `photographs` and an out-of-range sensor for `test-ood`.
    pub fn config(&self, photographs: &[PathBuf]) -> SimConfig {
        let domain = match self.split {
            Split::TestOod => Domain::OutOfDomain {
                photographs: photographs.to_vec(),
            },
            _ => Domain::InDomain,
        };
        randomised_config(self.preset, self.seed, self.index, &domain)
    }
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
            for split in Split::ALL {
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
    fn the_full_suite_has_the_sizes_version_5_promises() {
        let plan = suite_plan(SuiteScale::Full);
        let count = |split: Split, preset: Preset| {
            plan.iter()
                .filter(|e| e.split == split && e.preset == preset)
                .count()
        };
        for preset in Preset::ALL {
            assert!(count(Split::Val, preset) >= 4 && count(Split::Test, preset) >= 16);
        }
        let total = |split: Split| plan.iter().filter(|e| e.split == split).count();
        assert!(total(Split::Train) >= 10 * total(Split::Val));
        assert!(total(Split::TestOod) >= 12);
        assert!(plan.iter().all(|e| e.duration_us >= 3_000_000));
    }

    #[test]
    fn only_the_out_of_domain_split_gets_photographs() {
        let photographs = [PathBuf::from("a.png")];
        for entry in suite_plan(SuiteScale::Small) {
            let config = entry.config(&photographs);
            assert_eq!(
                config.scene.photographs.is_empty(),
                entry.split != Split::TestOod,
                "{}",
                entry.name
            );
        }
    }

    #[test]
    fn an_unknown_split_lists_the_accepted_ones() {
        let error = "holdout".parse::<Split>().unwrap_err().to_string();
        assert!(error.contains("train, val, test, test-ood"), "{error}");
        assert_eq!("test-ood".parse::<Split>().unwrap(), Split::TestOod);
        for split in Split::ALL {
            assert_eq!(split.name().parse::<Split>().unwrap(), split);
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
