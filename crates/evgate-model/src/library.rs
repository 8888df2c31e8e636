//! Finding the ONNX Runtime shared library that `ort` loads at run time (`load-dynamic`).
//!
//! Order: `ORT_DYLIB_PATH` when set, else `.ort/libonnxruntime.so` in the current directory or
//! any of its ancestors, else the same below the executable's directory and its ancestors (so a
//! binary under `target/release` finds the workspace's `.ort/`).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// Environment variable that names the library file explicitly.
pub const LIBRARY_PATH_VARIABLE: &str = "ORT_DYLIB_PATH";

/// Where `scripts/fetch-onnxruntime.sh` puts the library, relative to the workspace root.
pub const BUNDLED_LIBRARY: &str = ".ort/libonnxruntime.so";

#[derive(Debug, thiserror::Error)]
pub enum LibraryError {
    #[error(
        "{LIBRARY_PATH_VARIABLE}={} names no file; point it at libonnxruntime.so or unset it to \
         use {BUNDLED_LIBRARY} (fetch it with `bash scripts/fetch-onnxruntime.sh`)",
        path.display()
    )]
    OverrideMissing { path: PathBuf },
    #[error(
        "onnx runtime shared library not found; {LIBRARY_PATH_VARIABLE} is not set and none of \
         these exist: {}; fix: run `bash scripts/fetch-onnxruntime.sh` in the workspace root \
         (or `EVGATE_ORT_PACKAGE=onnxruntime-gpu bash scripts/fetch-onnxruntime.sh` for CUDA), \
         or set {LIBRARY_PATH_VARIABLE}",
        looked_at.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
    )]
    NotFound { looked_at: Vec<PathBuf> },
}

/// Finds the library from the process environment, current directory and executable path.
pub fn locate_onnxruntime() -> Result<PathBuf, LibraryError> {
    let mut start_directories = Vec::new();
    if let Ok(current) = std::env::current_dir() {
        start_directories.push(current);
    }
    if let Some(executable_directory) = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(Path::to_path_buf))
    {
        start_directories.push(executable_directory);
    }
    locate_onnxruntime_from(std::env::var_os(LIBRARY_PATH_VARIABLE), &start_directories)
}

/// The search itself, with its inputs explicit so that it can be tested without touching the
/// process environment.
pub fn locate_onnxruntime_from(
    override_path: Option<OsString>,
    start_directories: &[PathBuf],
) -> Result<PathBuf, LibraryError> {
    if let Some(path) = override_path.filter(|p| !p.is_empty()).map(PathBuf::from) {
        return if path.is_file() {
            Ok(path)
        } else {
            Err(LibraryError::OverrideMissing { path })
        };
    }
    let mut looked_at: Vec<PathBuf> = Vec::new();
    for start in start_directories {
        for directory in start.ancestors() {
            let candidate = directory.join(BUNDLED_LIBRARY);
            if looked_at.contains(&candidate) {
                continue;
            }
            if candidate.is_file() {
                return Ok(candidate);
            }
            looked_at.push(candidate);
        }
    }
    Err(LibraryError::NotFound { looked_at })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_bundled_library_in_an_ancestor() {
        let root = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(root.path().join(".ort")).unwrap();
        std::fs::write(root.path().join(BUNDLED_LIBRARY), b"").unwrap();
        let nested = root.path().join("target/release");
        std::fs::create_dir_all(&nested).unwrap();
        let found = locate_onnxruntime_from(None, std::slice::from_ref(&nested)).unwrap();
        assert_eq!(found, root.path().join(BUNDLED_LIBRARY));
    }

    #[test]
    fn override_wins_over_the_bundled_library() {
        let root = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(root.path().join(".ort")).unwrap();
        std::fs::write(root.path().join(BUNDLED_LIBRARY), b"").unwrap();
        let custom = root.path().join("custom.so");
        std::fs::write(&custom, b"").unwrap();
        let found =
            locate_onnxruntime_from(Some(custom.clone().into()), &[root.path().to_path_buf()])
                .unwrap();
        assert_eq!(found, custom);
    }

    #[test]
    fn missing_override_is_an_error_naming_it() {
        let root = tempfile::tempdir().unwrap();
        let missing = root.path().join("nowhere.so");
        let error = locate_onnxruntime_from(Some(missing.clone().into()), &[]).unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains(&missing.display().to_string()),
            "{message}"
        );
        assert!(message.contains(LIBRARY_PATH_VARIABLE), "{message}");
    }

    #[test]
    fn not_found_lists_every_place_and_the_fix() {
        let root = tempfile::tempdir().unwrap();
        let nested = root.path().join("a/b");
        std::fs::create_dir_all(&nested).unwrap();
        let error = locate_onnxruntime_from(None, std::slice::from_ref(&nested)).unwrap_err();
        let message = error.to_string();
        for directory in [nested.as_path(), &root.path().join("a"), root.path()] {
            let candidate = directory.join(BUNDLED_LIBRARY).display().to_string();
            assert!(
                message.contains(&candidate),
                "{candidate} missing in: {message}"
            );
        }
        assert!(
            message.contains("bash scripts/fetch-onnxruntime.sh"),
            "{message}"
        );
    }
}
