//! The fuzz targets' property in the ordinary test suite: any bytes, in any format, give events
//! on the sensor or an error, never a panic.

use evgate_core::SensorSize;
use evgate_io::reader::from_bytes;
use evgate_io::Format;
use proptest::prelude::*;

const FORMATS: [Format; 6] = [
    Format::Evt2,
    Format::Evt3,
    Format::Dat,
    Format::Aedat4,
    Format::Csv,
    Format::Native,
];

fn drain(bytes: Vec<u8>, format: Format) {
    let sensor = SensorSize::new(1280, 720);
    let Ok(mut reader) = from_bytes("arbitrary", bytes, format, Some(sensor)) else {
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

/// A real file's opening with a few bytes overwritten: gets past the magic and header checks.
fn mutated(real: &'static [u8]) -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec((0..real.len(), any::<u8>()), 0..16).prop_map(move |edits| {
        let mut bytes = real.to_vec();
        for (at, value) in edits {
            bytes[at] = value;
        }
        bytes
    })
}

fn real_prefix(name: &str, len: usize) -> &'static [u8] {
    let path = format!(
        "{}/../../../shared/data/real/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    Box::leak(bytes[..len.min(bytes.len())].to_vec().into_boxed_slice())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn random_bytes_never_panic_the_metadata_readers(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = evgate_io::pickle::read_pickle(&bytes);
        let _ = evgate_io::pyvalue::parse_literal(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2048), which in 0..6usize) {
        drain(bytes, FORMATS[which]);
    }

    #[test]
    fn mutated_evt3_never_panics(bytes in mutated(real_prefix("evt3_sample.raw", 2048))) {
        drain(bytes, Format::Evt3);
    }

    #[test]
    fn mutated_aedat4_never_panics(bytes in mutated(real_prefix("sample.aedat4", 12_000))) {
        drain(bytes, Format::Aedat4);
    }
}
