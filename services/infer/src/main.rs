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

fn main() -> anyhow::Result<()> {
    evgate_ipc::init_service_logging("info");
    let args = args::InferArgs::parse();
    let report = service::run(&args)?;
    tracing::info!("{}", report.line());
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
