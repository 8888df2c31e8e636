//! Creating the iceoryx2 node of a process.

use iceoryx2::prelude::{Node, NodeBuilder, NodeName};
use tracing::{debug, info};

use crate::iceoryx_config::{evgate_config, SharedMemoryRootError};
use crate::stale_service::{remove_unfinished_dynamic_configs, StaleServiceError};
use crate::Service;

/// Node creation failures.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error("node name {name:?} is rejected by iceoryx2: {reason}")]
    InvalidName { name: String, reason: String },
    #[error("cannot create iceoryx2 node {name:?}: {reason}")]
    Create { name: String, reason: String },
    #[error(transparent)]
    Root(#[from] SharedMemoryRootError),
    #[error(transparent)]
    StaleService(#[from] StaleServiceError),
}

/// Creates the node of this process on evgate's own iceoryx2 configuration
/// ([`crate::iceoryx_config`]) and removes the shared-memory resources left by processes
/// that died without cleaning up (crashed or killed), so a restarted service can reopen its
/// ports instead of finding them occupied.
pub fn create_node(name: &str) -> Result<Node<Service>, NodeError> {
    let node_name = NodeName::new(name).map_err(|error| NodeError::InvalidName {
        name: name.to_owned(),
        reason: format!("{error:?}"),
    })?;
    let config = evgate_config()?;
    // Node creation cleans dead nodes, which would wait forever on an empty unfinished one.
    remove_unfinished_dynamic_configs(config)?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .create::<Service>()
        .map_err(|error| NodeError::Create {
            name: name.to_owned(),
            reason: format!("{error:?}"),
        })?;
    let cleanup = node.try_cleanup_dead_nodes();
    if cleanup.cleanups > 0 {
        info!(
            removed = cleanup.cleanups,
            "removed resources of dead iceoryx2 nodes"
        );
    }
    if cleanup.failed_cleanups > 0 {
        // Typically nodes of other users or ones another process is cleaning right now.
        debug!(
            failed = cleanup.failed_cleanups,
            "could not remove resources of some dead iceoryx2 nodes"
        );
    }
    Ok(node)
}
