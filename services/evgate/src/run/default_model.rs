//! The shipped export `evgate run` uses when no `--model` is given: the smallest one whose input
//! holds the source's padded sensor, so that 320×240, 346×260 and 640×480 cameras all run with
//! the bundled network (a smaller sensor is zero-padded into the input, as the contract pads).
//! A sensor larger than every export is binned N×N with the smallest N that fits the smallest
//! export, the one that runs in real time on 2 cores (1280×720: N = 4, 320×180 on the 352×272
//! input), unless `--downsample` fixes N.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use evgate_core::SensorSize;
use evgate_io::network::{Endpoint, NetworkError};
use evgate_io::reader::UNBOUNDED_SENSOR;
use evgate_io::LabelledSequence;
use evgate_model::trusted_path::{self, Search};

/// The shipped exports of one set of weights, by the padded input size each takes, smallest
/// first.
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
        // A live stream's header gives its size: read it on a connection of its own.
        (Some(path), None) if network_endpoint(path).is_some() => {
            let endpoint = network_endpoint(path).expect("checked above")?;
            let connection = endpoint.connect(None)?;
            endpoint.decoder(connection, None)?.sensor_size()
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

/// Binning beyond this loses objects smaller than the cell; a larger sensor needs its own export.
const MAX_AUTOMATIC_DOWNSAMPLE: u16 = 8;

/// The export inference runs and the binning the sensor needs to fit it.
#[derive(Debug, PartialEq, Eq)]
pub struct ModelChoice {
    pub path: PathBuf,
    pub downsample: u16,
}

/// The AEDAT 4 network endpoint `input` names, if it names one rather than a file.
fn network_endpoint(input: &Path) -> Option<Result<Endpoint, NetworkError>> {
    Endpoint::parse(input.to_str()?)
}

/// The shipped model for `sensor` binned `downsample`×`downsample` (by default, unbinned where
/// an export holds the sensor, else the smallest binning up to 8×8 that fits the smallest:
/// S at 640×480 takes longer than the 50 ms stride on 2 cores, at 352×272 it keeps up;
/// BENCHMARKS.md, "Inference"),
/// looked for as `models/<file>` in each of `search_from` and their ancestors (the executable's
/// directory, so that a build anywhere in the checkout finds the checkout's models); like the
/// runtime library, only where no other user could have put it.
pub fn shipped_model_for(
    sensor: SensorSize,
    downsample: Option<u16>,
    search_from: &[PathBuf],
) -> anyhow::Result<ModelChoice> {
    let export_for = |factor: u16| {
        let padded = sensor.binned(factor).padded_to(16)?;
        SHIPPED
            .iter()
            .find(|(_, input)| padded.width <= input.width && padded.height <= input.height)
    };
    let chosen = match downsample {
        Some(factor) => export_for(factor).map(|(file, _)| (*file, factor)),
        None => export_for(1).map(|(file, _)| (*file, 1)).or_else(|| {
            let (smallest, input) = SHIPPED[0];
            (2..=MAX_AUTOMATIC_DOWNSAMPLE).find_map(|factor| {
                let padded = sensor.binned(factor).padded_to(16)?;
                (padded.width <= input.width && padded.height <= input.height)
                    .then_some((smallest, factor))
            })
        }),
    };
    let padded = sensor.binned(downsample.unwrap_or(1)).padded_to(16);
    let Some((file, downsample)) = chosen else {
        let shipped: Vec<String> = SHIPPED
            .iter()
            .map(|(file, input)| format!("models/{file} ({input})"))
            .collect();
        let binning = match downsample {
            Some(factor) => format!("binned {factor}x{factor}"),
            None => format!("even binned {MAX_AUTOMATIC_DOWNSAMPLE}x{MAX_AUTOMATIC_DOWNSAMPLE}"),
        };
        bail!(
            "no shipped model takes a {sensor} sensor{}, {binning}; the shipped ones take {}. \
             Pass a larger --downsample, or export a model for this size (models/training: \
             python -m evgate_train.export --height H --width W) and pass --model",
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
        Search::Found(path) => Ok(ModelChoice { path, downsample }),
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

    /// The file and binning chosen for a sensor and `--downsample`.
    fn choice(width: u16, height: u16, downsample: Option<u16>) -> (String, u16) {
        let shipped =
            shipped_model_for(SensorSize::new(width, height), downsample, &[workspace()]).unwrap();
        let file = shipped.path.file_name().unwrap().to_string_lossy();
        (file.into_owned(), shipped.downsample)
    }

    #[test]
    fn each_sensor_gets_the_smallest_export_that_holds_it() {
        let small = ("evgate-S.onnx".to_owned(), 1);
        let large = ("evgate-S-640x480.onnx".to_owned(), 1);
        assert_eq!(choice(346, 260, None), small);
        assert_eq!(choice(320, 240, None), small);
        assert_eq!(choice(352, 260, None), small);
        assert_eq!(choice(353, 260, None), large);
        assert_eq!(choice(640, 480, None), large);
    }

    #[test]
    fn a_sensor_larger_than_every_export_is_binned_until_it_fits() {
        assert_eq!(choice(1280, 720, None), ("evgate-S.onnx".to_owned(), 4));
        assert_eq!(choice(2048, 1536, None), ("evgate-S.onnx".to_owned(), 6));
        assert_eq!(
            choice(1280, 720, Some(2)),
            ("evgate-S-640x480.onnx".to_owned(), 2)
        );
        assert_eq!(choice(640, 480, Some(2)), ("evgate-S.onnx".to_owned(), 2));
        let message = shipped_model_for(SensorSize::new(4096, 3072), None, &[workspace()])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("4096x3072")
                && message.contains("binned 8x8")
                && message.contains("352x272")
                && message.contains("640x480"),
            "{message}"
        );
        let message = shipped_model_for(SensorSize::new(1280, 720), Some(1), &[workspace()])
            .unwrap_err()
            .to_string();
        assert!(message.contains("binned 1x1"), "{message}");
    }

    #[test]
    fn a_missing_model_names_where_it_was_looked_for() {
        let empty = tempfile::tempdir().unwrap();
        let message =
            shipped_model_for(SensorSize::new(346, 260), None, &[empty.path().to_owned()])
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
