//! `evgate`: the umbrella command line. Each subcommand lives in its own module; this file only
//! parses the command line, sets up logging and dispatches.

mod compare;
mod convert;
mod eval;
mod info;
mod render;
mod run;
mod sim;

use std::io::IsTerminal;

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
    /// Simulate an event camera with ground truth (labelled sequences, benchmark suites).
    Sim(sim::SimArgs),
    /// Draw an event file (with labels, mask outlines or a suppressed stream) as PNGs or a GIF.
    Render(render::RenderArgs),
    /// Score the model and the baselines on labelled sequences; write JSON, Markdown and plots.
    Eval(eval::EvalArgs),
    /// Decide whether a candidate beats a baseline: paired bootstrap over the sequences of two
    /// evaluation reports (or two methods of one).
    Compare(compare::CompareArgs),
    /// Run the pipeline (ingest → infer → gate) with a live status line and a final summary.
    Run(run::RunArgs),
    /// Describe an event file: format, sensor, event count, times, rate, polarity, repairs.
    Info(info::InfoArgs),
    /// Convert an event file; the output format follows the extension (.csv, .raw EVT 3.0, .evg).
    Convert(convert::ConvertArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // Long jobs (`sim suite`, `eval`) are often logged to a file, where colour codes are noise.
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    let cli: Cli = evgate_ipc::parse_with_config_file(&["run"]);
    match cli.command {
        Command::Sim(args) => sim::run(args),
        Command::Render(args) => render::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Run(args) => run::run(args),
        Command::Info(args) => info::run(args),
        Command::Convert(args) => convert::run(args),
    }
}
