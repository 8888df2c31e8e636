//! Arbitrary bytes as the three `.npy` event arrays of an EVIMO2 v2 sequence folder
//! (`dataset_events_t.npy`, `_xy.npy`, `_p.npy`), split by `evgate_io_fuzz::split_three`: the
//! decoder returns events on the sensor or an error, never panics, hangs or allocates without
//! bound.
#![no_main]

use evgate_core::SensorSize;
use evgate_io::evimo2_events::{
    Evimo2EventsDecoder, COORDINATES_FILE, POLARITIES_FILE, TIMES_FILE,
};
use evgate_io_fuzz::{drain, scratch, split_three};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [times, coordinates, polarities] = split_three(data);
    scratch::write(TIMES_FILE, times);
    scratch::write(COORDINATES_FILE, coordinates);
    scratch::write(POLARITIES_FILE, polarities);
    if let Ok(mut decoder) =
        Evimo2EventsDecoder::open(&scratch::folder(), SensorSize::new(640, 480))
    {
        drain(&mut decoder);
    }
});
