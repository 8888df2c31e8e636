//! Arbitrary bytes read as a `.npy` array: an array or an error, never a panic or an
//! allocation the input does not back.
#![no_main]

use evgate_io::npy::NpyArray;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(array) = NpyArray::read(&mut &data[..]) {
        let _ = array.to_vec::<i64>();
        let _ = array.to_vec::<u8>();
    }
});
