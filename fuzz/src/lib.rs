//! The one property every decoder fuzz target checks: arbitrary bytes decode to events inside
//! the sensor or to an error — never a panic, a hang or unbounded allocation.

pub mod scratch;

use evgate_core::SensorSize;
use evgate_io::reader::from_bytes;
use evgate_io::{EventReader, EvimoRecording, Format};

/// Decodes `data` as `format` to the end or to the first error.
pub fn decode_arbitrary_bytes(data: &[u8], format: Format) {
    // A size is given so inputs whose header lacks one still reach the event decoder.
    let sensor = Some(SensorSize::new(1280, 720));
    let Ok(mut reader) = from_bytes("fuzz-input", data.to_vec(), format, sensor) else {
        return;
    };
    drain(reader.as_mut());
}

/// Reads `reader` to the end or to the first error, checking every event lies on its sensor.
pub fn drain(reader: &mut dyn EventReader) {
    let mut chunk = Vec::new();
    while let Ok(count) = reader.read_chunk(&mut chunk) {
        if count == 0 {
            break;
        }
        assert!(chunk
            .iter()
            .all(|event| reader.sensor_size().contains(event)));
    }
}

/// Streams the events and every ground-truth frame of `recording` to the end or to the first
/// error, checking each frame covers the sensor.
pub fn ground_truth_frames(recording: &EvimoRecording) {
    if let Ok(mut events) = recording.events() {
        drain(events.as_mut());
    }
    let Ok(frames) = recording.frames() else {
        return;
    };
    let pixels = recording.sensor_size().pixels();
    for frame in frames {
        let Ok(frame) = frame else {
            return;
        };
        assert_eq!(frame.mask.len(), pixels);
        assert!(frame.depth.is_none_or(|depth| depth.len() == pixels));
    }
}

/// Splits one input into three files: two little-endian `u16` lengths (of the first and the
/// second), then the bytes of the first, the second and (the rest) the third.
pub fn split_three(data: &[u8]) -> [&[u8]; 3] {
    let length = |at: usize| {
        data.get(at..at + 2)
            .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]) as usize)
    };
    let (first, second) = (length(0), length(2));
    let rest = data.get(4..).unwrap_or_default();
    let (a, rest) = rest.split_at(first.min(rest.len()));
    let (b, c) = rest.split_at(second.min(rest.len()));
    [a, b, c]
}
