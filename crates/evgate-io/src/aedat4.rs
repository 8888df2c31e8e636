//! iniVation AEDAT 4.0: `#!AER-DAT4.0\r\n`, a 32-bit length and an `IOHE` FlatBuffer header
//! (compression, data-table position, XML stream description), then packets of a 32-bit stream
//! id, a 32-bit size and a (compressed) size-prefixed FlatBuffer. Only the packets of the event
//! stream (`typeIdentifier` `EVTS`) are decoded; IMU, trigger and frame packets are passed over
//! by stream id. Reading stops at the data table (the file's index), or at end of file when the
//! recording was not finalised.

use std::io::Read;

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::flatbuffer::Table;
use crate::format::Format;
use crate::source::ByteSource;
use crate::stream_decoder::{ChunkFormat, DecoderInput, StreamDecoder};

pub const MAGIC: &[u8; 14] = b"#!AER-DAT4.0\r\n";
/// A packet larger than this is taken for corruption rather than allocated.
const MAX_PACKET_BYTES: usize = 256 * 1024 * 1024;
/// A decompressed packet may hold at most this many bytes (4 M events; DV writes a few
/// thousand per packet)...
const MAX_DECOMPRESSED_BYTES: usize = 64 * 1024 * 1024;
/// ...and at most this many times its compressed size (event records compress 2-5×), except
/// that any packet may inflate to [`SMALL_PACKET_BYTES`]. Both bounds are applied while
/// inflating, so a few KB of zstd never become a GiB in memory.
const MAX_COMPRESSION_RATIO: usize = 100;
const SMALL_PACKET_BYTES: usize = 1024 * 1024;
const EVENT_BYTES: usize = 16;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Compression {
    None,
    Lz4,
    Zstd,
}

/// What the header says about the packets that follow, and the buffer they are decompressed
/// into.
pub struct Aedat4Packets {
    compression: Compression,
    event_stream: i32,
    /// Where the data table starts (packets end there); `None` when not finalised.
    data_end: Option<u64>,
    packet: Vec<u8>,
}

pub type Aedat4Decoder = StreamDecoder<Aedat4Packets>;

impl Aedat4Decoder {
    /// Reads the magic and header; `source` must be at the start of the file. `sensor_size`
    /// overrides the size in the stream description.
    pub fn new(
        mut source: ByteSource,
        sensor_size: Option<SensorSize>,
    ) -> Result<Self, DecodeError> {
        let magic = source
            .read_exact(MAGIC.len(), "the AEDAT 4 magic")?
            .to_vec();
        if magic != MAGIC {
            return Err(DecodeError::BadHeader {
                path: source.path().to_path_buf(),
                offset: 0,
                problem: format!(
                    "magic {:?} is not {:?}",
                    String::from_utf8_lossy(&magic),
                    "#!AER-DAT4.0\\r\\n"
                ),
            });
        }
        Self::after_magic(source, sensor_size)
    }

    /// Reads the header of an AEDAT 4 network stream (dv-processing's `NetworkWriter`, the DV
    /// runtime's network outputs): a file without its magic line and data table, so `source`
    /// starts at the header's length.
    pub fn network_stream(
        source: ByteSource,
        sensor_size: Option<SensorSize>,
    ) -> Result<Self, DecodeError> {
        Self::after_magic(source, sensor_size)
    }

    fn after_magic(
        mut source: ByteSource,
        sensor_size: Option<SensorSize>,
    ) -> Result<Self, DecodeError> {
        let path = source.path().to_path_buf();
        let bad = |offset: u64, problem: String| DecodeError::BadHeader {
            path: path.clone(),
            offset,
            problem,
        };
        let length_offset = source.offset();
        let length_bytes = source.read_exact(4, "the AEDAT 4 header length")?;
        let length = u32::from_le_bytes(length_bytes.try_into().expect("4 bytes")) as usize;
        if length > MAX_PACKET_BYTES {
            return Err(bad(
                length_offset,
                format!("header length {length} is implausible"),
            ));
        }
        let header_offset = source.offset();
        let header = source.read_exact(length, "the AEDAT 4 header")?.to_vec();
        let flatbuffer =
            |e: crate::flatbuffer::FlatbufferError| bad(header_offset + e.offset as u64, e.problem);
        let table = Table::root(&header, Some(b"IOHE")).map_err(flatbuffer)?;
        let compression = match table.i32_field(0, 0).map_err(flatbuffer)? {
            0 => Compression::None,
            1 | 2 => Compression::Lz4,
            3 | 4 => Compression::Zstd,
            other => {
                return Err(bad(
                    header_offset,
                    format!("compression {other} is unknown (accepted: 0 none, 1-2 LZ4, 3-4 ZSTD)"),
                ))
            }
        };
        let data_table = table.i64_field(1, -1).map_err(flatbuffer)?;
        let info = table.string_field(2).map_err(flatbuffer)?.ok_or_else(|| {
            bad(
                header_offset,
                "the header has no stream description (infoNode)".into(),
            )
        })?;
        let (event_stream, described_size) =
            event_stream(info).map_err(|problem| bad(header_offset, problem))?;
        let sensor_size = sensor_size.or(described_size).ok_or_else(|| {
            bad(
                header_offset,
                format!("event stream {event_stream} has no sizeX/sizeY; pass the sensor size"),
            )
        })?;
        Ok(Self::from_parts(
            source,
            sensor_size,
            Aedat4Packets {
                compression,
                event_stream,
                data_end: u64::try_from(data_table).ok().filter(|&p| p > 0),
                packet: Vec::new(),
            },
        ))
    }
}

impl ChunkFormat for Aedat4Packets {
    const FORMAT: Format = Format::Aedat4;

    /// Fills `out` with the events of the next event packet.
    fn decode_chunk(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
    ) -> Result<(), DecodeError> {
        while out.is_empty() {
            if self
                .data_end
                .is_some_and(|end| input.source.offset() >= end)
                || input.source.peek()?.is_none()
            {
                break;
            }
            let packet_offset = input.source.offset();
            let head = input.source.read_exact(8, "an AEDAT 4 packet header")?;
            let stream = i32::from_le_bytes(head[..4].try_into().expect("4 bytes"));
            let size = i32::from_le_bytes(head[4..].try_into().expect("4 bytes"));
            let size = usize::try_from(size)
                .ok()
                .filter(|&s| s <= MAX_PACKET_BYTES)
                .ok_or_else(|| {
                    input.malformed(packet_offset + 4, format!("packet size {size} is invalid"))
                })?;
            let body_offset = input.source.offset();
            let body = input.source.read_exact(size, "an AEDAT 4 packet")?;
            if stream != self.event_stream {
                continue;
            }
            let body = body.to_vec();
            self.decompress(input, &body, body_offset)?;
            self.decode_packet(input, out, body_offset)?;
        }
        Ok(())
    }
}

impl Aedat4Packets {
    fn decompress(
        &mut self,
        input: &DecoderInput,
        body: &[u8],
        offset: u64,
    ) -> Result<(), DecodeError> {
        inflate(self.compression, body, &mut self.packet)
            .map_err(|problem| input.malformed(offset, problem))
    }

    fn decode_packet(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
        offset: u64,
    ) -> Result<(), DecodeError> {
        let packet = std::mem::take(&mut self.packet);
        let decoded = (|| {
            // Size-prefixed: the FlatBuffer proper starts after its 32-bit length.
            let buffer = packet.get(4..).unwrap_or_default();
            let table = Table::root(buffer, Some(b"EVTS"))?;
            table.struct_vector(0, EVENT_BYTES)
        })();
        let elements = decoded
            .map_err(|e| input.malformed(offset, format!("event packet (decompressed) {e}")))?;
        for record in elements.unwrap_or_default().chunks_exact(EVENT_BYTES) {
            let event = Event::new(
                i64::from_le_bytes(record[..8].try_into().expect("8 bytes")),
                i16::from_le_bytes([record[8], record[9]]) as u16,
                i16::from_le_bytes([record[10], record[11]]) as u16,
                record[12] != 0,
            );
            // Packets are decompressed whole, so the best offset is the packet's.
            input.admission.admit(out, event, offset);
        }
        self.packet = packet;
        Ok(())
    }
}

/// The most bytes a packet of `compressed` bytes may inflate to.
fn decompressed_limit(compressed: usize) -> usize {
    compressed
        .saturating_mul(MAX_COMPRESSION_RATIO)
        .clamp(SMALL_PACKET_BYTES, MAX_DECOMPRESSED_BYTES)
}

/// Decompresses one packet body into `packet`, stopping as soon as it passes its limit.
fn inflate(compression: Compression, body: &[u8], packet: &mut Vec<u8>) -> Result<(), String> {
    packet.clear();
    let limit = decompressed_limit(body.len());
    // One byte past the limit tells a packet at the limit from one beyond it.
    let bounded = limit as u64 + 1;
    let result = match compression {
        Compression::None => {
            packet.extend_from_slice(body);
            Ok(0)
        }
        Compression::Lz4 => lz4_flex::frame::FrameDecoder::new(body)
            .take(bounded)
            .read_to_end(packet),
        Compression::Zstd => zstd::stream::read::Decoder::new(body)
            .and_then(|decoder| decoder.take(bounded).read_to_end(packet)),
    };
    result.map_err(|e| format!("event packet does not decompress ({compression:?}): {e}"))?;
    if packet.len() > limit {
        return Err(format!(
            "event packet of {} compressed bytes ({compression:?}) inflates past {limit} bytes \
             (limits: {MAX_COMPRESSION_RATIO}x its size, at least {SMALL_PACKET_BYTES} and at \
             most {MAX_DECOMPRESSED_BYTES} bytes); taken for corruption",
            body.len()
        ));
    }
    Ok(())
}

/// Finds the event stream in the XML description: its id and, when given, its size.
fn event_stream(info: &str) -> Result<(i32, Option<SensorSize>), String> {
    let mut streams: Vec<(i32, String)> = Vec::new();
    for node in info.split("<node ").skip(1) {
        let Some(path) = attribute(node, "path") else {
            continue;
        };
        let Some(rest) = path.split("/outInfo/").nth(1) else {
            continue;
        };
        let Ok(id) = rest.split('/').next().unwrap_or_default().parse::<i32>() else {
            continue;
        };
        match streams.iter_mut().find(|(known, _)| *known == id) {
            Some((_, text)) => text.push_str(node),
            None => streams.push((id, node.to_owned())),
        }
    }
    let (id, text) = streams
        .iter()
        .find(|(_, text)| value(text, "typeIdentifier").as_deref() == Some("EVTS"))
        .ok_or_else(|| {
            format!(
                "no event stream (typeIdentifier EVTS) among {} described streams",
                streams.len()
            )
        })?;
    let size = value(text, "sizeX")
        .zip(value(text, "sizeY"))
        .and_then(|(w, h)| Some(SensorSize::new(w.parse().ok()?, h.parse().ok()?)));
    Ok((*id, size))
}

fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let start = tag.find(&format!("{name}=\""))? + name.len() + 2;
    let len = tag[start..].find('"')?;
    Some(&tag[start..start + len])
}

/// The text of `<attr key="key" ...>text</attr>`.
fn value(text: &str, key: &str) -> Option<String> {
    let start = text.find(&format!("key=\"{key}\""))?;
    let open = start + text[start..].find('>')? + 1;
    let len = text[open..].find("</attr>")?;
    Some(text[open..open + len].trim().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    const INFO: &str = r#"<dv version="2.0">
    <node name="outInfo" path="/mainloop/Recorder/outInfo/">
        <node name="1" path="/mainloop/Recorder/outInfo/1/">
            <attr key="typeIdentifier" type="string">IMUS</attr>
        </node>
        <node name="3" path="/mainloop/Recorder/outInfo/3/">
            <attr key="typeIdentifier" type="string">EVTS</attr>
            <node name="info" path="/mainloop/Recorder/outInfo/3/info/">
                <attr key="sizeX" type="int">346</attr>
                <attr key="sizeY" type="int">260</attr>
            </node>
        </node>
    </node>
</dv>"#;

    /// Issue 15: a few KB of zstd inflated to 1 GiB before anything was checked.
    #[test]
    fn packets_that_inflate_past_their_limit_are_errors() {
        let zeros = vec![0u8; 64 * 1024 * 1024];
        let bomb = zstd::encode_all(zeros.as_slice(), 19).unwrap();
        assert!(bomb.len() < 64 * 1024, "{} bytes", bomb.len());
        let mut packet = Vec::new();
        let message = inflate(Compression::Zstd, &bomb, &mut packet).unwrap_err();
        assert!(message.contains("inflates past"), "{message}");
        // Inflating stopped at the limit instead of after the whole bomb.
        assert!(packet.len() <= SMALL_PACKET_BYTES + 1, "{}", packet.len());
        let lz4 = {
            let mut encoder = lz4_flex::frame::FrameEncoder::new(Vec::new());
            std::io::Write::write_all(&mut encoder, &zeros[..8 * 1024 * 1024]).unwrap();
            encoder.finish().unwrap()
        };
        assert!(inflate(Compression::Lz4, &lz4, &mut packet).is_err());
        // A packet within the limits inflates whole.
        let events: Vec<u8> = (0..200_000u32).flat_map(|i| i.to_le_bytes()).collect();
        let fine = zstd::encode_all(events.as_slice(), 3).unwrap();
        inflate(Compression::Zstd, &fine, &mut packet).unwrap();
        assert_eq!(packet, events);
    }

    #[test]
    fn event_stream_and_size_come_from_the_description() {
        assert_eq!(
            event_stream(INFO).unwrap(),
            (3, Some(SensorSize::new(346, 260)))
        );
        let err = event_stream(&INFO.replace("EVTS", "FRME")).unwrap_err();
        assert!(err.contains("no event stream"), "{err}");
    }
}
