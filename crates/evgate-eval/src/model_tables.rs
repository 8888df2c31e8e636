//! The two tables that compare networks: the ablation (Table VI: no forecast, linear
//! extrapolation, flow warping without ATC, with the reference ATC and with the position-aware
//! ATC) and the model sizes (Table VII: parameters, GFLOPs, runtime, prediction age, accuracy).

use std::fmt::Write;

use crate::markdown::{header, method_summaries, number, percent, preset_columns, row, truth_cell};
use crate::method::{MethodInfo, ModelInfo};
use crate::report::Report;

/// ATC variants in the order of the ablation's rows (weakest first).
const ATC_ORDER: [&str; 3] = ["none", "reference", "position-aware"];
/// Size classes in increasing width.
const SIZE_ORDER: [&str; 4] = ["XS", "S", "M", "L"];

fn model_of(method: &MethodInfo) -> &ModelInfo {
    method.model.as_ref().expect("Report::models yields models")
}

fn atc_cell(atc: &str) -> String {
    match atc {
        "none" => "×".to_owned(),
        other => format!("✓ ({other})"),
    }
}

fn model_label(method: &MethodInfo) -> String {
    let info = model_of(method);
    let untrained = if info.trained { "" } else { ", untrained" };
    format!("`{}` ({} steps{untrained})", method.name, info.train_steps)
}

/// Markdown of Tables VI and VII; `with_masks` says per preset column (and "all") whether any
/// recording there has masks.
pub fn model_tables(report: &Report, with_masks: &[bool]) -> String {
    let mut out = ablation(report, with_masks);
    out.push('\n');
    out += &sizes(report, with_masks);
    out
}

fn headline_miou_cells(report: &Report, method: &str, with_masks: &[bool]) -> Vec<String> {
    let headline = report.config.headline_horizon_ms;
    method_summaries(report, method)
        .iter()
        .zip(with_masks)
        .map(|(s, &masks)| {
            truth_cell(
                masks,
                percent(s.and_then(|s| s.at(headline)).and_then(|h| h.mean_iou)),
            )
        })
        .collect()
}

fn ablation(report: &Report, with_masks: &[bool]) -> String {
    let headline = report.config.headline_horizon_ms;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## Ablation: mIoU (%) at t + {headline} ms (Table VI)\n"
    );
    let Some(primary) = report.models().next() else {
        let _ = writeln!(
            out,
            "No model was evaluated: the ablation needs at least one (`--model`).\n"
        );
        return out;
    };
    let size = model_of(primary).size.clone();
    let _ = writeln!(
        out,
        "FW = future masks by flow warping; ATC = attention-based time conditioning. Rows: no \
         forecast and linear extrapolation of `{}`'s current mask, then every size-{size} model \
         by ATC variant (none = flow warping without ATC; reference = the same time query \
         everywhere; position-aware = the full model).\n",
        primary.name
    );
    let mut cells = vec!["FW".to_owned(), "ATC".to_owned(), "method".to_owned()];
    cells.extend(preset_columns(report));
    out += &header(&cells);
    let mut rows: Vec<(String, String, String, &str)> = vec![
        (
            "×".to_owned(),
            "×".to_owned(),
            "`no-forecast`".to_owned(),
            "no-forecast",
        ),
        (
            "linear".to_owned(),
            "×".to_owned(),
            "`linear`".to_owned(),
            "linear",
        ),
    ];
    let mut variants: Vec<&MethodInfo> = report
        .models()
        .filter(|m| model_of(m).size == size)
        .collect();
    variants.sort_by_key(|m| {
        ATC_ORDER
            .iter()
            .position(|&a| a == model_of(m).atc)
            .unwrap_or(ATC_ORDER.len())
    });
    for method in &variants {
        rows.push((
            "✓".to_owned(),
            atc_cell(&model_of(method).atc),
            model_label(method),
            method.name.as_str(),
        ));
    }
    for (flow_warping, atc, label, method) in rows {
        let mut cells = vec![flow_warping, atc, label];
        cells.extend(headline_miou_cells(report, method, with_masks));
        out += &row(&cells);
    }
    let missing: Vec<&str> = ATC_ORDER
        .iter()
        .copied()
        .filter(|&atc| !variants.iter().any(|m| model_of(m).atc == atc))
        .collect();
    if !missing.is_empty() {
        let _ = writeln!(
            out,
            "\nNot in this run (no size-{size} model with ATC {}): pass one with \
             `--model NAME=PATH` or `--ablation-models DIR`.",
            missing.join(", ")
        );
    }
    out
}

fn sizes(report: &Report, with_masks: &[bool]) -> String {
    let headline = report.config.headline_horizon_ms;
    let mut out = String::new();
    let _ = writeln!(out, "## Model sizes (Table VII)\n");
    let mut models: Vec<&MethodInfo> = report.models().collect();
    if models.is_empty() {
        let _ = writeln!(out, "No model was evaluated.\n");
        return out;
    }
    models.sort_by_key(|m| {
        let info = model_of(m);
        (
            SIZE_ORDER
                .iter()
                .position(|&s| s == info.size)
                .unwrap_or(SIZE_ORDER.len()),
            ATC_ORDER
                .iter()
                .position(|&a| a == info.atc)
                .unwrap_or(ATC_ORDER.len()),
        )
    });
    let sources: Vec<String> = models
        .iter()
        .filter_map(|m| model_of(m).size_figures_from.as_ref())
        .map(|p| format!("`{}`", p.display()))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let _ = writeln!(
        out,
        "Parameters counted in each ONNX file. GFLOPs (one window, one horizon) from {}, where \
         the table's row for the size has the model's parameter count; \"–\" where it describes \
         another architecture or no table was given (`--model-flops`). Runtime is the median \
         ONNX Runtime call per window on this machine; mIoU and R@0.5 at t + {headline} ms over \
         all recordings with masks.\n",
        if sources.is_empty() {
            "the FLOP table".to_owned()
        } else {
            sources.join(", ")
        }
    );
    out += &header(
        &[
            "method",
            "size",
            "ATC",
            "parameters",
            "GFLOPs 346×260",
            "GFLOPs 640×480",
            "runtime median (ms)",
            "prediction age (ms)",
            "mIoU",
            "R@0.5",
        ]
        .map(str::to_owned),
    );
    let all_masks = *with_masks.last().expect("the all column");
    for method in &models {
        let info = model_of(method);
        let summary = report.overall.get(&method.name);
        let at = summary.and_then(|s| s.at(headline));
        out += &row(&[
            model_label(method),
            info.size.clone(),
            atc_cell(&info.atc),
            info.parameters
                .map_or_else(|| "–".to_owned(), |p| p.to_string()),
            number(method.gflops_346x260, 3),
            number(method.gflops, 3),
            number(summary.and_then(|s| s.runtime_ms_median), 2),
            number(summary.and_then(|s| s.prediction_age_ms), 1),
            truth_cell(all_masks, percent(at.and_then(|h| h.mean_iou))),
            truth_cell(all_masks, percent(at.and_then(|h| h.instance_recall))),
        ]);
    }
    let _ = writeln!(out, "\nmIoU (%) at t + {headline} ms per preset:\n");
    let mut cells = vec!["method".to_owned(), "size".to_owned()];
    cells.extend(preset_columns(report));
    out += &header(&cells);
    for method in &models {
        let mut cells = vec![model_label(method), model_of(method).size.clone()];
        cells.extend(headline_miou_cells(report, &method.name, with_masks));
        out += &row(&cells);
    }
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::fixture;
    use crate::method::MethodKind;
    use crate::{EvalConfig, Evaluation, FlopTable, Recording};

    fn with_models(models: &[(&str, &str, &str, bool)]) -> Report {
        let recording =
            Recording::from_labelled(fixture::sequence(), Path::new("suite/test/slide-1.npz"))
                .unwrap();
        let mut evaluation = Evaluation::new(EvalConfig::default(), Vec::new()).unwrap();
        evaluation.evaluate(&recording, || {}).unwrap();
        let mut report = evaluation.finish(None).unwrap();
        // Stand-ins for networks: each reuses a baseline's scores under a model's identity.
        for (index, &(name, size, atc, trained)) in models.iter().enumerate() {
            let method = MethodInfo {
                name: format!("model:{name}"),
                description: String::new(),
                kind: MethodKind::Model(index),
                forecast_horizon_ms: 100.0,
                gflops: None,
                gflops_346x260: None,
                model: Some(ModelInfo {
                    size: size.to_owned(),
                    atc: atc.to_owned(),
                    base_channels: 16,
                    train_steps: 900 + index as u64,
                    trained,
                    path: None,
                    parameters: None,
                    size_figures_from: None,
                    threshold_logit: 0.0,
                    keep_threshold_logit: 0.0,
                    keep_dilation_px: 0,
                }),
            };
            let scores = report.overall["linear"].clone();
            report.overall.insert(method.name.clone(), scores);
            for preset in &mut report.presets {
                let scores = preset.methods["linear"].clone();
                preset.methods.insert(method.name.clone(), scores);
            }
            report.methods.push(method);
        }
        report
    }

    #[test]
    fn ablation_rows_follow_the_paper_and_name_missing_variants() {
        let report = with_models(&[
            ("S", "S", "position-aware", true),
            ("S-ref", "S", "reference", false),
            ("S-none", "S", "none", true),
            ("XS", "XS", "position-aware", true),
        ]);
        let text = ablation(&report, &[true, true]);
        let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("| ")).collect();
        assert_eq!(rows.len(), 2 + 5, "{text}");
        assert!(rows[2].starts_with("| × | × | `no-forecast` |"), "{text}");
        assert!(rows[3].starts_with("| linear | × | `linear` |"), "{text}");
        assert!(
            rows[4].starts_with("| ✓ | × | `model:S-none` (902 steps) |"),
            "{text}"
        );
        assert!(
            rows[5].starts_with("| ✓ | ✓ (reference) | `model:S-ref` (901 steps, untrained) |"),
            "{text}"
        );
        assert!(rows[6].starts_with("| ✓ | ✓ (position-aware) | `model:S` (900 steps) |"));
        assert!(
            !text.contains("model:XS"),
            "other sizes belong to Table VII: {text}"
        );
        assert!(!text.contains("Not in this run"));

        let partial = ablation(
            &with_models(&[("S", "S", "position-aware", true)]),
            &[true, true],
        );
        assert!(
            partial.contains("no size-S model with ATC none, reference"),
            "{partial}"
        );
    }

    #[test]
    fn size_table_orders_by_size_and_reads_the_flop_table() {
        let mut report = with_models(&[
            ("L", "L", "position-aware", true),
            ("XS", "XS", "position-aware", true),
            ("S", "S", "none", true),
        ]);
        let table: FlopTable = serde_json::from_str(
            r#"{"models": [{"size": "XS", "parameters": 558793, "gflops-346x260": 1.295,
                "gflops-640x480": 4.408}, {"size": "S", "parameters": 2227653,
                "gflops-346x260": 5.037, "gflops-640x480": 16.67}]}"#,
        )
        .unwrap();
        let counted = |name: &str, report: &mut Report, parameters: u64| {
            let method = report.methods.iter_mut().find(|m| m.name == name).unwrap();
            method.model.as_mut().unwrap().parameters = Some(parameters);
        };
        counted("model:XS", &mut report, 558_793);
        // The S file is another architecture than the table's S row: no GFLOPs from it.
        counted("model:S", &mut report, 325_880);
        let mismatched = table.apply(&mut report, Path::new("evidence/models/flops.json"));
        assert_eq!(mismatched, ["model:S"]);
        let text = sizes(&report, &[true, true]);
        let xs = text.find("| `model:XS`").unwrap();
        let l = text.find("| `model:L`").unwrap();
        assert!(xs < l, "{text}");
        assert!(
            text.contains("| XS | ✓ (position-aware) | 558793 | 1.295 | 4.408 |"),
            "{text}"
        );
        assert!(
            text.contains("| L | ✓ (position-aware) | – | – | – |"),
            "{text}"
        );
        assert!(text.contains("`evidence/models/flops.json`"));
    }

    #[test]
    fn recordings_without_masks_say_so_instead_of_a_score() {
        let report = with_models(&[("S", "S", "position-aware", true)]);
        let text = model_tables(&report, &[false, false]);
        assert!(text.contains(crate::markdown::NO_MASKS), "{text}");
        assert!(!text.contains("| ✓ | ✓ (position-aware) | `model:S` (900 steps) | 1"));
    }
}
