//! The network's GFLOPs at 346×260 and 640×480 from the training code's FLOP counter
//! (`python -m evgate_train.flops --output ...`), attached to the report's model methods by
//! size class (and ATC variant, when the table states it) where the row's parameter count is
//! the model file's: a row of another architecture of the same size class is not used. The
//! table counts the PyTorch module, whose batch-norm parameters the ONNX export folds into the
//! convolutions, so counts within `FOLDED_PARAMETER_TOLERANCE` of each other are the same
//! architecture.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::report::Report;

#[derive(Debug, Error)]
pub enum FlopTableError {
    #[error("cannot read FLOP table {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "FLOP table {path}: {source}; expected {{\"models\": [{{\"size\": \"S\", \"parameters\": N, \
         \"gflops-346x260\": G, \"gflops-640x480\": G}}, ...]}}"
    )]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// Largest relative difference between the table's and the file's parameter counts that
/// batch-norm folding explains (the S model loses 0.2 %; a variant without ATC differs by 3 %).
pub const FOLDED_PARAMETER_TOLERANCE: f64 = 0.01;

/// One size class (optionally one ATC variant) of the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct FlopRow {
    pub size: String,
    /// The variant counted; absent: the training code's default (position-aware).
    #[serde(default)]
    pub atc: Option<String>,
    #[serde(default)]
    pub parameters: Option<u64>,
    #[serde(rename = "gflops-346x260", default)]
    pub gflops_346x260: Option<f64>,
    #[serde(rename = "gflops-640x480", default)]
    pub gflops_640x480: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlopTable {
    pub models: Vec<FlopRow>,
}

impl FlopTable {
    pub fn read(path: &Path) -> Result<Self, FlopTableError> {
        let text = std::fs::read_to_string(path).map_err(|source| FlopTableError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| FlopTableError::Parse {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The row of this size and variant, else the row of this size without a stated variant.
    pub fn row(&self, size: &str, atc: &str) -> Option<&FlopRow> {
        let of_size = || self.models.iter().filter(move |r| r.size == size);
        of_size()
            .find(|r| r.atc.as_deref() == Some(atc))
            .or_else(|| of_size().find(|r| r.atc.is_none()))
    }

    /// Sets the GFLOPs of every model method the table has a matching row for (and the
    /// parameter count where the model's is not known yet); returns the names of the models
    /// whose row has another parameter count (left without GFLOPs).
    pub fn apply(&self, report: &mut Report, source: &Path) -> Vec<String> {
        let mut mismatched = Vec::new();
        for method in &mut report.methods {
            let Some(model) = method.model.as_mut() else {
                continue;
            };
            let Some(row) = self.row(&model.size, &model.atc) else {
                continue;
            };
            match (model.parameters, row.parameters) {
                (Some(counted), Some(listed)) if !same_architecture(counted, listed) => {
                    mismatched.push(method.name.clone());
                    continue;
                }
                (None, listed) => model.parameters = listed,
                _ => {}
            }
            method.gflops = row.gflops_640x480;
            method.gflops_346x260 = row.gflops_346x260;
            model.size_figures_from = Some(source.to_path_buf());
        }
        mismatched
    }
}

fn same_architecture(counted_in_file: u64, listed: u64) -> bool {
    let difference = counted_in_file.abs_diff(listed) as f64;
    difference <= FOLDED_PARAMETER_TOLERANCE * listed.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &str = r#"{"horizons": 1, "models": [
        {"size": "XS", "parameters": 558793, "gflops-346x260": 1.295, "gflops-640x480": 4.408},
        {"size": "S", "parameters": 2227653, "gflops-346x260": 5.037, "gflops-640x480": 16.67},
        {"size": "S", "atc": "none", "parameters": 2000000, "gflops-346x260": 4.9, "gflops-640x480": 16.0}
    ]}"#;

    #[test]
    fn rows_are_found_by_size_and_variant() {
        let table: FlopTable = serde_json::from_str(TABLE).unwrap();
        assert_eq!(table.row("S", "none").unwrap().parameters, Some(2_000_000));
        assert_eq!(
            table.row("S", "position-aware").unwrap().parameters,
            Some(2_227_653)
        );
        assert_eq!(
            table.row("XS", "reference").unwrap().gflops_640x480,
            Some(4.408)
        );
        assert!(table.row("L", "none").is_none());
    }

    #[test]
    fn folded_batch_norm_counts_match_and_other_architectures_do_not() {
        assert!(same_architecture(336_536, 337_144));
        assert!(same_architecture(337_144, 337_144));
        assert!(!same_architecture(325_880, 337_144));
        assert!(!same_architecture(2_227_653, 337_144));
    }

    #[test]
    fn a_bad_table_names_the_file_and_the_expected_layout() {
        let folder = tempfile::tempdir().unwrap();
        let path = folder.path().join("flops.json");
        std::fs::write(&path, r#"{"sizes": []}"#).unwrap();
        let error = FlopTable::read(&path).unwrap_err().to_string();
        assert!(
            error.contains("flops.json") && error.contains("missing field `models`"),
            "{error}"
        );
        assert!(error.contains("gflops-640x480"), "{error}");
        let missing = FlopTable::read(&folder.path().join("absent.json")).unwrap_err();
        assert!(
            missing.to_string().starts_with("cannot read FLOP table"),
            "{missing}"
        );
    }
}
