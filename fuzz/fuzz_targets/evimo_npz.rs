//! Arbitrary bytes as an EVIMO single `.npz` (a zip of `.npy` members: `events`, `mask`,
//! `depth` and the pickled `meta`), read through the zip/npy path: the events decoder and the
//! ground-truth reader return data or an error, never panic, hang or allocate without bound.
#![no_main]

use evgate_io::evimo::EvimoDecoder;
use evgate_io::EvimoRecording;
use evgate_io_fuzz::{drain, ground_truth_frames};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = evgate_io_fuzz::scratch::write("recording.npz", data);
    if let Ok(mut decoder) = EvimoDecoder::open(&path, None) {
        drain(&mut decoder);
    }
    if let Ok(recording) = EvimoRecording::open(&path) {
        ground_truth_frames(&recording);
    }
});
