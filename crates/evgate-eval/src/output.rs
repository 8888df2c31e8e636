//! Writes a report to a folder: `report.json`, `report.md` and the PNG plots.

use std::fs;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::binned::{BinValue, EVENT_BINS_FIRST_DECADE, EVENT_BINS_LAST_DECADE};
use crate::markdown;
use crate::method::MethodKind;
use crate::plot::{LinePlot, PlotError, Series, XAxis};
use crate::report::Report;
use crate::summary::MethodSummary;

#[derive(Debug, Error)]
pub enum OutputError {
    #[error("cannot create report folder {path}: {source}")]
    Folder {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot serialise the report as JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// The files written, relative to the folder.
#[derive(Clone, Debug, PartialEq)]
pub struct WrittenReport {
    pub json: PathBuf,
    pub markdown: PathBuf,
    pub plots: Vec<PathBuf>,
}

fn write(path: PathBuf, contents: &str) -> Result<PathBuf, OutputError> {
    fs::write(&path, contents).map_err(|source| OutputError::Write {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}

/// Methods drawn in the plots: everything but the oracle (a flat 100 % on the truth grid).
fn plotted(report: &Report) -> Vec<&str> {
    report
        .methods
        .iter()
        .filter(|m| !matches!(m.kind, MethodKind::Oracle))
        .map(|m| m.name.as_str())
        .collect()
}

fn horizon_series<'a>(
    methods: &[&str],
    lookup: impl Fn(&str) -> Option<&'a MethodSummary>,
) -> Vec<Series> {
    methods
        .iter()
        .filter_map(|&name| {
            let summary = lookup(name)?;
            Some(Series {
                name: name.to_owned(),
                points: summary
                    .horizons
                    .iter()
                    .filter_map(|h| Some((f64::from(h.horizon_ms), h.mean_iou? * 100.0)))
                    .collect(),
            })
        })
        .collect()
}

fn binned_series(
    methods: &[&str],
    binned: &std::collections::BTreeMap<String, Vec<BinValue>>,
    x: impl Fn(usize, &BinValue) -> f64,
) -> Vec<Series> {
    methods
        .iter()
        .filter_map(|&name| {
            let bins = binned.get(name)?;
            Some(Series {
                name: name.to_owned(),
                points: bins
                    .iter()
                    .enumerate()
                    .filter_map(|(k, b)| Some((x(k, b), b.mean_iou? * 100.0)))
                    .collect(),
            })
        })
        .collect()
}

fn mean_iou_plot(title: String, x_label: &str, x_axis: XAxis, series: Vec<Series>) -> LinePlot {
    LinePlot {
        title,
        x_label: x_label.to_owned(),
        y_label: "mIoU [%]".to_owned(),
        x_axis,
        y_range: (0.0, 100.0),
        y_step: 10.0,
        series,
    }
}

/// Writes everything into `folder` (created if missing). Plots without any point are skipped.
pub fn write_report(report: &Report, folder: &Path) -> Result<WrittenReport, OutputError> {
    fs::create_dir_all(folder).map_err(|source| OutputError::Folder {
        path: folder.to_path_buf(),
        source,
    })?;
    let headline = report.config.headline_horizon_ms;
    let methods = plotted(report);
    let mut plots: Vec<(String, String, LinePlot)> = Vec::new();
    plots.push((
        "mIoU against horizon, all sequences".to_owned(),
        "horizon-all.png".to_owned(),
        mean_iou_plot(
            "mIoU vs horizon: all sequences".to_owned(),
            "horizon [ms]",
            XAxis::Linear { step: 10.0 },
            horizon_series(&methods, |m| report.overall.get(m)),
        ),
    ));
    for preset in &report.presets {
        plots.push((
            format!("mIoU against horizon, {}", preset.preset),
            format!("horizon-{}.png", preset.preset),
            mean_iou_plot(
                format!("mIoU vs horizon: {}", preset.preset),
                "horizon [ms]",
                XAxis::Linear { step: 10.0 },
                horizon_series(&methods, |m| preset.methods.get(m)),
            ),
        ));
    }
    plots.push((
        format!("mIoU at t + {headline} ms against events per window"),
        "events-per-window.png".to_owned(),
        mean_iou_plot(
            format!("mIoU at +{headline} ms vs events per window"),
            "events in the 50 ms window (log)",
            XAxis::Log10 {
                first_decade: EVENT_BINS_FIRST_DECADE as i32,
                last_decade: EVENT_BINS_LAST_DECADE as i32,
            },
            binned_series(&methods, &report.events_per_window, |_, b| {
                (b.lower.unwrap_or(1.0) * b.upper.unwrap_or(1.0)).sqrt()
            }),
        ),
    ));
    plots.push((
        format!("mIoU at t + {headline} ms by object speed"),
        "object-speed.png".to_owned(),
        mean_iou_plot(
            format!("mIoU at +{headline} ms by object speed"),
            "object speed [px/s]",
            XAxis::Categories(report.config.speed_bucket_labels()),
            binned_series(&methods, &report.object_speed, |k, _| k as f64),
        ),
    ));

    let mut written_plots = Vec::new();
    let mut linked = Vec::new();
    for (title, file, plot) in plots {
        if plot.series.iter().all(|s| s.points.is_empty()) {
            continue;
        }
        let path = folder.join(&file);
        plot.write_png(&path)?;
        written_plots.push(path);
        linked.push((title, file));
    }
    let json = write(
        folder.join("report.json"),
        &serde_json::to_string_pretty(report)?,
    )?;
    let markdown = write(folder.join("report.md"), &markdown::render(report, &linked))?;
    Ok(WrittenReport {
        json,
        markdown,
        plots: written_plots,
    })
}
