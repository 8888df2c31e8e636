//! evgate-eval
