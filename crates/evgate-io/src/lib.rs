//! evgate-io
