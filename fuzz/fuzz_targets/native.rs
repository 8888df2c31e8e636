//! Arbitrary bytes decoded as Native: the decoder must return events or an error, never panic,
//! hang or allocate without bound.
#![no_main]

use evgate_io::Format;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| evgate_io_fuzz::decode_arbitrary_bytes(data, Format::Native));
