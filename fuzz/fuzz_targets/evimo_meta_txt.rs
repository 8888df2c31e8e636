//! Arbitrary bytes as the `meta.txt` (a Python literal) of an EVIMO text folder: the literal
//! parser and the metadata checks return a recording or an error, never panic, hang or
//! allocate without bound.
#![no_main]

use evgate_io::pyvalue::parse_literal;
use evgate_io::EvimoRecording;
use evgate_io_fuzz::ground_truth_frames;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = parse_literal(text).map(|value| value.find_dict_with_key("frames").is_some());
    }
    let meta = evgate_io_fuzz::scratch::write("meta.txt", data);
    let folder = meta.parent().expect("a scratch file has a folder");
    if let Ok(recording) = EvimoRecording::open(folder) {
        ground_truth_frames(&recording);
    }
});
