//! Arbitrary bytes decoded as Dat: the decoder must return events or an error, never panic,
//! hang or allocate without bound.
#![no_main]

use evgate_core::SensorSize;
use evgate_io::reader::from_bytes;
use evgate_io::Format;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // A size is given so inputs whose header lacks one still reach the event decoder.
    let sensor = Some(SensorSize::new(1280, 720));
    let Ok(mut reader) = from_bytes("fuzz-input", data.to_vec(), Format::Dat, sensor) else {
        return;
    };
    let mut chunk = Vec::new();
    while let Ok(count) = reader.read_chunk(&mut chunk) {
        if count == 0 {
            break;
        }
        assert!(chunk.iter().all(|event| reader.sensor_size().contains(event)));
    }
});
