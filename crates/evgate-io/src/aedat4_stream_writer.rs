//! The writing side of an AEDAT 4 network stream ([`crate::network`]): the size-prefixed
//! `IOHE` header that describes one uncompressed event stream (id 0), and size-prefixed `EVTS`
//! packets behind their 32-bit stream id and size, as DV tools and dv-processing's
//! `NetworkReader` read them. Offsets keep every scalar aligned to its size from the start of
//! the size-prefixed buffer, as FlatBuffers verifiers require.

use evgate_core::{Event, SensorSize};

/// The stream id the header gives the event stream.
pub const EVENT_STREAM_ID: i32 = 0;
const EVENT_BYTES: usize = 16;

/// The stream header for a `sensor`-sized event stream named `source` (the camera name DV
/// shows).
pub fn stream_header(sensor: SensorSize, source: &str) -> Vec<u8> {
    let info = format!(
        "<dv version=\"2.0\">\n    <node name=\"outInfo\" path=\"/outInfo/\">\n        \
         <node name=\"{EVENT_STREAM_ID}\" path=\"/outInfo/{EVENT_STREAM_ID}/\">\n            \
         <attr key=\"compression\" type=\"string\">NONE</attr>\n            \
         <attr key=\"originalModuleName\" type=\"string\">evgate</attr>\n            \
         <attr key=\"originalOutputName\" type=\"string\">events</attr>\n            \
         <attr key=\"typeIdentifier\" type=\"string\">EVTS</attr>\n            \
         <node name=\"info\" path=\"/outInfo/{EVENT_STREAM_ID}/info/\">\n                \
         <attr key=\"sizeX\" type=\"int\">{}</attr>\n                \
         <attr key=\"sizeY\" type=\"int\">{}</attr>\n                \
         <attr key=\"source\" type=\"string\">{}</attr>\n            \
         </node>\n        </node>\n    </node>\n</dv>\n",
        sensor.width,
        sensor.height,
        escape_xml(source)
    );
    let mut buffer = Vec::with_capacity(48 + info.len());
    // Size prefix (filled in last), root offset, identifier.
    buffer.extend_from_slice(&[0; 4]);
    put_u32(&mut buffer, 24 - 4);
    buffer.extend_from_slice(b"IOHE");
    // The vtable at 12: its size, the table's size, then the offset of each of the 3 fields.
    for half in [10u16, 20, 4, 8, 16] {
        buffer.extend_from_slice(&half.to_le_bytes());
    }
    buffer.extend_from_slice(&[0; 2]);
    // The table at 24: back to its vtable, compression NONE, no data table, the description.
    buffer.extend_from_slice(&(24i32 - 12).to_le_bytes());
    buffer.extend_from_slice(&0i32.to_le_bytes());
    buffer.extend_from_slice(&(-1i64).to_le_bytes());
    put_u32(&mut buffer, 44 - 40);
    put_u32(&mut buffer, info.len() as u32);
    buffer.extend_from_slice(info.as_bytes());
    buffer.push(0);
    finish(buffer)
}

/// Appends one packet of `events` to `out`: stream id, size, and the size-prefixed buffer.
pub fn push_event_packet(events: &[Event], out: &mut Vec<u8>) {
    let mut buffer = Vec::with_capacity(32 + events.len() * EVENT_BYTES);
    buffer.extend_from_slice(&[0; 4]);
    put_u32(&mut buffer, 20 - 4);
    buffer.extend_from_slice(b"EVTS");
    // The vtable at 12: one field.
    for half in [6u16, 8, 4] {
        buffer.extend_from_slice(&half.to_le_bytes());
    }
    buffer.extend_from_slice(&[0; 2]);
    // The table at 20, its vector of events at 28 so that the elements start 8-aligned at 32.
    buffer.extend_from_slice(&(20i32 - 12).to_le_bytes());
    put_u32(&mut buffer, 28 - 24);
    put_u32(&mut buffer, events.len() as u32);
    for event in events {
        buffer.extend_from_slice(&event.t.to_le_bytes());
        buffer.extend_from_slice(&(event.x as i16).to_le_bytes());
        buffer.extend_from_slice(&(event.y as i16).to_le_bytes());
        buffer.extend_from_slice(&[u8::from(event.is_on()), 0, 0, 0]);
    }
    let buffer = finish(buffer);
    out.extend_from_slice(&EVENT_STREAM_ID.to_le_bytes());
    out.extend_from_slice(&(buffer.len() as i32).to_le_bytes());
    out.extend_from_slice(&buffer);
}

fn put_u32(buffer: &mut Vec<u8>, value: u32) {
    buffer.extend_from_slice(&value.to_le_bytes());
}

/// Pads to 8 bytes and writes the size prefix (the length after it).
fn finish(mut buffer: Vec<u8>) -> Vec<u8> {
    buffer.resize(buffer.len().next_multiple_of(8), 0);
    let size = (buffer.len() - 4) as u32;
    buffer[..4].copy_from_slice(&size.to_le_bytes());
    buffer
}

fn escape_xml(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Endpoint;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn what_is_written_decodes_to_the_same_events(
            packets in prop::collection::vec(
                prop::collection::vec((0i64..1_000_000, 0u16..640, 0u16..480, any::<bool>()), 0..50),
                1..6,
            ),
        ) {
            let sensor = SensorSize::new(640, 480);
            let mut stream = stream_header(sensor, "evgate <test> & co");
            let mut t_offset = 0;
            let mut expected = Vec::new();
            for packet in &packets {
                let mut events: Vec<Event> = packet
                    .iter()
                    .map(|&(t, x, y, on)| Event::new(t + t_offset, x, y, on))
                    .collect();
                events.sort_by_key(|event| event.t);
                t_offset += 1_000_000;
                push_event_packet(&events, &mut stream);
                expected.extend(events);
            }
            let endpoint = Endpoint::Tcp { address: "test:1".into() };
            let mut decoder = endpoint
                .decoder(Box::new(std::io::Cursor::new(stream)), None)
                .unwrap();
            prop_assert_eq!(decoder.sensor_size(), sensor);
            let (mut decoded, mut chunk) = (Vec::new(), Vec::new());
            while decoder.read_chunk(&mut chunk).unwrap() > 0 {
                decoded.extend_from_slice(&chunk);
            }
            prop_assert_eq!(decoded, expected);
        }
    }
}
