//! Finding the ONNX Runtime shared library that `ort` loads at run time (`load-dynamic`).
//!
//! Order: `ORT_DYLIB_PATH` when set (the user's explicit choice), else `.ort/libonnxruntime.so`
//! in the executable's directory or one of its ancestors (so a binary under `target/release`
//! finds the workspace's `.ort/`). The working directory is never searched, and a found library
//! is loaded only where no other user could have put it ([`crate::trusted_path`]).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use crate::trusted_path::{self, Search, UntrustedPath};

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
    #[error("{source}; or set {LIBRARY_PATH_VARIABLE}")]
    Untrusted {
        #[source]
        source: UntrustedPath,
    },
}

/// Finds the library from the process environment and the executable's path.
pub fn locate_onnxruntime() -> Result<PathBuf, LibraryError> {
    let starts: Vec<PathBuf> = trusted_path::executable_directory().into_iter().collect();
    locate_onnxruntime_from(
        std::env::var_os(LIBRARY_PATH_VARIABLE),
        &starts,
        trusted_path::current_user(),
    )
}

/// The search itself, with its inputs explicit so that it can be tested without touching the
/// process environment.
pub fn locate_onnxruntime_from(
    override_path: Option<OsString>,
    start_directories: &[PathBuf],
    user: u32,
) -> Result<PathBuf, LibraryError> {
    if let Some(path) = override_path.filter(|p| !p.is_empty()).map(PathBuf::from) {
        return if path.is_file() {
            Ok(path)
        } else {
            Err(LibraryError::OverrideMissing { path })
        };
    }
    match trusted_path::find_in_ancestors(Path::new(BUNDLED_LIBRARY), start_directories, user)
        .map_err(|source| LibraryError::Untrusted { source })?
    {
        Search::Found(path) => Ok(path),
        Search::Missing(looked_at) => Err(LibraryError::NotFound { looked_at }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trusted_path::current_user;

    #[test]
    fn finds_the_bundled_library_in_an_ancestor() {
        let root = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(root.path().join(".ort")).unwrap();
        std::fs::write(root.path().join(BUNDLED_LIBRARY), b"").unwrap();
        let nested = root.path().join("target/release");
        std::fs::create_dir_all(&nested).unwrap();
        let found =
            locate_onnxruntime_from(None, std::slice::from_ref(&nested), current_user()).unwrap();
        assert_eq!(found, root.path().join(BUNDLED_LIBRARY));
    }

    #[test]
    fn override_wins_over_the_bundled_library() {
        let root = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(root.path().join(".ort")).unwrap();
        std::fs::write(root.path().join(BUNDLED_LIBRARY), b"").unwrap();
        let custom = root.path().join("custom.so");
        std::fs::write(&custom, b"").unwrap();
        let found = locate_onnxruntime_from(
            Some(custom.clone().into()),
            &[root.path().to_path_buf()],
            current_user(),
        )
        .unwrap();
        assert_eq!(found, custom);
    }

    #[test]
    fn missing_override_is_an_error_naming_it() {
        let root = tempfile::tempdir().unwrap();
        let missing = root.path().join("nowhere.so");
        let error =
            locate_onnxruntime_from(Some(missing.clone().into()), &[], current_user()).unwrap_err();
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
        let error = locate_onnxruntime_from(None, std::slice::from_ref(&nested), current_user())
            .unwrap_err();
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

    /// The attack of issue 15: another user's `.ort/` in an ancestor of the search start.
    #[test]
    fn a_library_others_could_plant_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let root = tempfile::tempdir().unwrap();
        let shared = root.path().join("shared");
        std::fs::create_dir_all(shared.join(".ort")).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o777)).unwrap();
        std::fs::write(shared.join(BUNDLED_LIBRARY), b"").unwrap();
        let work = shared.join("work/target/release");
        std::fs::create_dir_all(&work).unwrap();
        let message = locate_onnxruntime_from(None, &[work], current_user())
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("refusing to load") && message.contains(LIBRARY_PATH_VARIABLE),
            "{message}"
        );
    }
}
