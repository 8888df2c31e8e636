//! Removing what a process killed half-way through creating a service leaves behind.
//!
//! iceoryx2 0.10 creates a service by first writing its static config file with owner-only
//! read-write permissions (its "locked" state), then its content, and only then makes it
//! read-only; everyone who finds the file still writable waits for the creator. A creator killed
//! inside that window (the content write and its fsync take milliseconds) leaves a file that stays
//! writable forever: `open_or_create` then fails with `HangsInCreation` after the creation timeout,
//! and dead-node cleanup does not remove it (it treats a locked static config as a service that
//! does not exist and only drops the dead node's service tag). Every later process of that
//! pipeline fails to start until someone deletes the file by hand.
//!
//! The creator registers a service tag in its node directory before it creates the static config,
//! so a locked static config that no live node holds a tag for has a dead creator and can go.
//! The paths follow iceoryx2 0.10's layout (`<root>/services/<prefix><hash><suffix>`,
//! `<root>/nodes/<node id>/<prefix><hash><tag suffix>`), built from the node's own config.
//!
//! A creator killed one step later, while creating the service's dynamic config (a shared-memory
//! object that stays write-only until initialised), leaves one that nobody may read. When it is
//! empty, iceoryx2 0.10 waits for it to grow without any timeout, and it does so inside dead-node
//! cleanup, which every node creation runs: every later process of the machine hangs at start.
//! A creator initialises its dynamic config within microseconds, so one still unreadable after
//! the creation timeout is abandoned; [`remove_unfinished_dynamic_configs`] removes it before
//! the node is created.

use std::fs::Metadata;
use std::io::ErrorKind;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use iceoryx2::config::Config;
use iceoryx2::node::{NodeState, NodeView};
use iceoryx2::prelude::{CallbackProgression, Node, ServiceName};
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::service_hash::ServiceHash;
use tracing::warn;

use crate::Service;

/// The permissions of a static config that is still being created (iceoryx2's
/// `INIT_PERMISSIONS`); a finished one is read-only.
const LOCKED_STATIC_CONFIG_MODE: u32 = 0o600;

/// Where POSIX shared-memory objects appear as files on Linux, iceoryx2's dynamic configs among them.
const SHARED_MEMORY_DIR: &str = "/dev/shm";

/// Failures while looking for or removing what a killed creator left.
#[derive(Debug, thiserror::Error)]
pub enum StaleServiceError {
    #[error("cannot inspect the static config {path} of service {service:?}: {source}")]
    Inspect {
        path: PathBuf,
        service: String,
        source: std::io::Error,
    },
    #[error("cannot remove the orphaned static config {path} of service {service:?}: {source}")]
    Remove {
        path: PathBuf,
        service: String,
        source: std::io::Error,
    },
    #[error("cannot list the iceoryx2 nodes to find who creates service {service:?}: {reason}")]
    ListNodes { service: String, reason: String },
    #[error("cannot list {path}, where iceoryx2 keeps its dynamic configs: {source}")]
    ListSharedMemory {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Where iceoryx2 keeps the files of one service of one messaging pattern.
struct ServiceFiles {
    hash: String,
    static_config: PathBuf,
}

impl ServiceFiles {
    fn new(config: &Config, name: &ServiceName, pattern: MessagingPattern) -> Self {
        let hash = ServiceHash::new::<<Service as iceoryx2::service::Service>::ServiceNameHasher>(
            name, pattern,
        )
        .to_string();
        let global = &config.global;
        let static_config = Path::new(&global.service_dir().to_string()).join(format!(
            "{}{hash}{}",
            global.prefix, global.service.static_config_storage_suffix
        ));
        Self {
            hash,
            static_config,
        }
    }

    /// The service tag a node registers before it creates or opens this service.
    fn tag_of(&self, config: &Config, node_id: u128) -> PathBuf {
        let global = &config.global;
        Path::new(&global.node_dir().to_string())
            .join(node_id.to_string())
            .join(format!(
                "{}{}{}",
                global.prefix, self.hash, global.node.service_tag_suffix
            ))
    }
}

/// Identifies one file: a new file at the same path, even on a reused inode, differs in ctime.
fn identity(metadata: &Metadata) -> (u64, u64, i64, i64) {
    (
        metadata.dev(),
        metadata.ino(),
        metadata.ctime(),
        metadata.ctime_nsec(),
    )
}

fn is_locked(metadata: &Metadata) -> bool {
    metadata.permissions().mode() & 0o7777 == LOCKED_STATIC_CONFIG_MODE
}

/// Removes the static config of `name` (messaging `pattern`) when it is stuck in creation and no
/// live node can be its creator; true when it removed one, so opening the service again can
/// create it afresh.
pub fn remove_orphaned_static_config(
    node: &Node<Service>,
    name: &ServiceName,
    pattern: MessagingPattern,
) -> Result<bool, StaleServiceError> {
    let config = node.config();
    let files = ServiceFiles::new(config, name, pattern);
    let service = name.as_str();
    let inspect = |source| StaleServiceError::Inspect {
        path: files.static_config.clone(),
        service: service.to_owned(),
        source,
    };
    let before = match std::fs::metadata(&files.static_config) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == ErrorKind::NotFound => return Ok(false),
        Err(error) => return Err(inspect(error)),
    };
    if !is_locked(&before) || any_live_node_holds_tag(config, &files, service)? {
        return Ok(false);
    }
    // The file judged orphaned must be the one removed: a process that removed it meanwhile may
    // already be creating the service anew at the same path.
    match std::fs::metadata(&files.static_config) {
        Ok(now) if identity(&now) == identity(&before) && is_locked(&now) => {}
        Ok(_) => return Ok(false),
        Err(error) if error.kind() == ErrorKind::NotFound => return Ok(false),
        Err(error) => return Err(inspect(error)),
    }
    match std::fs::remove_file(&files.static_config) {
        Ok(()) => {}
        Err(error) if error.kind() == ErrorKind::NotFound => return Ok(false),
        Err(source) => {
            return Err(StaleServiceError::Remove {
                path: files.static_config.clone(),
                service: service.to_owned(),
                source,
            })
        }
    }
    warn!(
        service,
        path = %files.static_config.display(),
        "removed the static config of a service whose creator died while creating it"
    );
    Ok(true)
}

/// Whether a node that is not known to be dead registered a tag for the service; nodes whose
/// state cannot be told count as live, so a doubt never removes a service in creation.
fn any_live_node_holds_tag(
    config: &Config,
    files: &ServiceFiles,
    service: &str,
) -> Result<bool, StaleServiceError> {
    let mut holds = false;
    Node::<Service>::list(config, |state| {
        let id = match &state {
            NodeState::Alive(view) => view.id(),
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => id,
            NodeState::Dead(_) => return CallbackProgression::Continue,
        };
        holds = match std::fs::symlink_metadata(files.tag_of(config, id.value())) {
            Ok(_) => true,
            // A node directory that cannot be read may hold the tag.
            Err(error) => error.kind() != ErrorKind::NotFound,
        };
        if holds {
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    })
    .map_err(|error| StaleServiceError::ListNodes {
        service: service.to_owned(),
        reason: format!("{error:?}"),
    })?;
    Ok(holds)
}

/// A dynamic config of this user that no one may read yet: its creator has not finished
/// initialising it. Other users' files are theirs to clean up, whatever their name.
fn is_unfinished_dynamic_config(metadata: &Metadata) -> bool {
    // SAFETY: geteuid has no preconditions and cannot fail.
    let user = unsafe { libc::geteuid() };
    metadata.is_file() && metadata.uid() == user && metadata.permissions().mode() & 0o444 == 0
}

/// When the creation timeout of a file last changed as `metadata` says runs out, on the
/// monotonic clock: its age is read once from the wall clock, so a clock step during the wait
/// cannot shorten or stretch it.
fn creation_deadline(metadata: &Metadata, creation_timeout: Duration) -> Instant {
    let changed_at =
        UNIX_EPOCH + Duration::new(metadata.ctime().max(0) as u64, metadata.ctime_nsec() as u32);
    let age = SystemTime::now()
        .duration_since(changed_at)
        .unwrap_or(Duration::ZERO);
    Instant::now() + creation_timeout.saturating_sub(age)
}

/// Removes the dynamic configs of this user (`config`'s prefix and suffix: on evgate's own
/// configuration the prefix is this user's `evgate<uid>_`, so no other application's file is
/// looked at) that are still
/// unreadable once the creation timeout has passed since their last change, waiting out that
/// timeout for young ones; returns how many it removed.
pub fn remove_unfinished_dynamic_configs(config: &Config) -> Result<usize, StaleServiceError> {
    let prefix = config.global.prefix.to_string();
    let suffix = config
        .global
        .service
        .dynamic_config_storage_suffix
        .to_string();
    let creation_timeout = config.global.creation_timeout;
    let entries = match std::fs::read_dir(SHARED_MEMORY_DIR) {
        Ok(entries) => entries,
        Err(error) if error.kind() == ErrorKind::NotFound => return Ok(0),
        Err(source) => {
            return Err(StaleServiceError::ListSharedMemory {
                path: PathBuf::from(SHARED_MEMORY_DIR),
                source,
            })
        }
    };
    let mut removed = 0;
    // Entries that vanish or cannot be read are left to their owners: failing here would stop
    // every evgate process from starting over a file that may not even be ours.
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let name = file_name.to_string_lossy();
        if !(name.starts_with(&prefix) && name.ends_with(&suffix)) {
            continue;
        }
        let path = entry.path();
        let Ok(Some(before)) = unfinished_metadata(&path) else {
            continue;
        };
        let deadline = creation_deadline(&before, creation_timeout);
        if !matches!(stays_unfinished_until(&path, &before, deadline), Ok(true)) {
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => {
                removed += 1;
                warn!(
                    path = %path.display(),
                    "removed an iceoryx2 dynamic config its creator never finished"
                );
            }
            Err(error) if error.kind() == ErrorKind::NotFound => {}
            Err(error) => warn!(
                path = %path.display(),
                %error,
                "cannot remove an iceoryx2 dynamic config its creator never finished; \
                 dead-node cleanup may wait on it"
            ),
        }
    }
    Ok(removed)
}

/// Whether the unfinished dynamic config `path` (as `before` describes it) is still the same
/// unfinished file at `deadline`; polls so that a live creator's progress ends the wait at once.
fn stays_unfinished_until(
    path: &Path,
    before: &Metadata,
    deadline: Instant,
) -> std::io::Result<bool> {
    const POLL: Duration = Duration::from_millis(10);
    loop {
        // A creator's progress (size, permissions) changes ctime, so the identity tells it.
        match unfinished_metadata(path)? {
            Some(now) if identity(&now) == identity(before) => {}
            _ => return Ok(false),
        }
        match deadline.checked_duration_since(Instant::now()) {
            Some(remaining) if !remaining.is_zero() => std::thread::sleep(remaining.min(POLL)),
            _ => return Ok(true),
        }
    }
}

/// The metadata of `path` when it is an unfinished dynamic config; `None` when it is finished or gone.
fn unfinished_metadata(path: &Path) -> std::io::Result<Option<Metadata>> {
    match std::fs::symlink_metadata(path) {
        Ok(metadata) if is_unfinished_dynamic_config(&metadata) => Ok(Some(metadata)),
        Ok(_) => Ok(None),
        Err(error) if error.kind() == ErrorKind::NotFound => Ok(None),
        Err(error) => Err(error),
    }
}
