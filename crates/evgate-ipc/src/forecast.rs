//! The user header of the forecast stream and the layout of its mask words.

use evgate_core::{is_event_time, MAX_EVENT_TIME_US};
use iceoryx2::prelude::ZeroCopySend;

/// Most horizons one forecast carries.
pub const MAX_HORIZONS: usize = 8;

/// The longest horizon a forecast may carry, microseconds (a minute; the network's is 100 ms).
pub const MAX_HORIZON_US: i64 = 60_000_000;

/// A forecast that does not describe its payload.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ForecastError {
    #[error("forecast header field horizon-count = {value} is out of range: accepted 1..={MAX_HORIZONS}")]
    HorizonCount { value: u32 },
    #[error("forecast header field horizons-us[{index}] = {value} is out of range: accepted 0..={MAX_HORIZON_US}")]
    HorizonRange { index: usize, value: i64 },
    #[error("forecast header field horizons-us[{index}] = {value} must be above horizons-us[{previous}]")]
    HorizonOrder {
        index: usize,
        previous: usize,
        value: i64,
    },
    #[error("forecast header field {field} = {value} is out of range: accepted -{MAX_EVENT_TIME_US}..={MAX_EVENT_TIME_US}")]
    Time { field: &'static str, value: i64 },
    #[error("forecast header field source-stream-id = 0: a forecast names the stream it was computed from")]
    NoSourceStream,
    #[error("forecast header field words-per-mask = {value} does not match a {width}x{height} mask (expected {expected})")]
    WordsPerMask {
        value: u32,
        width: u16,
        height: u16,
        expected: usize,
    },
    #[error("forecast payload has {actual} words, the header announces (1 + {horizon_count}) masks x {words_per_mask} words = {expected}")]
    PayloadLength {
        actual: usize,
        horizon_count: u32,
        words_per_mask: u32,
        expected: usize,
    },
}

/// Describes one forecast: the payload is `1 + horizon_count` bit-packed masks of
/// `words_per_mask` `u64` words each (evgate-core's `BitMask` layout: row-major bits), first the
/// mask at `reference_time_us`, then one per horizon, in the order of `horizons_us`.
#[repr(C)]
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable, ZeroCopySend,
)]
#[type_name("evgate::ForecastHeader/v1")]
pub struct ForecastHeader {
    /// Forecast number from 0 for one inference process.
    pub sequence: u64,
    /// Hash identifying the model file (so stats and logs can tell models apart).
    pub model_id: u64,
    /// `stream_id` of the event stream the forecast was computed from.
    pub source_stream_id: u64,
    /// The time t the forecast refers to (end of the input window), microseconds.
    pub reference_time_us: i64,
    /// Start of the input window, microseconds.
    pub window_start_us: i64,
    /// Horizons Δt after `reference_time_us`, microseconds, strictly increasing, in
    /// `0..=MAX_HORIZON_US`; only the first `horizon_count` are meaningful.
    pub horizons_us: [i64; MAX_HORIZONS],
    /// Time the model took for this forecast, microseconds.
    pub model_runtime_us: u64,
    /// Wall-clock publication time, microseconds since the Unix epoch.
    pub published_at_wall_us: i64,
    /// CLOCK_MONOTONIC publication time, microseconds (see [`crate::clock::monotonic_us`]).
    pub published_at_monotonic_us: u64,
    pub width: u16,
    pub height: u16,
    /// Number K of horizon masks after the current mask.
    pub horizon_count: u32,
    /// `u64` words per mask.
    pub words_per_mask: u32,
    /// Keeps the header free of implicit padding; always zero.
    pub reserved: u32,
}

const _: () = assert!(core::mem::size_of::<ForecastHeader>() == 144);

impl ForecastHeader {
    /// Number of masks in the payload: the current one plus one per horizon.
    pub const fn mask_count(&self) -> usize {
        1 + self.horizon_count as usize
    }

    /// The meaningful horizons.
    pub fn horizons(&self) -> &[i64] {
        &self.horizons_us[..(self.horizon_count as usize).min(MAX_HORIZONS)]
    }

    /// Payload length in words the header announces.
    pub const fn payload_words(&self) -> usize {
        self.mask_count() * self.words_per_mask as usize
    }

    /// Checks that the header is self-consistent, that `words_per_mask` is the word count of a
    /// `BitMask` of its size (`expected_words_per_mask`) and that the payload has that many words.
    ///
    /// Validate a copy, never the header in shared memory: its publisher can still write it.
    pub fn validate(
        &self,
        expected_words_per_mask: usize,
        payload_words: usize,
    ) -> Result<(), ForecastError> {
        if self.horizon_count == 0 || self.horizon_count as usize > MAX_HORIZONS {
            return Err(ForecastError::HorizonCount {
                value: self.horizon_count,
            });
        }
        if self.source_stream_id == 0 {
            return Err(ForecastError::NoSourceStream);
        }
        for (field, value) in [
            ("reference-time-us", self.reference_time_us),
            ("window-start-us", self.window_start_us),
        ] {
            if !is_event_time(value) {
                return Err(ForecastError::Time { field, value });
            }
        }
        let horizons = self.horizons();
        if let Some(index) = horizons
            .iter()
            .position(|horizon| !(0..=MAX_HORIZON_US).contains(horizon))
        {
            return Err(ForecastError::HorizonRange {
                index,
                value: horizons[index],
            });
        }
        for index in 1..horizons.len() {
            if horizons[index] <= horizons[index - 1] {
                return Err(ForecastError::HorizonOrder {
                    index,
                    previous: index - 1,
                    value: horizons[index],
                });
            }
        }
        if self.words_per_mask as usize != expected_words_per_mask {
            return Err(ForecastError::WordsPerMask {
                value: self.words_per_mask,
                width: self.width,
                height: self.height,
                expected: expected_words_per_mask,
            });
        }
        if payload_words != self.payload_words() {
            return Err(ForecastError::PayloadLength {
                actual: payload_words,
                horizon_count: self.horizon_count,
                words_per_mask: self.words_per_mask,
                expected: self.payload_words(),
            });
        }
        Ok(())
    }

    /// The words of mask `index` (0 = current, k = horizon k − 1) within a validated payload.
    pub fn mask_words<'a>(&self, payload: &'a [u64], index: usize) -> &'a [u64] {
        let words = self.words_per_mask as usize;
        &payload[index * words..(index + 1) * words]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(horizons: &[i64], words_per_mask: u32) -> ForecastHeader {
        let mut header = ForecastHeader {
            source_stream_id: 9,
            horizon_count: horizons.len() as u32,
            words_per_mask,
            width: 8,
            height: 8,
            ..Default::default()
        };
        header.horizons_us[..horizons.len()].copy_from_slice(horizons);
        header
    }

    #[test]
    fn valid_forecast_splits_into_masks() {
        let header = header(&[10_000, 20_000], 1);
        header.validate(1, 3).unwrap();
        let payload = [1u64, 2, 3];
        assert_eq!(header.mask_words(&payload, 0), &[1]);
        assert_eq!(header.mask_words(&payload, 2), &[3]);
        assert_eq!(header.horizons(), &[10_000, 20_000]);
    }

    #[test]
    fn rejects_inconsistent_headers() {
        assert_eq!(
            header(&[], 1).validate(1, 1),
            Err(ForecastError::HorizonCount { value: 0 })
        );
        assert!(matches!(
            header(&[20, 10], 1).validate(1, 3),
            Err(ForecastError::HorizonOrder { index: 1, .. })
        ));
        assert!(matches!(
            header(&[10], 2).validate(1, 4),
            Err(ForecastError::WordsPerMask { .. })
        ));
        assert!(matches!(
            header(&[10], 1).validate(1, 3),
            Err(ForecastError::PayloadLength { expected: 2, .. })
        ));
    }

    /// Issue 15: equal horizons passed here but failed the gate's view, so every forecast was
    /// dropped silently; extreme times and stream id 0 were accepted.
    #[test]
    fn rejects_what_the_gate_could_not_use() {
        assert!(matches!(
            header(&[10, 10], 1).validate(1, 3),
            Err(ForecastError::HorizonOrder { index: 1, .. })
        ));
        assert!(matches!(
            header(&[-1], 1).validate(1, 2),
            Err(ForecastError::HorizonRange { index: 0, .. })
        ));
        assert!(matches!(
            header(&[MAX_HORIZON_US + 1], 1).validate(1, 2),
            Err(ForecastError::HorizonRange { index: 0, .. })
        ));
        let mut extreme = header(&[10], 1);
        extreme.reference_time_us = i64::MIN;
        assert_eq!(
            extreme.validate(1, 2),
            Err(ForecastError::Time {
                field: "reference-time-us",
                value: i64::MIN
            })
        );
        let mut anonymous = header(&[10], 1);
        anonymous.source_stream_id = 0;
        assert_eq!(anonymous.validate(1, 2), Err(ForecastError::NoSourceStream));
    }
}
