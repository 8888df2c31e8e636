//! `evgate-infer`: the inference service of the pipeline (see docs/runtime.md).

mod args;
mod horizons;
mod latency;
mod latest_slot;
mod service;
mod stats;
mod windowing;
mod worker;

use clap::Parser;
use tracing_subscriber::EnvFilter;

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = args::InferArgs::parse();
    let report = service::run(&args)?;
    tracing::info!("{}", report.line());
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
