//! `evgate-infer`: the inference service of the pipeline (see docs/runtime.md).

fn main() -> anyhow::Result<()> {
    evgate_ipc::init_service_logging("info");
    let config: evgate_infer::Config = evgate_ipc::parse_with_config_file(&[]);
    let report = evgate_infer::run(&config)?;
    tracing::info!("{}", report.line());
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
