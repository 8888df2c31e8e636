//! Finding files that evgate loads without being told where (the ONNX Runtime library, the
//! shipped model) in places only their owner could have put them.
//!
//! A file found by searching is loaded only when it and every directory above it belong to the
//! current user or root and none of them can be written by anyone else (a sticky directory such
//! as `/tmp` may be, since there nobody can replace another user's entry). Otherwise any local
//! user could plant `/tmp/.ort/libonnxruntime.so` and have it run inside evgate. The search
//! starts at the executable's directory, never at the working directory, which a user may share
//! with others or not think of as code.

use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// Permission bits that let the group or others write.
const GROUP_OR_OTHER_WRITE: u32 = 0o022;
const STICKY: u32 = 0o1000;
const ROOT_UID: u32 = 0;

/// Why a found file is not loaded.
#[derive(Debug, thiserror::Error)]
pub enum UntrustedPath {
    #[error(
        "refusing to load {}: {} is owned by uid {owner}, not by you (uid {user}) or root; \
         remove it or name the file you trust explicitly",
        found.display(), offender.display()
    )]
    ForeignOwner {
        found: PathBuf,
        offender: PathBuf,
        owner: u32,
        user: u32,
    },
    #[error(
        "refusing to load {}: {} can be written by other users (mode {mode:o}); fix with \
         `chmod go-w {}` or name the file you trust explicitly",
        found.display(), offender.display(), offender.display()
    )]
    WritableByOthers {
        found: PathBuf,
        offender: PathBuf,
        mode: u32,
    },
    #[error("cannot inspect {} while checking {}: {source}", offender.display(), found.display())]
    Inspect {
        found: PathBuf,
        offender: PathBuf,
        source: std::io::Error,
    },
}

/// The effective user id of this process.
pub fn current_user() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// Checks that `found`, and each directory above it, is owned by `user` or root and writable by
/// nobody else (sticky directories excepted); for a link, both the path as named and where it
/// leads.
pub fn check_trusted(found: &Path, user: u32) -> Result<(), UntrustedPath> {
    let inspect = |offender: &Path, source| UntrustedPath::Inspect {
        found: found.to_path_buf(),
        offender: offender.to_path_buf(),
        source,
    };
    let absolute = std::path::absolute(found).map_err(|source| inspect(found, source))?;
    let resolved = std::fs::canonicalize(&absolute).map_err(|source| inspect(&absolute, source))?;
    check_ancestors(found, &absolute, user)?;
    if resolved != absolute {
        check_ancestors(found, &resolved, user)?;
    }
    Ok(())
}

/// [`check_trusted`] for `path` and its ancestors, naming `found` in errors.
fn check_ancestors(found: &Path, path: &Path, user: u32) -> Result<(), UntrustedPath> {
    for (depth, offender) in path.ancestors().enumerate() {
        let metadata = std::fs::metadata(offender).map_err(|source| UntrustedPath::Inspect {
            found: found.to_path_buf(),
            offender: offender.to_path_buf(),
            source,
        })?;
        let owner = metadata.uid();
        if owner != user && owner != ROOT_UID {
            return Err(UntrustedPath::ForeignOwner {
                found: found.to_path_buf(),
                offender: offender.to_path_buf(),
                owner,
                user,
            });
        }
        let mode = metadata.mode() & 0o7777;
        let sticky_directory = depth > 0 && mode & STICKY != 0;
        if mode & GROUP_OR_OTHER_WRITE != 0 && !sticky_directory {
            return Err(UntrustedPath::WritableByOthers {
                found: found.to_path_buf(),
                offender: offender.to_path_buf(),
                mode,
            });
        }
    }
    Ok(())
}

/// What a search of ancestors found.
#[derive(Debug)]
pub enum Search {
    Found(PathBuf),
    /// Nothing there; every candidate looked at, nearest first.
    Missing(Vec<PathBuf>),
}

/// Looks for `relative` in each of `starts` and their ancestors, nearest first; the first
/// existing candidate must pass [`check_trusted`].
pub fn find_in_ancestors(
    relative: &Path,
    starts: &[PathBuf],
    user: u32,
) -> Result<Search, UntrustedPath> {
    let mut looked_at: Vec<PathBuf> = Vec::new();
    for start in starts {
        for directory in start.ancestors() {
            let candidate = directory.join(relative);
            if looked_at.contains(&candidate) {
                continue;
            }
            if candidate.is_file() {
                check_trusted(&candidate, user)?;
                return Ok(Search::Found(candidate));
            }
            looked_at.push(candidate);
        }
    }
    Ok(Search::Missing(looked_at))
}

/// The directory of the running executable, where searches start.
pub fn executable_directory() -> Option<PathBuf> {
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(Path::to_path_buf))
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    fn private_directory() -> tempfile::TempDir {
        let directory = tempfile::tempdir().unwrap();
        std::fs::set_permissions(directory.path(), std::fs::Permissions::from_mode(0o700)).unwrap();
        directory
    }

    #[test]
    fn a_private_file_is_trusted() {
        let root = private_directory();
        let file = root.path().join("lib.so");
        std::fs::write(&file, b"").unwrap();
        check_trusted(&file, current_user()).unwrap();
    }

    #[test]
    fn a_file_in_a_directory_others_can_write_is_refused() {
        let root = private_directory();
        let shared = root.path().join(".ort");
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o777)).unwrap();
        let file = shared.join("libonnxruntime.so");
        std::fs::write(&file, b"").unwrap();
        let message = check_trusted(&file, current_user())
            .unwrap_err()
            .to_string();
        assert!(
            message.contains(&shared.display().to_string()) && message.contains("777"),
            "{message}"
        );
        // The sticky bit is what makes /tmp safe to share.
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
        check_trusted(&file, current_user()).unwrap();
    }

    #[test]
    fn a_file_others_can_write_is_refused() {
        let root = private_directory();
        let file = root.path().join("model.onnx");
        std::fs::write(&file, b"").unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o666)).unwrap();
        assert!(matches!(
            check_trusted(&file, current_user()),
            Err(UntrustedPath::WritableByOthers { .. })
        ));
    }

    #[test]
    fn a_file_of_another_user_is_refused() {
        let root = private_directory();
        let file = root.path().join("lib.so");
        std::fs::write(&file, b"").unwrap();
        let stranger = 4242;
        // Root can give the file away; anyone else checks as a user who is not its owner.
        let (owner, user) = if current_user() == ROOT_UID {
            std::os::unix::fs::chown(&file, Some(stranger), None).unwrap();
            (stranger, ROOT_UID)
        } else {
            (current_user(), stranger)
        };
        let message = check_trusted(&file, user).unwrap_err().to_string();
        assert!(
            message.contains("not by you") && message.contains(&format!("uid {owner}")),
            "{message}"
        );
    }

    #[test]
    fn a_link_to_a_file_others_can_write_is_refused() {
        let root = private_directory();
        let open = root.path().join("open");
        std::fs::create_dir(&open).unwrap();
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o777)).unwrap();
        let target = open.join("lib.so");
        std::fs::write(&target, b"").unwrap();
        let link = root.path().join("lib.so");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        assert!(matches!(
            check_trusted(&link, current_user()),
            Err(UntrustedPath::WritableByOthers { .. })
        ));
    }

    #[test]
    fn the_nearest_candidate_is_found_and_checked() {
        let root = private_directory();
        let nested = root.path().join("a/b");
        std::fs::create_dir_all(&nested).unwrap();
        let relative = Path::new("models/m.onnx");
        match find_in_ancestors(relative, std::slice::from_ref(&nested), current_user()).unwrap() {
            Search::Missing(looked_at) => {
                assert_eq!(looked_at[0], nested.join(relative));
                assert!(looked_at.contains(&root.path().join(relative)));
            }
            Search::Found(path) => panic!("found {}", path.display()),
        }
        std::fs::create_dir_all(root.path().join("models")).unwrap();
        std::fs::write(root.path().join(relative), b"").unwrap();
        match find_in_ancestors(relative, &[nested], current_user()).unwrap() {
            Search::Found(path) => assert_eq!(path, root.path().join(relative)),
            Search::Missing(looked_at) => panic!("missing: {looked_at:?}"),
        }
    }
}
