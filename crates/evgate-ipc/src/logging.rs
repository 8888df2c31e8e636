//! The log set-up of the pipeline's service binaries: tracing on stderr (stdout carries their
//! JSON summaries), filtered by `RUST_LOG`.

use std::io::IsTerminal;

use tracing_subscriber::EnvFilter;

/// Installs the global subscriber; `default_filter` applies when `RUST_LOG` is unset or invalid.
pub fn init_service_logging(default_filter: &str) {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default_filter)),
        )
        .with_writer(std::io::stderr)
        // Colour codes only help a terminal; in a log file or a test's failure report they are noise.
        .with_ansi(std::io::stderr().is_terminal())
        .init();
}
