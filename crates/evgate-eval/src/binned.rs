//! Frame scores pooled into bins of a per-frame quantity (events per window, object speed).

use serde::{Deserialize, Serialize};

use crate::summary::Mean;

/// The events-per-window plot spans 10² to 10⁶ events, as the paper's.
pub const EVENT_BINS_FIRST_DECADE: u32 = 2;
pub const EVENT_BINS_LAST_DECADE: u32 = 6;

/// One bin's pooled mean.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct BinValue {
    pub label: String,
    /// Lower and upper bound of the binned quantity (None = unbounded).
    pub lower: Option<f64>,
    pub upper: Option<f64>,
    pub frames: u64,
    pub mean_iou: Option<f64>,
}

/// Logarithmic bins of events per window from 10^`first_decade` to 10^`last_decade`.
#[derive(Clone, Debug, PartialEq)]
pub struct LogBins {
    pub first_decade: u32,
    pub last_decade: u32,
    pub per_decade: u32,
}

impl LogBins {
    pub fn count(&self) -> usize {
        ((self.last_decade - self.first_decade) * self.per_decade) as usize
    }

    /// Bin of `value`, `None` outside [10^first, 10^last).
    pub fn bin(&self, value: f64) -> Option<usize> {
        if value.is_nan() || value <= 0.0 {
            return None;
        }
        let position = (value.log10() - f64::from(self.first_decade)) * f64::from(self.per_decade);
        (position >= 0.0 && position < self.count() as f64).then(|| position.floor() as usize)
    }

    pub fn bounds(&self, bin: usize) -> (f64, f64) {
        let exponent =
            |k: usize| f64::from(self.first_decade) + k as f64 / f64::from(self.per_decade);
        (10f64.powf(exponent(bin)), 10f64.powf(exponent(bin + 1)))
    }

    /// Geometric centre of a bin, where its point is plotted.
    pub fn centre(&self, bin: usize) -> f64 {
        let (lower, upper) = self.bounds(bin);
        (lower * upper).sqrt()
    }
}

/// Pooled means per bin for one method.
#[derive(Clone, Debug, PartialEq)]
pub struct BinnedMeans {
    pub bins: Vec<Mean>,
}

impl BinnedMeans {
    pub fn new(count: usize) -> Self {
        Self {
            bins: vec![Mean::default(); count],
        }
    }

    pub fn add(&mut self, bin: usize, value: Option<f64>) {
        if let Some(slot) = self.bins.get_mut(bin) {
            slot.add(value);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_bins_cover_decades() {
        let bins = LogBins {
            first_decade: 2,
            last_decade: 6,
            per_decade: 2,
        };
        assert_eq!(bins.count(), 8);
        assert_eq!(bins.bin(99.0), None);
        assert_eq!(bins.bin(100.0), Some(0));
        assert_eq!(bins.bin(400.0), Some(1));
        assert_eq!(bins.bin(999_999.0), Some(7));
        assert_eq!(bins.bin(1e6), None);
        let (lower, upper) = bins.bounds(0);
        assert!((lower - 100.0).abs() < 1e-9 && (upper - 316.227766).abs() < 1e-3);
    }
}
