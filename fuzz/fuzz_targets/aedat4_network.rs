//! Arbitrary bytes read as a peer's AEDAT 4 network stream (header, then packets): the decoder
//! must return events or an error, never panic, hang or allocate without bound. The peer of
//! `evgate-ingest --input tcp://…` is as untrusted as a file.
#![no_main]

use evgate_io::network::Endpoint;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let endpoint = Endpoint::Tcp {
        address: "fuzz:1".to_owned(),
    };
    let stream = Box::new(std::io::Cursor::new(data.to_vec()));
    if let Ok(mut decoder) = endpoint.decoder(stream, None) {
        evgate_io_fuzz::drain(&mut decoder);
    }
});
