//! Which networks `evgate eval` compares: `--model [NAME=]PATH` (repeatable, the first is the
//! model under test), every `.onnx` of `--ablation-models DIR`, or the committed model.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{bail, Context};

/// The committed model, evaluated when no `--model` is given.
pub const DEFAULT_MODEL: &str = "models/evgate-S.onnx";

/// A network to evaluate and the name its rows carry (`model:NAME`).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    pub label: String,
    pub path: PathBuf,
    /// Found in `--ablation-models` rather than named: skipped when its content repeats a
    /// model already loaded.
    pub from_folder: bool,
}

impl ModelSpec {
    /// Named by the file stem.
    pub fn from_path(path: PathBuf) -> Self {
        let label = path.file_stem().map_or_else(
            || path.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        Self {
            label,
            path,
            from_folder: false,
        }
    }
}

impl FromStr for ModelSpec {
    type Err = String;

    /// `NAME=PATH` or `PATH`; a NAME holds no path separator, so `dir/a=b.onnx` is a path.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text.split_once('=') {
            Some((label, path)) if !label.contains(['/', '\\']) => {
                if label.is_empty() || path.is_empty() {
                    return Err(format!(
                        "model {text:?}: expected NAME=PATH with a non-empty NAME and PATH, or PATH"
                    ));
                }
                Ok(Self {
                    label: label.to_owned(),
                    path: PathBuf::from(path),
                    from_folder: false,
                })
            }
            _ => Ok(Self::from_path(PathBuf::from(text))),
        }
    }
}

/// Every `*.onnx` file of `folder`, sorted by name.
pub fn models_in(folder: &Path) -> anyhow::Result<Vec<ModelSpec>> {
    let entries = fs::read_dir(folder)
        .with_context(|| format!("cannot list --ablation-models folder {}", folder.display()))?;
    let mut paths = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("cannot list {}", folder.display()))?
            .path();
        if path.is_file() && path.extension().is_some_and(|e| e == "onnx") {
            paths.push(path);
        }
    }
    if paths.is_empty() {
        bail!(
            "--ablation-models folder {} holds no .onnx file",
            folder.display()
        );
    }
    paths.sort();
    Ok(paths
        .into_iter()
        .map(|path| ModelSpec {
            from_folder: true,
            ..ModelSpec::from_path(path)
        })
        .collect())
}

/// The models of a run in order: the given ones (or the committed model when none is given and
/// it exists), then those of the ablation folder that are not already listed. Labels must be
/// unique, since they key every table.
pub fn select_models(
    given: &[ModelSpec],
    ablation_folder: Option<&Path>,
    default_model: &Path,
) -> anyhow::Result<Vec<ModelSpec>> {
    let mut models = given.to_vec();
    if models.is_empty() {
        if default_model.is_file() {
            models.push(ModelSpec::from_path(default_model.to_path_buf()));
        } else {
            tracing::warn!(
                "{} not found and no --model given: it is left out",
                default_model.display()
            );
        }
    }
    if let Some(folder) = ablation_folder {
        let listed: BTreeSet<PathBuf> = models
            .iter()
            .filter_map(|m| fs::canonicalize(&m.path).ok())
            .collect();
        for model in models_in(folder)? {
            let canonical = fs::canonicalize(&model.path).ok();
            if canonical.is_none_or(|c| !listed.contains(&c)) {
                models.push(model);
            }
        }
    }
    let mut labels = BTreeSet::new();
    for model in &models {
        if !labels.insert(model.label.as_str()) {
            bail!(
                "two models are named {:?} (the second is {}); name them with --model NAME=PATH",
                model.label,
                model.path.display()
            );
        }
    }
    Ok(models)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_optional() {
        let named: ModelSpec = "full=models/ablation/evgate-S-atc-position-aware.onnx"
            .parse()
            .unwrap();
        assert_eq!(named.label, "full");
        assert_eq!(
            named.path,
            Path::new("models/ablation/evgate-S-atc-position-aware.onnx")
        );
        let plain: ModelSpec = "models/evgate-S.onnx".parse().unwrap();
        assert_eq!(plain.label, "evgate-S");
        let with_equals_in_folder: ModelSpec = "runs/a=b/m.onnx".parse().unwrap();
        assert_eq!(with_equals_in_folder.label, "m");
        assert!("=m.onnx"
            .parse::<ModelSpec>()
            .unwrap_err()
            .contains("NAME=PATH"));
    }

    #[test]
    fn ablation_folder_adds_unlisted_models_in_name_order() {
        let folder = tempfile::tempdir().unwrap();
        for name in [
            "evgate-S-atc-reference.onnx",
            "evgate-S-atc-none.onnx",
            "notes.md",
        ] {
            fs::write(folder.path().join(name), b"").unwrap();
        }
        let primary = folder.path().join("evgate-S-atc-none.onnx");
        let given = [ModelSpec {
            label: "S".to_owned(),
            path: primary,
            from_folder: false,
        }];
        let models = select_models(&given, Some(folder.path()), Path::new("absent.onnx")).unwrap();
        let labels: Vec<&str> = models.iter().map(|m| m.label.as_str()).collect();
        assert_eq!(labels, ["S", "evgate-S-atc-reference"]);
        assert!(!models[0].from_folder && models[1].from_folder);
    }

    #[test]
    fn duplicate_labels_and_empty_folders_are_refused() {
        let folder = tempfile::tempdir().unwrap();
        let error = select_models(&[], Some(folder.path()), Path::new("absent.onnx"))
            .unwrap_err()
            .to_string();
        assert!(error.contains("holds no .onnx file"), "{error}");
        let twice = ["a/m.onnx".parse().unwrap(), "b/m.onnx".parse().unwrap()];
        let error = select_models(&twice, None, Path::new("absent.onnx"))
            .unwrap_err()
            .to_string();
        assert!(error.contains("two models are named \"m\""), "{error}");
    }
}
