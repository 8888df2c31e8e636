//! Arbitrary bytes as the pickle inside an EVIMO `.npz`'s `meta` object array (NumPy's
//! `np.savez(meta=dict)`): the pickle reader and the metadata checks of the single-`.npz`
//! layout return a recording or an error, never panic, hang or allocate without bound.
#![no_main]

use evgate_io::npy::{DType, NpyArray};
use evgate_io::npz::{NpzCompression, NpzWriter};
use evgate_io::pickle::read_pickle;
use evgate_io::EvimoRecording;
use evgate_io_fuzz::ground_truth_frames;
use libfuzzer_sys::fuzz_target;

/// The mask stack the metadata is checked against: 2 frames of 12x8.
const FRAMES: usize = 2;
const HEIGHT: usize = 8;
const WIDTH: usize = 12;

fn recording_with_meta(pickle: &[u8]) -> Vec<u8> {
    let mut npz = NpzWriter::new(
        "fuzz-input.npz".into(),
        std::io::Cursor::new(Vec::new()),
        NpzCompression::Stored,
    );
    let events = [0.001, 1.0, 2.0, 1.0, 0.002, 3.0, 4.0, 0.0];
    npz.add("events", &[2, 4], &events).expect("in memory");
    let stack = vec![1000u16; FRAMES * HEIGHT * WIDTH];
    npz.add("mask", &[FRAMES, HEIGHT, WIDTH], &stack)
        .expect("in memory");
    npz.add("depth", &[FRAMES, HEIGHT, WIDTH], &stack)
        .expect("in memory");
    let meta = NpyArray {
        dtype: DType::Object,
        shape: vec![],
        data: pickle.to_vec(),
    };
    npz.add_array("meta", &meta).expect("in memory");
    npz.finish().expect("in memory").into_inner()
}

fuzz_target!(|data: &[u8]| {
    let _ = read_pickle(data).map(|value| value.find_dict_with_key("frames").is_some());
    let path = evgate_io_fuzz::scratch::write("meta.npz", &recording_with_meta(data));
    if let Ok(recording) = EvimoRecording::open(&path) {
        ground_truth_frames(&recording);
    }
});
