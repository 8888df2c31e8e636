//! The process-wide ONNX Runtime environment.
//!
//! `ort` loads the shared library once per process and ONNX Runtime keeps a single environment,
//! so every session shares one; asking for a different library later is an error instead of
//! being silently ignored.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use ort::environment::Environment;

#[derive(Debug, thiserror::Error)]
pub enum EnvironmentError {
    #[error("cannot load the onnx runtime library {}: {message}", path.display())]
    Load { path: PathBuf, message: String },
    #[error("cannot create the onnx runtime environment from {}: {source}", path.display())]
    Create { path: PathBuf, source: ort::Error },
    #[error(
        "onnx runtime is already loaded from {} in this process; cannot switch to {}",
        loaded.display(),
        requested.display()
    )]
    AlreadyLoaded { loaded: PathBuf, requested: PathBuf },
}

static SHARED: Mutex<Option<(PathBuf, Environment)>> = Mutex::new(None);

/// Loads `library` (first call) and returns the shared environment.
pub fn shared_environment(library: &Path) -> Result<Environment, EnvironmentError> {
    let mut shared = SHARED
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((loaded, environment)) = shared.as_ref() {
        return if same_file(loaded, library) {
            Ok(environment.clone())
        } else {
            Err(EnvironmentError::AlreadyLoaded {
                loaded: loaded.clone(),
                requested: library.to_path_buf(),
            })
        };
    }
    let builder = ort::init_from(library).map_err(|error| EnvironmentError::Load {
        path: library.to_path_buf(),
        message: error.to_string(),
    })?;
    let environment =
        builder
            .with_name("evgate")
            .build()
            .map_err(|source| EnvironmentError::Create {
                path: library.to_path_buf(),
                source,
            })?;
    tracing::info!(library = %library.display(), "onnx runtime loaded");
    *shared = Some((library.to_path_buf(), environment.clone()));
    Ok(environment)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}
