//! evgate-sim
