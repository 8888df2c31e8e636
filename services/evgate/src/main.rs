//! `evgate`: the umbrella command line. Each subcommand lives in its own module; this file only
//! parses the command line, sets up logging and dispatches.

mod run;

use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

/// Motion-aware event suppression for event cameras.
#[derive(Parser)]
#[command(name = "evgate", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the pipeline (ingest → infer → gate) with a live status line and a final summary.
    Run(run::RunArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")))
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => run::run(args),
    }
}
