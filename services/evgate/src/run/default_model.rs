//! The shipped export `evgate run` uses when no `--model` is given: the one whose input size the
//! source's sensor pads to, so that the simulated driving camera and 640×480 recordings run
//! with the bundled network as the 346×260 presets do.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use evgate_core::SensorSize;
use evgate_io::reader::UNBOUNDED_SENSOR;
use evgate_io::LabelledSequence;
use evgate_model::trusted_path::{self, Search};

/// The shipped exports of one set of weights, by the padded input size each takes.
const SHIPPED: [(&str, SensorSize); 2] = [
    ("evgate-S.onnx", SensorSize::new(352, 272)),
    ("evgate-S-640x480.onnx", SensorSize::new(640, 480)),
];

/// The source's sensor: the preset's for the simulated camera, else `--sensor` or the file's.
pub fn source_sensor(
    input: Option<&Path>,
    sensor_flag: Option<SensorSize>,
    preset: &str,
) -> anyhow::Result<SensorSize> {
    let sensor = match (input, sensor_flag) {
        (None, _) => preset.parse::<evgate_sim::Preset>()?.config().sensor,
        (Some(_), Some(sensor)) => sensor,
        (Some(path), None) if LabelledSequence::is_labelled_sequence(path) => {
            LabelledSequence::read_sensor_size(path)?
        }
        (Some(path), None) => evgate_io::open(path)
            .with_context(|| format!("cannot open --input {}", path.display()))?
            .sensor_size(),
    };
    if sensor == UNBOUNDED_SENSOR {
        bail!(
            "--input {} does not give its sensor size (text event files carry none); pass \
             --sensor WIDTHxHEIGHT",
            input.map_or(String::new(), |path| path.display().to_string())
        );
    }
    Ok(sensor)
}

/// The shipped model for `sensor`, looked for as `models/<file>` in each of `search_from` and
/// their ancestors (the executable's directory, so that a build anywhere in the checkout finds
/// the checkout's models); like the runtime library, only where no other user could have put it.
pub fn shipped_model_for(sensor: SensorSize, search_from: &[PathBuf]) -> anyhow::Result<PathBuf> {
    let padded = sensor.padded_to(16);
    let Some((file, _)) = SHIPPED.iter().find(|(_, input)| Some(*input) == padded) else {
        let shipped: Vec<String> = SHIPPED
            .iter()
            .map(|(file, input)| format!("models/{file} ({input})"))
            .collect();
        bail!(
            "no shipped model takes a {sensor} sensor{}; the shipped ones take {}. Export one \
             for this size (models/training: python -m evgate_train.export --height H --width \
             W) and pass --model",
            padded.map_or(String::new(), |padded| format!(" (padded to {padded})")),
            shipped.join(", ")
        );
    };
    let relative = Path::new("models").join(file);
    match trusted_path::find_in_ancestors(&relative, search_from, trusted_path::current_user())
        .with_context(|| {
            format!(
                "the shipped model {} cannot be used; pass --model",
                relative.display()
            )
        })? {
        Search::Found(path) => Ok(path),
        Search::Missing(looked_at) => bail!(
            "the shipped model models/{file} for a {sensor} sensor is missing (looked at {}); \
             pass --model",
            looked_at
                .iter()
                .map(|path| path.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workspace() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn each_sensor_gets_the_export_it_pads_to() {
        let for_size = |width, height| {
            shipped_model_for(SensorSize::new(width, height), &[workspace()])
                .unwrap()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        };
        assert_eq!(for_size(346, 260), "evgate-S.onnx");
        assert_eq!(for_size(640, 480), "evgate-S-640x480.onnx");
        let message = shipped_model_for(SensorSize::new(1280, 720), &[workspace()])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("1280x720")
                && message.contains("352x272")
                && message.contains("640x480"),
            "{message}"
        );
    }

    #[test]
    fn a_missing_model_names_where_it_was_looked_for() {
        let empty = tempfile::tempdir().unwrap();
        let message = shipped_model_for(SensorSize::new(346, 260), &[empty.path().to_owned()])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains(
                &empty
                    .path()
                    .join("models/evgate-S.onnx")
                    .display()
                    .to_string()
            ),
            "{message}"
        );
    }

    #[test]
    fn the_source_sensor_comes_from_the_preset_or_the_file() {
        assert_eq!(
            source_sensor(None, None, "boxes").unwrap(),
            SensorSize::new(346, 260)
        );
        assert_eq!(
            source_sensor(None, None, "driving").unwrap(),
            SensorSize::new(640, 480)
        );
        assert!(source_sensor(None, None, "night").is_err());
        let recording = workspace().join("../../../shared/data/real/evt2_640x480.raw");
        assert_eq!(
            source_sensor(Some(&recording), None, "boxes").unwrap(),
            SensorSize::new(640, 480)
        );
        let text = tempfile::NamedTempFile::with_suffix(".csv").unwrap();
        std::fs::write(text.path(), "1,2,3,1\n").unwrap();
        let message = source_sensor(Some(text.path()), None, "boxes")
            .unwrap_err()
            .to_string();
        assert!(message.contains("--sensor"), "{message}");
        assert_eq!(
            source_sensor(Some(text.path()), Some(SensorSize::new(346, 260)), "boxes").unwrap(),
            SensorSize::new(346, 260)
        );
    }
}
