//! The 16-byte event record shared by decoders, the simulator, shared memory and the gate.

use iceoryx2::prelude::ZeroCopySend;

/// Polarity of a brightness change: `1` = ON (brighter), `0` = OFF (darker).
pub type Polarity = u8;

/// The largest event time, in microseconds (2^60, about 36 600 years), that decoders deliver
/// and services accept; its negative is the smallest. Stream-time arithmetic (batch spans,
/// horizons, prediction ages) on times within it cannot overflow.
pub const MAX_EVENT_TIME_US: i64 = 1 << 60;

/// True when `t` lies within ±[`MAX_EVENT_TIME_US`].
#[inline]
pub const fn is_event_time(t: i64) -> bool {
    t.unsigned_abs() <= MAX_EVENT_TIME_US.unsigned_abs()
}

/// One event: time in microseconds, pixel coordinates, polarity.
///
/// The layout matches AEDAT4 / dv-processing (16 bytes, 8-byte aligned) so a slice of events can
/// be placed in shared memory and cast to bytes without copying.
#[repr(C)]
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    bytemuck::Pod,
    bytemuck::Zeroable,
    ZeroCopySend,
)]
#[type_name("evgate::Event/v1")]
pub struct Event {
    /// Timestamp in microseconds (stream time base; may be negative after an offset).
    pub t: i64,
    /// Column, 0 = left.
    pub x: u16,
    /// Row, 0 = top.
    pub y: u16,
    /// 1 = ON, 0 = OFF.
    pub polarity: Polarity,
    /// Keeps the record at 16 bytes with no implicit padding (required by `Pod`); always zero.
    pub reserved: [u8; 3],
}

impl Event {
    /// Builds an event; any non-zero `polarity` is stored as ON.
    pub const fn new(t: i64, x: u16, y: u16, polarity: bool) -> Self {
        Self {
            t,
            x,
            y,
            polarity: polarity as u8,
            reserved: [0; 3],
        }
    }

    /// True for an ON (brightness increase) event.
    pub const fn is_on(&self) -> bool {
        self.polarity != 0
    }

    /// +1.0 for ON, −1.0 for OFF: the value an event contributes to a voxel grid.
    pub fn signed_unit(&self) -> f32 {
        if self.is_on() {
            1.0
        } else {
            -1.0
        }
    }
}

const _: () = assert!(core::mem::size_of::<Event>() == 16);
const _: () = assert!(core::mem::align_of::<Event>() == 8);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_bytes_round_trip() {
        let events = [Event::new(-5, 1, 2, true), Event::new(7, 345, 259, false)];
        let bytes: &[u8] = bytemuck::cast_slice(&events);
        assert_eq!(bytes.len(), 32);
        let back: &[Event] = bytemuck::cast_slice(bytes);
        assert_eq!(back, &events);
    }

    #[test]
    fn polarity_maps_to_signed_unit() {
        assert_eq!(Event::new(0, 0, 0, true).signed_unit(), 1.0);
        assert_eq!(Event::new(0, 0, 0, false).signed_unit(), -1.0);
    }
}
