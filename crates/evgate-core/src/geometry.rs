//! Sensor geometry: the pixel grid events live on.

use serde::{Deserialize, Serialize};

use crate::event::Event;

/// Width and height of a sensor in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SensorSize {
    pub width: u16,
    pub height: u16,
}

impl SensorSize {
    pub const fn new(width: u16, height: u16) -> Self {
        Self { width, height }
    }

    /// Number of pixels.
    pub const fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// True when the event's coordinates lie on the sensor.
    pub const fn contains(&self, event: &Event) -> bool {
        event.x < self.width && event.y < self.height
    }

    /// Row-major index of a pixel that lies on the sensor.
    pub const fn index(&self, x: u16, y: u16) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// The size of this sensor binned `factor`×`factor` (a partial last column or row of
    /// pixels makes a cell of its own); `factor` must not be 0.
    pub const fn binned(&self, factor: u16) -> SensorSize {
        SensorSize {
            width: self.width.div_ceil(factor),
            height: self.height.div_ceil(factor),
        }
    }

    /// The smallest size whose sides are multiples of `multiple` and at least this size
    /// (the network's encoder halves the resolution four times, so it needs multiples of 16);
    /// `None` where a side would pass 65 535.
    pub const fn padded_to(&self, multiple: u16) -> Option<SensorSize> {
        let (Some(width), Some(height)) = (
            self.width.div_ceil(multiple).checked_mul(multiple),
            self.height.div_ceil(multiple).checked_mul(multiple),
        ) else {
            return None;
        };
        Some(SensorSize { width, height })
    }
}

impl std::fmt::Display for SensorSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_rounds_up_to_multiple() {
        assert_eq!(
            SensorSize::new(346, 260).padded_to(16),
            Some(SensorSize::new(352, 272))
        );
        assert_eq!(
            SensorSize::new(640, 480).padded_to(16),
            Some(SensorSize::new(640, 480))
        );
    }

    /// A text file without geometry reads as 65535 × 65535, which used to pad to 0 × 0.
    #[test]
    fn padding_past_the_largest_side_is_none() {
        assert_eq!(SensorSize::new(u16::MAX, u16::MAX).padded_to(16), None);
        assert_eq!(SensorSize::new(65_521, 8).padded_to(16), None);
        assert_eq!(
            SensorSize::new(65_520, 1).padded_to(16),
            Some(SensorSize::new(65_520, 16))
        );
    }

    #[test]
    fn binning_rounds_partial_cells_up() {
        assert_eq!(
            SensorSize::new(1280, 720).binned(2),
            SensorSize::new(640, 360)
        );
        assert_eq!(
            SensorSize::new(346, 260).binned(3),
            SensorSize::new(116, 87)
        );
        assert_eq!(SensorSize::new(5, 7).binned(1), SensorSize::new(5, 7));
    }

    #[test]
    fn contains_checks_both_axes() {
        let s = SensorSize::new(4, 3);
        assert!(s.contains(&Event::new(0, 3, 2, true)));
        assert!(!s.contains(&Event::new(0, 4, 0, true)));
        assert!(!s.contains(&Event::new(0, 0, 3, true)));
    }
}
