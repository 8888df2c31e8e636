//! `evgate-ingest`: publishes events into an evgate pipeline (see docs/pipeline.md).

fn main() -> anyhow::Result<()> {
    evgate_ipc::init_service_logging("info,iceoryx2_bb_loggers=error");
    let config: evgate_ingest::Config = evgate_ipc::parse_with_config_file(&[]);
    let summary = evgate_ingest::run(&config)?;
    if config.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        tracing::info!(?summary, "ingest finished");
    }
    Ok(())
}
