//! The EVIMO readers open paths (zip archives, sequence folders), not byte streams: their
//! targets write each input to a scratch folder private to the fuzzing process first.

use std::path::PathBuf;

/// A folder under the system temporary directory that only this process writes to.
pub fn folder() -> PathBuf {
    let folder = std::env::temp_dir().join(format!("evgate-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&folder).expect("the temporary directory is writable");
    folder
}

/// Writes `bytes` to `name` inside [`folder`] and returns its path.
pub fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let path = folder().join(name);
    std::fs::write(&path, bytes).expect("the scratch folder is writable");
    path
}
