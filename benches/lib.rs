//! Helpers shared by the benchmarks: the command line and the JSON report.

use std::path::Path;

pub type BenchResult<T> = Result<T, Box<dyn std::error::Error>>;

/// The argument after `flag` on this process's command line.
pub fn flag_value(flag: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == flag)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

/// Writes `report` to `out` (creating its folder), prints it, and says where it went.
pub fn write_report(out: &Path, report: &serde_json::Value) -> BenchResult<()> {
    if let Some(parent) = out.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(out, serde_json::to_string_pretty(report)?)?;
    println!("{}", serde_json::to_string_pretty(report)?);
    eprintln!("written to {}", out.display());
    Ok(())
}
