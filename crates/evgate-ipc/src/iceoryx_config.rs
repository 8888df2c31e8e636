//! evgate's own iceoryx2 configuration, built in code and handed to every node.
//!
//! Left to itself, iceoryx2 loads the first `config/iceoryx2.toml` it finds (the working
//! directory's first) and keeps its files under `/tmp/iceoryx2`, which any local user can create
//! before us and so read or spoof every pipeline of the machine. evgate reads no configuration
//! file; its root is a directory of this user only, created mode 0700 and checked on every start:
//!
//! * `$XDG_RUNTIME_DIR/evgate` when `XDG_RUNTIME_DIR` is an absolute path,
//! * `/tmp/evgate-<uid>` otherwise.
//!
//! Shared-memory objects live in the machine-wide `/dev/shm`, so their names carry a prefix of
//! this user's (`evgate<uid>_`): pipelines of different users never meet there, and evgate's
//! stale-resource cleanup touches no other application's files. Any consumer has to use the same
//! two settings (`examples/python/kept_consumer.py` does).
//!
//! iceoryx2 still reads its process-wide configuration in places that take none (cleaning up
//! a dead node whose details are gone), and would look for files there. So the configuration is
//! also written to `<root>/iceoryx2.toml` and installed as iceoryx2's global one before any
//! node exists.

use std::fs::DirBuilder;
use std::io::ErrorKind;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, SemanticString};

/// Why evgate's iceoryx2 root cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SharedMemoryRootError {
    #[error("cannot create the iceoryx2 root {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot inspect the iceoryx2 root {path}: {source}")]
    Inspect {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the iceoryx2 root {path} is a {found}, not a directory; remove it")]
    NotADirectory { path: PathBuf, found: &'static str },
    #[error(
        "the iceoryx2 root {path} belongs to user {owner}, not to this user ({user}): another \
         user could read or spoof this user's pipelines through it; remove it, or set \
         XDG_RUNTIME_DIR to a directory of your own"
    )]
    ForeignOwner {
        path: PathBuf,
        owner: u32,
        user: u32,
    },
    #[error(
        "the iceoryx2 root {path} has mode {mode:04o}, so other users can enter it; accepted: \
         0700 (chmod 700 {path})"
    )]
    OpenToOthers { path: PathBuf, mode: u32 },
    #[error("the iceoryx2 root {path} is not a path iceoryx2 accepts: {reason}")]
    Rejected { path: PathBuf, reason: String },
    #[error("cannot write evgate's iceoryx2 configuration {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("iceoryx2 refuses evgate's configuration {path}: {reason}")]
    Install { path: PathBuf, reason: String },
    #[error(
        "iceoryx2's process-wide configuration was loaded before evgate's (root {found}); \
         create evgate's nodes before any other iceoryx2 call"
    )]
    LoadedTooEarly { found: String },
}

fn current_user() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// The directory evgate keeps its iceoryx2 files in, for this user and environment.
pub fn root_directory() -> PathBuf {
    root_for(std::env::var_os("XDG_RUNTIME_DIR"), current_user())
}

fn root_for(xdg_runtime_dir: Option<std::ffi::OsString>, user: u32) -> PathBuf {
    match xdg_runtime_dir.map(PathBuf::from) {
        Some(runtime) if runtime.is_absolute() => runtime.join("evgate"),
        _ => PathBuf::from(format!("/tmp/evgate-{user}")),
    }
}

/// The prefix of every file evgate's iceoryx2 creates, in the root and in `/dev/shm`.
pub fn file_prefix() -> String {
    format!("evgate{}_", current_user())
}

/// Creates `path` mode 0700 when it does not exist, then checks that it is a directory (not a
/// link) of this user that no one else may enter. In a sticky directory such as `/tmp` only its
/// owner can rename or remove the entry afterwards, so what was checked stays ours.
pub fn prepare_root(path: &Path) -> Result<(), SharedMemoryRootError> {
    match DirBuilder::new().mode(0o700).create(path) {
        Ok(()) => {}
        Err(error) if error.kind() == ErrorKind::AlreadyExists => {}
        Err(source) => {
            return Err(SharedMemoryRootError::Create {
                path: path.to_owned(),
                source,
            })
        }
    }
    let metadata =
        std::fs::symlink_metadata(path).map_err(|source| SharedMemoryRootError::Inspect {
            path: path.to_owned(),
            source,
        })?;
    let file_type = metadata.file_type();
    if !file_type.is_dir() {
        let found = if file_type.is_symlink() {
            "symbolic link"
        } else {
            "file"
        };
        return Err(SharedMemoryRootError::NotADirectory {
            path: path.to_owned(),
            found,
        });
    }
    let user = current_user();
    if metadata.uid() != user {
        return Err(SharedMemoryRootError::ForeignOwner {
            path: path.to_owned(),
            owner: metadata.uid(),
            user,
        });
    }
    let mode = metadata.permissions().mode() & 0o7777;
    if mode & 0o077 != 0 {
        return Err(SharedMemoryRootError::OpenToOthers {
            path: path.to_owned(),
            mode,
        });
    }
    Ok(())
}

/// The iceoryx2 configuration with `root` as its root and this user's file prefix.
pub fn config_with_root(root: &Path) -> Result<Config, SharedMemoryRootError> {
    let rejected = |reason: String| SharedMemoryRootError::Rejected {
        path: root.to_owned(),
        reason,
    };
    let mut text = root
        .to_str()
        .ok_or_else(|| rejected("not UTF-8".to_owned()))?
        .to_owned();
    if !text.ends_with('/') {
        text.push('/');
    }
    let root_path = iceoryx2::prelude::Path::new(text.as_bytes())
        .map_err(|error| rejected(format!("{error:?}")))?;
    let prefix = FileName::new(file_prefix().as_bytes())
        .map_err(|error| rejected(format!("prefix: {error:?}")))?;
    let mut config = Config::default();
    config.global.set_root_path(&root_path);
    config.global.prefix = prefix;
    Ok(config)
}

/// Writes `config` to `<root>/iceoryx2.toml` (through a file of this process, renamed into
/// place, so concurrent starts never read half a file) and installs it as iceoryx2's
/// process-wide configuration, which it returns.
fn install_globally(
    config: &Config,
    root: &Path,
) -> Result<&'static Config, SharedMemoryRootError> {
    let path = root.join("iceoryx2.toml");
    let write_error = |source| SharedMemoryRootError::Write {
        path: path.clone(),
        source,
    };
    let text = toml::to_string(config).map_err(|error| SharedMemoryRootError::Install {
        path: path.clone(),
        reason: error.to_string(),
    })?;
    let scratch = root.join(format!(".iceoryx2.toml.{}", std::process::id()));
    std::fs::write(&scratch, text).map_err(write_error)?;
    std::fs::rename(&scratch, &path).map_err(write_error)?;
    let file =
        iceoryx2::prelude::FilePath::new(path.as_os_str().as_encoded_bytes()).map_err(|error| {
            SharedMemoryRootError::Install {
                path: path.clone(),
                reason: format!("{error:?}"),
            }
        })?;
    let installed = Config::setup_global_config_from_file(&file).map_err(|error| {
        SharedMemoryRootError::Install {
            path: path.clone(),
            reason: format!("{error:?}"),
        }
    })?;
    if installed.global.root_path() != config.global.root_path()
        || installed.global.prefix != config.global.prefix
    {
        return Err(SharedMemoryRootError::LoadedTooEarly {
            found: installed.global.root_path().to_string(),
        });
    }
    Ok(installed)
}

/// evgate's iceoryx2 configuration for this process: its root prepared and checked once, and
/// installed as iceoryx2's process-wide configuration.
pub fn evgate_config() -> Result<&'static Config, SharedMemoryRootError> {
    static CONFIG: OnceLock<&'static Config> = OnceLock::new();
    // One thread prepares and installs; the others wait for it (they would share its scratch
    // file, named after the process).
    static PREPARING: Mutex<()> = Mutex::new(());
    if let Some(config) = CONFIG.get() {
        return Ok(*config);
    }
    let _preparing = PREPARING
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(config) = CONFIG.get() {
        return Ok(*config);
    }
    let root = root_directory();
    prepare_root(&root)?;
    let installed = install_globally(&config_with_root(&root)?, &root)?;
    Ok(*CONFIG.get_or_init(|| installed))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch() -> tempfile::TempDir {
        tempfile::tempdir().unwrap()
    }

    #[test]
    fn a_missing_root_is_created_for_this_user_only() {
        let dir = scratch();
        let root = dir.path().join("evgate");
        prepare_root(&root).unwrap();
        let metadata = std::fs::metadata(&root).unwrap();
        assert_eq!(metadata.permissions().mode() & 0o777, 0o700);
        assert_eq!(metadata.uid(), current_user());
        // A second start finds it and accepts it.
        prepare_root(&root).unwrap();
    }

    #[test]
    fn a_root_others_can_enter_is_refused() {
        let dir = scratch();
        let root = dir.path().join("evgate");
        std::fs::create_dir(&root).unwrap();
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o755)).unwrap();
        let error = prepare_root(&root).unwrap_err();
        assert!(
            matches!(
                error,
                SharedMemoryRootError::OpenToOthers { mode: 0o755, .. }
            ),
            "{error}"
        );
        assert!(error.to_string().contains("chmod 700"), "{error}");
    }

    #[test]
    fn a_link_in_place_of_the_root_is_refused() {
        let dir = scratch();
        let target = dir.path().join("elsewhere");
        std::fs::create_dir(&target).unwrap();
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o700)).unwrap();
        let root = dir.path().join("evgate");
        std::os::unix::fs::symlink(&target, &root).unwrap();
        let error = prepare_root(&root).unwrap_err();
        assert!(
            matches!(
                error,
                SharedMemoryRootError::NotADirectory {
                    found: "symbolic link",
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn a_root_another_user_created_is_refused() {
        if current_user() != 0 {
            eprintln!("skipped: giving a directory to another user needs root (CI runs as root)");
            return;
        }
        let dir = scratch();
        let root = dir.path().join("evgate");
        std::fs::create_dir(&root).unwrap();
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o700)).unwrap();
        std::os::unix::fs::chown(&root, Some(65534), Some(65534)).unwrap();
        let error = prepare_root(&root).unwrap_err();
        assert!(
            matches!(
                error,
                SharedMemoryRootError::ForeignOwner {
                    owner: 65534,
                    user: 0,
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn the_config_names_this_users_root_and_prefix() {
        let dir = scratch();
        let config = config_with_root(dir.path()).unwrap();
        let root = config.global.root_path().to_string();
        assert_eq!(
            root.trim_end_matches('/'),
            dir.path().to_str().unwrap().trim_end_matches('/')
        );
        assert_eq!(
            config.global.prefix.to_string(),
            format!("evgate{}_", current_user())
        );
        assert!(config
            .global
            .service_dir()
            .to_string()
            .starts_with(dir.path().to_str().unwrap()));
    }

    #[test]
    fn iceoryx2s_process_wide_configuration_is_evgates() {
        let ours = evgate_config().unwrap();
        let global = Config::global_config();
        assert_eq!(global.global.root_path(), ours.global.root_path());
        assert_eq!(global.global.prefix, ours.global.prefix);
        let file = root_directory().join("iceoryx2.toml");
        let written = std::fs::read_to_string(&file).unwrap();
        assert!(written.contains(&file_prefix()), "{written}");
    }

    #[test]
    fn threads_starting_together_all_get_the_configuration() {
        let handles: Vec<_> = (0..8)
            .map(|_| std::thread::spawn(|| evgate_config().map(|c| c.global.prefix)))
            .collect();
        for handle in handles {
            assert_eq!(handle.join().unwrap().unwrap().to_string(), file_prefix());
        }
    }

    #[test]
    fn the_root_follows_xdg_runtime_dir_only_when_absolute() {
        assert_eq!(
            root_for(Some("/run/user/4242".into()), 4242),
            PathBuf::from("/run/user/4242/evgate")
        );
        assert_eq!(
            root_for(Some("relative/dir".into()), 4242),
            PathBuf::from("/tmp/evgate-4242")
        );
        assert_eq!(root_for(None, 7), PathBuf::from("/tmp/evgate-7"));
    }
}
