//! The ASCII header of Prophesee RAW and DAT files: lines starting with `%`, optionally closed
//! by `% end`.

use std::collections::BTreeMap;

use evgate_core::SensorSize;

use crate::error::DecodeError;
use crate::source::ByteSource;

/// Header lines longer than this are not a header.
const MAX_HEADER_LINE: usize = 64 * 1024;

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PropheseeHeader {
    /// `% key value` lines, keys lower-cased (a repeated key keeps its last value).
    pub fields: BTreeMap<String, String>,
}

impl PropheseeHeader {
    /// Reads all `%` lines, leaving the source at the first data byte.
    pub fn read(source: &mut ByteSource) -> Result<Self, DecodeError> {
        let mut fields = BTreeMap::new();
        let mut line = Vec::new();
        while source.peek()? == Some(b'%') {
            let Some(offset) = source.read_line(MAX_HEADER_LINE, &mut line)? else {
                break;
            };
            let text = std::str::from_utf8(&line).map_err(|_| DecodeError::BadHeader {
                path: source.path().to_path_buf(),
                offset,
                problem: "header line is not UTF-8 text".into(),
            })?;
            let text = text.trim_start_matches('%').trim();
            if text == "end" {
                break;
            }
            let (key, value) = text.split_once(char::is_whitespace).unwrap_or((text, ""));
            fields.insert(key.to_ascii_lowercase(), value.trim().to_owned());
        }
        Ok(Self { fields })
    }

    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.get(key).map(String::as_str)
    }

    /// The declared event format: `2.0`, `3.0` (from `% evt 3.0` or `% format EVT3;...`).
    pub fn evt_version(&self) -> Option<String> {
        if let Some(version) = self.get("evt") {
            return Some(version.to_owned());
        }
        let format = self.get("format")?;
        let name = format.split(';').next()?.trim().to_ascii_uppercase();
        match name.as_str() {
            "EVT2" => Some("2.0".into()),
            "EVT21" => Some("2.1".into()),
            "EVT3" => Some("3.0".into()),
            _ => Some(name),
        }
    }

    /// The sensor size from `% format ...;width=W;height=H`, `% geometry WxH`, `% width W` +
    /// `% height H`, or, when none is given (older recordings), from the camera plugin name.
    pub fn sensor_size(&self) -> Option<SensorSize> {
        self.format_geometry()
            .or_else(|| self.get("geometry").and_then(parse_geometry))
            .or_else(|| {
                let width = self.get("width")?.parse().ok()?;
                let height = self.get("height")?.parse().ok()?;
                Some(SensorSize::new(width, height))
            })
            .or_else(|| self.get("plugin_name").and_then(sensor_of_plugin))
            .filter(|size| size.width > 0 && size.height > 0)
    }

    fn format_geometry(&self) -> Option<SensorSize> {
        let format = self.get("format")?;
        let (mut width, mut height) = (None, None);
        for option in format.split(';').skip(1) {
            match option.split_once('=') {
                Some(("width", value)) => width = value.trim().parse().ok(),
                Some(("height", value)) => height = value.trim().parse().ok(),
                _ => {}
            }
        }
        Some(SensorSize::new(width?, height?))
    }
}

/// Parses the `WxH` notation (`640x480`) used by `% geometry` and the command line.
pub fn parse_geometry(text: &str) -> Option<SensorSize> {
    let (width, height) = text.split_once('x')?;
    Some(SensorSize::new(
        width.trim().parse().ok()?,
        height.trim().parse().ok()?,
    ))
    .filter(|size| size.width > 0 && size.height > 0)
}

/// [`parse_geometry`] for a command-line `--sensor` value, with the error a user reads.
pub fn parse_sensor_flag(text: &str) -> Result<SensorSize, String> {
    parse_geometry(text).ok_or_else(|| {
        format!("`{text}` is not a sensor size WxH with sides in 1..=65535 (e.g. 640x480)")
    })
}

/// Sensor sizes of the Prophesee camera plugins whose recordings carry no geometry line
/// (the sizes of the Gen3 VGA, Gen4.1/IMX636 HD and GenX320 sensors).
fn sensor_of_plugin(plugin: &str) -> Option<SensorSize> {
    let plugin = plugin.to_ascii_lowercase();
    if plugin.contains("gen41") || plugin.contains("imx636") || plugin.contains("gen4") {
        Some(SensorSize::new(1280, 720))
    } else if plugin.contains("gen3") || plugin.contains("gen31") {
        Some(SensorSize::new(640, 480))
    } else if plugin.contains("genx320") || plugin.contains("imx8") {
        Some(SensorSize::new(320, 320))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn header(text: &str) -> (PropheseeHeader, u64) {
        let mut bytes = text.as_bytes().to_vec();
        bytes.extend_from_slice(&[0x11, 0x22]);
        let mut source = ByteSource::new("mem".into(), Box::new(Cursor::new(bytes)));
        let header = PropheseeHeader::read(&mut source).unwrap();
        (header, source.offset())
    }

    #[test]
    fn header_styles_give_version_and_size() {
        let (h, offset) = header("% format EVT3;height=720;width=1280\n% end\n");
        assert_eq!(h.evt_version().as_deref(), Some("3.0"));
        assert_eq!(h.sensor_size(), Some(SensorSize::new(1280, 720)));
        assert_eq!(offset, 42);
        let (h, _) = header("% evt 2.0\n% geometry 640x480\n");
        assert_eq!(h.evt_version().as_deref(), Some("2.0"));
        assert_eq!(h.sensor_size(), Some(SensorSize::new(640, 480)));
        let (h, _) = header("% Height 240\n% Width 304\n% Version 2\n");
        assert_eq!(h.sensor_size(), Some(SensorSize::new(304, 240)));
        let (h, _) = header("% evt 3.0\n% plugin_name hal_plugin_gen41_evk3\n");
        assert_eq!(h.sensor_size(), Some(SensorSize::new(1280, 720)));
        let (h, _) = header("% evt 3.0\n");
        assert_eq!(h.sensor_size(), None);
    }
}
