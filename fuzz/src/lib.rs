//! The one property every decoder fuzz target checks: arbitrary bytes decode to events inside
//! the sensor or to an error — never a panic, a hang or unbounded allocation.

use evgate_core::SensorSize;
use evgate_io::reader::from_bytes;
use evgate_io::Format;

/// Decodes `data` as `format` to the end or to the first error.
pub fn decode_arbitrary_bytes(data: &[u8], format: Format) {
    // A size is given so inputs whose header lacks one still reach the event decoder.
    let sensor = Some(SensorSize::new(1280, 720));
    let Ok(mut reader) = from_bytes("fuzz-input", data.to_vec(), format, sensor) else {
        return;
    };
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
