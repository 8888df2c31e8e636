//! evgate-ipc
