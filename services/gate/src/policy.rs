//! What happens to events no valid forecast judges.

use std::time::Duration;

use serde::{Deserialize, Serialize};

/// Fate of an event without a valid forecast (before the first forecast, after the latest one
/// expired, or off the forecast's time range).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum NoForecast {
    /// Let it through (nothing is lost when the inference lags or stops).
    Pass,
    /// Suppress it.
    Drop,
    /// Judge it by the nearest mask of the latest forecast (the current mask before the
    /// forecast's time, the farthest horizon after it) while that forecast is at most
    /// `--last-mask-max-age-ms` away from the event; older forecasts let it through.
    LastMask,
}

/// The policy with its parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Policy {
    pub no_forecast: NoForecast,
    pub last_mask_max_age: Duration,
}
