//! The Markdown tables of a report, laid out like the paper's tables (scores in percent).

use std::fmt::Write;

use crate::bootstrap::{Interval, MethodIntervals, Metric};
use crate::method::MethodKind;
use crate::model_tables::model_tables;
use crate::recording::GroundTruth;
use crate::report::{PresetResult, Report};
use crate::summary::{HorizonSummary, MethodSummary};

pub(crate) fn percent(value: Option<f64>) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{:.1}", v * 100.0))
}

/// A score in percent with its 95 % interval over sequences, when it has one:
/// `69.2 [66.1, 72.0]`.
pub(crate) fn percent_within(value: Option<f64>, interval: Option<&Interval>) -> String {
    match (value, interval) {
        (Some(_), Some(interval)) => format!(
            "{} [{:.1}, {:.1}]",
            percent(value),
            interval.low * 100.0,
            interval.high * 100.0
        ),
        _ => percent(value),
    }
}

pub(crate) fn number(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{v:.decimals$}"))
}

/// What a cell of a ground-truth metric says where the recordings have no masks.
pub const NO_MASKS: &str = "n/a — no masks in this recording";

pub(crate) fn rate(value: Option<f64>) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{:.3}", v / 1e6))
}

pub(crate) fn row(cells: &[String]) -> String {
    format!("| {} |\n", cells.join(" | "))
}

pub(crate) fn header(cells: &[String]) -> String {
    let rule: Vec<String> = cells.iter().map(|_| "---".to_owned()).collect();
    row(cells) + &row(&rule)
}

/// Rows of (label, per-preset summaries, overall summary).
pub(crate) fn preset_columns(report: &Report) -> Vec<String> {
    let mut columns: Vec<String> = report.presets.iter().map(|p| p.preset.clone()).collect();
    columns.push("all".to_owned());
    columns
}

/// Per preset column (and "all"): whether any of its recordings has masks.
fn columns_with_masks(report: &Report) -> Vec<bool> {
    let has_masks = |preset: Option<&str>| {
        report
            .sequences
            .iter()
            .filter(|s| preset.is_none_or(|p| s.preset == p))
            .any(|s| s.ground_truth.has_masks())
    };
    let mut columns: Vec<bool> = report
        .presets
        .iter()
        .map(|p| has_masks(Some(&p.preset)))
        .collect();
    columns.push(has_masks(None));
    columns
}

/// A ground-truth score, or [`NO_MASKS`] where there was nothing to score against.
pub(crate) fn truth_cell(has_masks: bool, text: String) -> String {
    if has_masks {
        text
    } else {
        NO_MASKS.to_owned()
    }
}

/// "mIoU / R@0.5" of one method at one horizon, each with its interval.
fn iou_and_recall_cell(
    has_masks: bool,
    at: Option<&HorizonSummary>,
    intervals: Option<&MethodIntervals>,
) -> String {
    let interval = |metric: Metric| intervals.and_then(|i| i.get(&metric));
    truth_cell(
        has_masks,
        format!(
            "{} / {}",
            percent_within(at.and_then(|h| h.mean_iou), interval(Metric::MeanIou)),
            percent_within(
                at.and_then(|h| h.instance_recall),
                interval(Metric::InstanceRecall)
            )
        ),
    )
}

/// One value per preset column, then the "all" column's.
fn per_column<'a, T>(
    report: &'a Report,
    preset: impl Fn(&'a PresetResult) -> Option<&'a T>,
    all: Option<&'a T>,
) -> Vec<Option<&'a T>> {
    report.presets.iter().map(preset).chain([all]).collect()
}

/// The intervals of `method` per preset column and for "all", as [`method_summaries`].
pub(crate) fn method_intervals<'a>(
    report: &'a Report,
    method: &str,
) -> Vec<Option<&'a MethodIntervals>> {
    per_column(
        report,
        |p| p.intervals.get(method),
        report.intervals.get(method),
    )
}

pub(crate) fn method_summaries<'a>(
    report: &'a Report,
    method: &str,
) -> Vec<Option<&'a MethodSummary>> {
    per_column(
        report,
        |p| p.methods.get(method),
        report.overall.get(method),
    )
}

/// The whole report as Markdown; `plots` are the file names of the figures written beside it.
pub fn render(report: &Report, plots: &[(String, String)]) -> String {
    let headline = report.config.headline_horizon_ms;
    let mut out = String::new();
    let split = report
        .split
        .as_deref()
        .map_or_else(String::new, |s| format!(" — split `{s}`"));
    let _ = writeln!(out, "# evgate evaluation{split}\n");
    let presets: Vec<String> = report
        .presets
        .iter()
        .map(|p| format!("{} ({})", p.preset, p.sequences))
        .collect();
    let references: usize = report.sequences.iter().map(|s| s.references).sum();
    let _ = writeln!(
        out,
        "{} sequences ({}), {} reference times, horizons {:?} ms, headline horizon {} ms; \
         scores averaged per sequence, then over sequences; run took {:.0} s.\n",
        report.sequences.len(),
        presets.join(", "),
        references,
        report.config.horizons_ms,
        headline,
        report.elapsed_s
    );
    if report.models().next().is_none() {
        let _ = writeln!(
            out,
            "No model was evaluated: no-forecast and linear start from the ground-truth mask at t, \
             so they measure forecasting alone.\n"
        );
    }
    let count_of = |kind: GroundTruth| {
        report
            .sequences
            .iter()
            .filter(|s| s.ground_truth == kind)
            .count()
    };
    let (camera_frames, events_only) = (
        count_of(GroundTruth::Masks),
        count_of(GroundTruth::EventsOnly),
    );
    if camera_frames > 0 {
        let _ = writeln!(
            out,
            "{camera_frames} recording(s) with masks at camera frame times (EVIMO): the reference \
             times are the frame times, the truth at t + Δt is the frame nearest to it within {} \
             ms (other horizons are not scored there), and per-event scores are not available \
             (no per-event labels).\n",
            report.config.camera_frame_tolerance_ms
        );
    }
    if events_only > 0 {
        let _ = writeln!(
            out,
            "{events_only} recording(s) without ground truth (e.g. DSEC): only the kept share, \
             event rates, runtime and prediction age are measured there; every score that needs \
             masks reads \"{NO_MASKS}\" where no recording of a column has masks.\n"
        );
    }
    let not_run: Vec<String> = report
        .sequences
        .iter()
        .flat_map(|s| {
            s.models_not_run.iter().map(move |m| {
                format!(
                    "`{}` on {} ({} > {})",
                    m.method, s.name, m.padded_sensor, m.model_input
                )
            })
        })
        .collect();
    if !not_run.is_empty() {
        let _ = writeln!(
            out,
            "Not evaluated, the recording's sensor (padded to multiples of 16) being larger than \
             the model's input: {}. The averages of these models, and of no-forecast and linear \
             where the first model sat out, leave those recordings out (export a model for the \
             size to include them).\n",
            not_run.join(", ")
        );
    }
    let _ = writeln!(out, "Methods:\n");
    for method in &report.methods {
        let _ = writeln!(out, "- `{}`: {}", method.name, method.description);
    }
    out.push('\n');

    let forecasters: Vec<&str> = report
        .methods
        .iter()
        .filter(|m| !matches!(m.kind, MethodKind::Oracle))
        .map(|m| m.name.as_str())
        .collect();

    // Table I
    let _ = writeln!(
        out,
        "## Future prediction at t + {headline} ms: mIoU / R@0.5 (%) (Table I)\n"
    );
    let mut cells = vec!["preset".to_owned()];
    cells.extend(forecasters.iter().map(|m| format!("{m} mIoU / R@0.5")));
    out += &header(&cells);
    let with_masks = columns_with_masks(report);
    for (index, column) in preset_columns(report).iter().enumerate() {
        let mut cells = vec![column.clone()];
        for method in &forecasters {
            let at = method_summaries(report, method)[index].and_then(|s| s.at(headline));
            let intervals = method_intervals(report, method)[index];
            cells.push(iou_and_recall_cell(with_masks[index], at, intervals));
        }
        out += &row(&cells);
    }
    out.push('\n');

    // All headline metrics.
    let _ = writeln!(
        out,
        "## All metrics, all sequences (mIoU, IMO IoU, SR@0.5, R@0.5 at t + {headline} ms; pIoU at t; \
         per-event scores of the gate over [t, t + {} ms); kept share and event rates in \
         millions of events per second, which need no ground truth)\n\n\
         In brackets: the 95 % bootstrap interval over sequences (docs/evaluation.md).\n",
        report.config.gate_span_ms
    );
    let any_masks = *with_masks.last().expect("the all column");
    let any_labels = report
        .sequences
        .iter()
        .any(|s| s.ground_truth == GroundTruth::MasksAndEventLabels);
    out += &header(
        &[
            "method",
            "mIoU",
            "IMO IoU",
            "SR@0.5",
            "R@0.5",
            "pIoU",
            "event precision",
            "event recall",
            "event F1",
            "kept %",
            "Mev/s in",
            "Mev/s kept",
        ]
        .map(str::to_owned),
    );
    for method in &report.methods {
        let Some(summary) = report.overall.get(&method.name) else {
            continue;
        };
        let at = summary.at(headline);
        let intervals = report.intervals.get(&method.name);
        let within = |value: Option<f64>, metric: Metric| {
            percent_within(value, intervals.and_then(|i| i.get(&metric)))
        };
        let masks = |value: Option<f64>, metric| truth_cell(any_masks, within(value, metric));
        let labels = |value: Option<f64>, metric| {
            if any_labels {
                within(value, metric)
            } else {
                "n/a — no per-event labels in this recording".to_owned()
            }
        };
        out += &row(&[
            method.name.clone(),
            masks(at.and_then(|h| h.mean_iou), Metric::MeanIou),
            masks(at.and_then(|h| h.imo_iou), Metric::ImoIou),
            masks(at.and_then(|h| h.success_rate), Metric::SuccessRate),
            masks(at.and_then(|h| h.instance_recall), Metric::InstanceRecall),
            masks(summary.point_iou, Metric::PointIou),
            labels(summary.events.precision, Metric::EventPrecision),
            labels(summary.events.recall, Metric::EventRecall),
            labels(summary.events.f1, Metric::EventF1),
            percent(summary.kept.kept_ratio),
            rate(summary.kept.event_rate_hz),
            rate(summary.kept.kept_event_rate_hz),
        ]);
    }
    out.push('\n');

    // OMS sweep
    let _ = writeln!(
        out,
        "## OMS: published setting and best of the sweep (all sequences)\n\n\
         The best setting is chosen by mIoU at t + {headline} ms on the evaluated sequences \
         themselves ({} settings), so it is an optimistic bound for OMS.\n",
        report.oms_sweep.settings.len()
    );
    out += &header(
        &[
            "setting",
            "centre r",
            "surround r",
            "threshold",
            "mIoU",
            "R@0.5",
            "SR@0.5",
            "pIoU",
        ]
        .map(str::to_owned),
    );
    for (label, scores) in [
        ("published", &report.oms_sweep.published),
        ("best of sweep", &report.oms_sweep.best),
    ] {
        if let Some(s) = scores {
            let masks = |value: Option<f64>| truth_cell(any_masks, percent(value));
            out += &row(&[
                label.to_owned(),
                s.parameters.centre_radius.to_string(),
                s.parameters.surround_radius.to_string(),
                s.parameters.threshold.to_string(),
                masks(s.mean_iou),
                masks(s.instance_recall),
                masks(s.success_rate),
                masks(s.point_iou),
            ]);
        }
    }
    out.push('\n');

    // Table II
    let _ = writeln!(out, "## Current instant: pIoU (%) (Table II)\n");
    let mut cells = vec!["method".to_owned()];
    cells.extend(preset_columns(report));
    out += &header(&cells);
    for method in report.methods.iter().filter(|m| {
        matches!(
            m.kind,
            MethodKind::Oms(_) | MethodKind::Model(_) | MethodKind::Oracle
        )
    }) {
        let mut cells = vec![method.name.clone()];
        cells.extend(
            method_summaries(report, &method.name)
                .iter()
                .zip(method_intervals(report, &method.name))
                .zip(&with_masks)
                .map(|((s, intervals), &masks)| {
                    let interval = intervals.and_then(|i| i.get(&Metric::PointIou));
                    truth_cell(masks, percent_within(s.and_then(|s| s.point_iou), interval))
                }),
        );
        out += &row(&cells);
    }
    out.push('\n');

    // Table III
    let _ = writeln!(
        out,
        "## Runtime, prediction age and GFLOPs (Table III)\n\n\
         Runtime is the wall time per window on this machine (the model: the ONNX Runtime call; \
         no-forecast and linear include the model that makes their current mask). Prediction \
         age = forecast horizon − runtime. GFLOPs are analytical, at 640×480.\n"
    );
    out += &header(
        &[
            "method",
            "runtime mean (ms)",
            "runtime std (ms)",
            "runtime median (ms)",
            "prediction age (ms)",
            "GFLOPs",
        ]
        .map(str::to_owned),
    );
    for method in report
        .methods
        .iter()
        .filter(|m| !matches!(m.kind, MethodKind::Oracle))
    {
        let Some(summary) = report.overall.get(&method.name) else {
            continue;
        };
        out += &row(&[
            method.name.clone(),
            number(summary.runtime_ms_mean, 2),
            number(summary.runtime_ms_std, 2),
            number(summary.runtime_ms_median, 2),
            number(summary.prediction_age_ms, 1),
            number(method.gflops, 3),
        ]);
    }
    out.push('\n');

    out += &model_tables(report, &with_masks);

    // Horizon curves as numbers.
    let _ = writeln!(out, "## mIoU (%) against horizon, all sequences\n");
    let mut cells = vec!["method".to_owned()];
    cells.extend(report.config.horizons_ms.iter().map(|h| format!("{h} ms")));
    out += &header(&cells);
    for method in &forecasters {
        if let Some(summary) = report.overall.get(*method) {
            let mut cells = vec![(*method).to_owned()];
            cells.extend(summary.horizons.iter().map(|h| percent(h.mean_iou)));
            out += &row(&cells);
        }
    }
    out.push('\n');

    for (title, binned) in [
        ("events per window", &report.events_per_window),
        ("object speed (px/s)", &report.object_speed),
    ] {
        let _ = writeln!(
            out,
            "## mIoU (%) at t + {headline} ms by {title} (frames pooled over sequences)\n"
        );
        let Some(first) = forecasters.iter().find_map(|m| binned.get(*m)) else {
            continue;
        };
        let mut cells = vec!["method".to_owned()];
        cells.extend(first.iter().map(|b| b.label.clone()));
        out += &header(&cells);
        let mut frames = vec!["frames".to_owned()];
        frames.extend(first.iter().map(|b| b.frames.to_string()));
        out += &row(&frames);
        for method in &forecasters {
            if let Some(bins) = binned.get(*method) {
                let mut cells = vec![(*method).to_owned()];
                cells.extend(bins.iter().map(|b| percent(b.mean_iou)));
                out += &row(&cells);
            }
        }
        out.push('\n');
    }

    if !plots.is_empty() {
        let _ = writeln!(out, "## Plots\n");
        for (title, file) in plots {
            let _ = writeln!(out, "![{title}]({file})\n");
        }
    }

    let _ = writeln!(
        out,
        "## Per sequence (mIoU / R@0.5 at t + {headline} ms, %)\n"
    );
    let mut cells = vec![
        "sequence".to_owned(),
        "preset".to_owned(),
        "refs".to_owned(),
    ];
    cells.extend(forecasters.iter().map(|m| (*m).to_owned()));
    out += &header(&cells);
    for sequence in &report.sequences {
        let mut cells = vec![
            sequence.name.clone(),
            sequence.preset.clone(),
            sequence.references.to_string(),
        ];
        for method in &forecasters {
            let at = sequence.methods.get(*method).and_then(|s| s.at(headline));
            cells.push(iou_and_recall_cell(
                sequence.ground_truth.has_masks(),
                at,
                None,
            ));
        }
        out += &row(&cells);
    }
    out.push('\n');
    out += &gating_table(report);
    out
}

/// Per recording: what ground truth it had, the input event rate and every method's kept share
/// (the figures a recording without masks still gives).
fn gating_table(report: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## Gating per recording: ground truth, input rate (Mev/s) and kept share (%)\n"
    );
    let methods: Vec<&str> = report.methods.iter().map(|m| m.name.as_str()).collect();
    let mut cells = vec![
        "sequence".to_owned(),
        "ground truth".to_owned(),
        "Mev/s in".to_owned(),
    ];
    cells.extend(methods.iter().map(|m| format!("{m} kept")));
    out += &header(&cells);
    for sequence in &report.sequences {
        let input_rate = sequence.methods.values().find_map(|s| s.kept.event_rate_hz);
        let ground_truth = match sequence.ground_truth {
            GroundTruth::MasksAndEventLabels => "masks, event labels",
            GroundTruth::Masks => "masks",
            GroundTruth::EventsOnly => "none",
        };
        let mut cells = vec![
            sequence.name.clone(),
            ground_truth.to_owned(),
            rate(input_rate),
        ];
        cells.extend(
            methods
                .iter()
                .map(|m| percent(sequence.methods.get(*m).and_then(|s| s.kept.kept_ratio))),
        );
        out += &row(&cells);
    }
    out
}
