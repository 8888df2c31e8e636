//! `evgate compare`: the model-shipping rule on two evaluation reports (or two methods of one).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use evgate_eval::bootstrap::Metric;
use evgate_eval::comparison::{compare, Comparison, Side};
use evgate_eval::Report;

/// Paired bootstrap comparison of a candidate with a baseline, sequence by sequence; the
/// candidate ships when the 95 % interval of its gain on the deciding metric lies above zero.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// report.json of the baseline (`evgate eval --report DIR` writes DIR/report.json).
    #[arg(long, value_name = "REPORT")]
    baseline: PathBuf,
    /// report.json of the candidate; default: the baseline's report (two methods of one run).
    #[arg(long, value_name = "REPORT")]
    candidate: Option<PathBuf>,
    /// Method of the baseline report, e.g. `model:evgate-S` or `linear`.
    #[arg(long, value_name = "NAME")]
    baseline_method: String,
    /// Method of the candidate report; default: the baseline's method.
    #[arg(long, value_name = "NAME")]
    method: Option<String>,
    /// Metric that decides: miou, imo-iou, sr, r, piou, event-precision, event-recall, event-f1.
    #[arg(long, default_value = "miou", value_parser = parse_metric)]
    metric: Metric,
    /// Print the comparison as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

fn parse_metric(name: &str) -> Result<Metric, String> {
    Metric::from_name(name).ok_or_else(|| {
        let accepted: Vec<&str> = Metric::ALL.iter().map(|m| m.name()).collect();
        format!(
            "{name:?} is not a metric; accepted: {}",
            accepted.join(", ")
        )
    })
}

fn read_report(path: &Path) -> anyhow::Result<Report> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the report {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{} is not an evgate eval report.json", path.display()))
}

pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let baseline_report = read_report(&args.baseline)?;
    let candidate_report = match &args.candidate {
        Some(path) => Some(read_report(path)?),
        None => None,
    };
    let candidate_method = args.method.as_deref().unwrap_or(&args.baseline_method);
    let comparison = compare(
        &Side {
            report: &baseline_report,
            method: &args.baseline_method,
        },
        &Side {
            report: candidate_report.as_ref().unwrap_or(&baseline_report),
            method: candidate_method,
        },
        args.metric,
    )?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&comparison)?);
    } else {
        print_table(&comparison);
    }
    Ok(())
}

fn percent(value: Option<f64>) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{:.1}", v * 100.0))
}

fn print_table(comparison: &Comparison) {
    println!(
        "{} (candidate) against {} (baseline), {} paired sequences, horizon metrics at {} ms; in %:",
        comparison.candidate,
        comparison.baseline,
        comparison.paired_sequences,
        comparison.headline_horizon_ms
    );
    if !comparison.unpaired_sequences.is_empty() {
        println!(
            "left out, scored on one side only: {}",
            comparison.unpaired_sequences.join(", ")
        );
    }
    println!(
        "{:<16} {:>9} {:>9} {:>9} {:>18}  verdict",
        "metric", "baseline", "candidate", "gain", "95 % interval"
    );
    for difference in &comparison.metrics {
        let interval = difference.interval.map_or_else(
            || "–".to_owned(),
            |i| format!("[{:.1}, {:.1}]", i.low * 100.0, i.high * 100.0),
        );
        let verdict = if difference.clear_gain {
            "clear gain"
        } else if difference.clear_loss {
            "clear loss"
        } else {
            "within noise"
        };
        println!(
            "{:<16} {:>9} {:>9} {:>9} {:>18}  {verdict}",
            difference.metric.name(),
            percent(difference.baseline_mean),
            percent(difference.candidate_mean),
            percent(difference.mean_difference),
            interval
        );
    }
    println!(
        "ships by the rule (clear gain in {}): {}",
        comparison.deciding_metric.name(),
        if comparison.ships { "yes" } else { "no" }
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_metric_lists_the_accepted_ones() {
        let error = parse_metric("accuracy").unwrap_err();
        assert!(
            error.contains("accuracy") && error.contains("miou, imo-iou"),
            "{error}"
        );
        assert_eq!(parse_metric("event-f1"), Ok(Metric::EventF1));
    }

    #[test]
    fn a_file_that_is_no_report_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.json");
        std::fs::write(&path, "{\"events\": 3}").unwrap();
        let error = format!("{:#}", read_report(&path).unwrap_err());
        assert!(error.contains("summary.json") && error.contains("not an evgate eval report"));
    }
}
