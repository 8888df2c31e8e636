//! The newest valid forecast, copied out of shared memory so the sample is returned at once.

use evgate_core::{words_for, Forecast, ForecastView, GateError, MaskError, MaskView, SensorSize};
use evgate_ipc::{BatchHeader, ForecastError, ForecastHeader};

/// Why a received forecast was ignored.
#[derive(Debug, thiserror::Error)]
pub enum RejectedForecast {
    #[error("forecast {sequence}: {source}")]
    Header {
        sequence: u64,
        source: ForecastError,
    },
    #[error("forecast {sequence}: {source}")]
    Masks { sequence: u64, source: GateError },
    #[error("forecast {sequence}, current mask: {source}")]
    CurrentMask { sequence: u64, source: MaskError },
}

/// A validated forecast: the current mask and one mask per horizon.
pub struct StoredForecast {
    pub header: ForecastHeader,
    words: Vec<u64>,
}

impl StoredForecast {
    /// Copies a received forecast and validates the copy (so a publisher writing the shared
    /// memory afterwards cannot change what was checked).
    pub fn copy_from(header: ForecastHeader, payload: &[u64]) -> Result<Self, RejectedForecast> {
        let stored = Self {
            header,
            words: payload.to_vec(),
        };
        let sensor = stored.sensor();
        header
            .validate(words_for(sensor.pixels()), stored.words.len())
            .map_err(|source| RejectedForecast::Header {
                sequence: header.sequence,
                source,
            })?;
        stored.view().map_err(|source| RejectedForecast::Masks {
            sequence: header.sequence,
            source,
        })?;
        MaskView::new(sensor, header.mask_words(&stored.words, 0)).map_err(|source| {
            RejectedForecast::CurrentMask {
                sequence: header.sequence,
                source,
            }
        })?;
        Ok(stored)
    }

    /// Whether it was computed from this batch's stream and sensor.
    pub fn describes(&self, batch: &BatchHeader) -> bool {
        self.header.source_stream_id == batch.stream_id && self.sensor() == batch.sensor()
    }

    pub fn sensor(&self) -> SensorSize {
        SensorSize::new(self.header.width, self.header.height)
    }

    /// The horizon masks as evgate-core's gating kernel reads them.
    pub fn view(&self) -> Result<ForecastView<'_>, GateError> {
        let per_mask = self.header.words_per_mask as usize;
        ForecastView::new(
            self.header.reference_time_us,
            self.header.horizons(),
            self.sensor(),
            &self.words[per_mask..],
        )
    }

    /// The forecast as the judge reads it.
    pub fn forecast(&self) -> Forecast<'_> {
        Forecast {
            current: MaskView::new(self.sensor(), self.header.mask_words(&self.words, 0))
                .expect("validated when stored"),
            horizons: self.view().expect("validated when stored"),
        }
    }
}
