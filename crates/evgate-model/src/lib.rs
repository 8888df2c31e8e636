//! evgate-model
