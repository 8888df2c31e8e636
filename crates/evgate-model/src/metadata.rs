//! The `evgate.*` metadata keys of an exported network (docs/model-contract.md), parsed and
//! checked so that a wrong file fails at load time with the key and value at fault.

use serde::Serialize;

/// Encoder stages, hence recurrent state tensors.
pub const STATE_COUNT: usize = 4;

/// Voxel bins the runtime feeds (evgate-core's voxel grid).
pub const SUPPORTED_BINS: u32 = 2;

/// The padded input must be divisible by 2^STATE_COUNT so that every encoder stage halves it.
pub const INPUT_MULTIPLE: u16 = 16;

pub const KEY_MODEL_SIZE: &str = "evgate.model-size";
pub const KEY_BASE_CHANNELS: &str = "evgate.base-channels";
pub const KEY_STATE_CHANNELS: &str = "evgate.state-channels";
pub const KEY_BINS: &str = "evgate.bins";
pub const KEY_WINDOW_MS: &str = "evgate.window-ms";
pub const KEY_INPUT_HEIGHT: &str = "evgate.input-height";
pub const KEY_INPUT_WIDTH: &str = "evgate.input-width";
pub const KEY_MAX_HORIZON_MS: &str = "evgate.max-horizon-ms";
pub const KEY_ATC: &str = "evgate.atc";
pub const KEY_TRAIN_MANIFEST_SHA256: &str = "evgate.train-manifest-sha256";
pub const KEY_TRAIN_STEPS: &str = "evgate.train-steps";
/// Optional: the `future_flow` output is at 1/stride of the input size. Exports made before the
/// key existed wrote the flow at full resolution, so an absent key means 1.
pub const KEY_FLOW_STRIDE: &str = "evgate.flow-stride";

/// Optional: the mask logit above which a pixel is an independently moving object, chosen on
/// validation data for the best per-event F1. Exports without the key use 0 (probability 0.5).
pub const KEY_THRESHOLD_LOGIT: &str = "evgate.threshold-logit";

/// Optional: the gate keeps the events of a horizon's *keep region*, the forecast logits
/// dilated by this radius in model pixels (the maximum over the (2r + 1)-pixel square) and
/// thresholded at `evgate.keep-threshold-logit`; chosen together on validation data for the
/// best per-event F1. The forecast masks themselves stay undilated. Absent: 0.
pub const KEY_KEEP_DILATION_PX: &str = "evgate.keep-dilation-px";

/// Optional: the logit above which a pixel of a dilated forecast is in the keep region.
/// Absent: `evgate.threshold-logit`'s value.
pub const KEY_KEEP_THRESHOLD_LOGIT: &str = "evgate.keep-threshold-logit";

/// The largest dilation radius an export may declare.
pub const MAX_KEEP_DILATION_PX: u16 = 16;

/// Flow strides an export may declare: powers of two that divide every padded input side.
pub const FLOW_STRIDES: [u16; 5] = [1, 2, 4, 8, 16];

/// Every key the contract requires, in the order of docs/model-contract.md.
pub const REQUIRED_KEYS: [&str; 11] = [
    KEY_MODEL_SIZE,
    KEY_BASE_CHANNELS,
    KEY_STATE_CHANNELS,
    KEY_BINS,
    KEY_WINDOW_MS,
    KEY_INPUT_HEIGHT,
    KEY_INPUT_WIDTH,
    KEY_MAX_HORIZON_MS,
    KEY_ATC,
    KEY_TRAIN_MANIFEST_SHA256,
    KEY_TRAIN_STEPS,
];

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MetadataError {
    #[error("metadata key `{key}` is missing")]
    Missing { key: &'static str },
    #[error("metadata key `{key}` has value {value:?}; expected {expected}")]
    Invalid {
        key: &'static str,
        value: String,
        expected: String,
    },
}

/// Model width class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ModelSize {
    #[serde(rename = "XS")]
    ExtraSmall,
    #[serde(rename = "S")]
    Small,
    #[serde(rename = "M")]
    Medium,
    #[serde(rename = "L")]
    Large,
}

impl ModelSize {
    pub fn label(self) -> &'static str {
        match self {
            Self::ExtraSmall => "XS",
            Self::Small => "S",
            Self::Medium => "M",
            Self::Large => "L",
        }
    }
}

/// How the attention-based time conditioning forms its query.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AtcVariant {
    /// Token + time encoding: the attended map varies over the image.
    PositionAware,
    /// The reference code's query: the same time vector everywhere.
    Reference,
    /// No time conditioning.
    None,
}

/// The validated metadata of one exported network.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct ModelMetadata {
    pub model_size: ModelSize,
    pub base_channels: u32,
    pub state_channels: [u32; STATE_COUNT],
    pub bins: u32,
    pub window_ms: u32,
    pub input_height: u16,
    pub input_width: u16,
    pub max_horizon_ms: f32,
    pub atc: AtcVariant,
    /// Hash of the training suite's manifest; `None` for an export of untrained weights (the
    /// exporter writes `untrained`), which only runtime tests use.
    pub train_manifest_sha256: Option<String>,
    pub train_steps: u64,
    /// `future_flow` is `input / flow_stride` high and wide (1 for exports without the key).
    pub flow_stride: u16,
    /// Logit above which a mask pixel is set (0 for exports without the key).
    pub threshold_logit: f32,
    /// Logit above which a pixel of a dilated forecast is kept (`threshold_logit` without the
    /// key).
    pub keep_threshold_logit: f32,
    /// Radius by which forecast logits are dilated into keep regions (0 without the key).
    pub keep_dilation_px: u16,
}

impl ModelMetadata {
    /// Parses the contract's keys through `lookup` (key → value, `None` when absent).
    pub fn from_lookup(lookup: impl Fn(&str) -> Option<String>) -> Result<Self, MetadataError> {
        let value = |key: &'static str| lookup(key).ok_or(MetadataError::Missing { key });
        let threshold_logit = lookup(KEY_THRESHOLD_LOGIT).map_or(Ok(0.0), |threshold| {
            parse_threshold_logit(KEY_THRESHOLD_LOGIT, &threshold)
        })?;
        let metadata = Self {
            model_size: parse_model_size(&value(KEY_MODEL_SIZE)?)?,
            base_channels: parse_positive(KEY_BASE_CHANNELS, &value(KEY_BASE_CHANNELS)?)?,
            state_channels: parse_state_channels(&value(KEY_STATE_CHANNELS)?)?,
            bins: parse_bins(&value(KEY_BINS)?)?,
            window_ms: parse_positive(KEY_WINDOW_MS, &value(KEY_WINDOW_MS)?)?,
            input_height: parse_input_side(KEY_INPUT_HEIGHT, &value(KEY_INPUT_HEIGHT)?)?,
            input_width: parse_input_side(KEY_INPUT_WIDTH, &value(KEY_INPUT_WIDTH)?)?,
            max_horizon_ms: parse_max_horizon(&value(KEY_MAX_HORIZON_MS)?)?,
            atc: parse_atc(&value(KEY_ATC)?)?,
            train_manifest_sha256: parse_sha256(&value(KEY_TRAIN_MANIFEST_SHA256)?)?,
            train_steps: parse_count(KEY_TRAIN_STEPS, &value(KEY_TRAIN_STEPS)?)?,
            flow_stride: lookup(KEY_FLOW_STRIDE)
                .map_or(Ok(1), |stride| parse_flow_stride(&stride))?,
            threshold_logit,
            keep_threshold_logit: lookup(KEY_KEEP_THRESHOLD_LOGIT)
                .map_or(Ok(threshold_logit), |threshold| {
                    parse_threshold_logit(KEY_KEEP_THRESHOLD_LOGIT, &threshold)
                })?,
            keep_dilation_px: lookup(KEY_KEEP_DILATION_PX)
                .map_or(Ok(0), |radius| parse_mask_dilation(&radius))?,
        };
        Ok(metadata)
    }

    /// Shape [1, C_i, H / 2^(i+1), W / 2^(i+1)] of recurrent state `stage`.
    pub fn state_shape(&self, stage: usize) -> [usize; 4] {
        let divisor = 1usize << (stage + 1);
        [
            1,
            self.state_channels[stage] as usize,
            usize::from(self.input_height) / divisor,
            usize::from(self.input_width) / divisor,
        ]
    }

    /// (height, width) of each `future_flow` plane.
    pub fn flow_size(&self) -> (usize, usize) {
        let stride = usize::from(self.flow_stride);
        (
            usize::from(self.input_height) / stride,
            usize::from(self.input_width) / stride,
        )
    }
}

fn invalid(key: &'static str, value: &str, expected: impl Into<String>) -> MetadataError {
    MetadataError::Invalid {
        key,
        value: value.to_owned(),
        expected: expected.into(),
    }
}

fn parse_model_size(value: &str) -> Result<ModelSize, MetadataError> {
    match value.trim() {
        "XS" => Ok(ModelSize::ExtraSmall),
        "S" => Ok(ModelSize::Small),
        "M" => Ok(ModelSize::Medium),
        "L" => Ok(ModelSize::Large),
        _ => Err(invalid(KEY_MODEL_SIZE, value, "one of XS, S, M, L")),
    }
}

fn parse_positive(key: &'static str, value: &str) -> Result<u32, MetadataError> {
    match value.trim().parse::<u32>() {
        Ok(parsed) if parsed > 0 => Ok(parsed),
        _ => Err(invalid(key, value, "a positive integer")),
    }
}

fn parse_count(key: &'static str, value: &str) -> Result<u64, MetadataError> {
    value
        .trim()
        .parse::<u64>()
        .map_err(|_| invalid(key, value, "a non-negative integer"))
}

fn parse_state_channels(value: &str) -> Result<[u32; STATE_COUNT], MetadataError> {
    let expected = "four comma-separated positive integers, e.g. 16,32,64,128";
    let parsed: Vec<u32> = value
        .split(',')
        .map(|part| part.trim().parse::<u32>().ok().filter(|&c| c > 0))
        .collect::<Option<_>>()
        .ok_or_else(|| invalid(KEY_STATE_CHANNELS, value, expected))?;
    parsed
        .try_into()
        .map_err(|_| invalid(KEY_STATE_CHANNELS, value, expected))
}

fn parse_bins(value: &str) -> Result<u32, MetadataError> {
    match value.trim().parse::<u32>() {
        Ok(SUPPORTED_BINS) => Ok(SUPPORTED_BINS),
        _ => Err(invalid(
            KEY_BINS,
            value,
            format!("{SUPPORTED_BINS} (the voxel grid evgate-core builds)"),
        )),
    }
}

fn parse_input_side(key: &'static str, value: &str) -> Result<u16, MetadataError> {
    match value.trim().parse::<u16>() {
        Ok(side) if side > 0 && side % INPUT_MULTIPLE == 0 => Ok(side),
        _ => Err(invalid(
            key,
            value,
            format!("a positive multiple of {INPUT_MULTIPLE} up to 65520"),
        )),
    }
}

fn parse_max_horizon(value: &str) -> Result<f32, MetadataError> {
    match value.trim().parse::<f32>() {
        Ok(horizon) if horizon.is_finite() && horizon > 0.0 => Ok(horizon),
        _ => Err(invalid(
            KEY_MAX_HORIZON_MS,
            value,
            "a positive number of milliseconds",
        )),
    }
}

fn parse_atc(value: &str) -> Result<AtcVariant, MetadataError> {
    match value.trim() {
        "position-aware" => Ok(AtcVariant::PositionAware),
        "reference" => Ok(AtcVariant::Reference),
        "none" => Ok(AtcVariant::None),
        _ => Err(invalid(
            KEY_ATC,
            value,
            "one of position-aware, reference, none",
        )),
    }
}

fn parse_flow_stride(value: &str) -> Result<u16, MetadataError> {
    match value.trim().parse::<u16>() {
        Ok(stride) if FLOW_STRIDES.contains(&stride) => Ok(stride),
        _ => Err(invalid(KEY_FLOW_STRIDE, value, "one of 1, 2, 4, 8, 16")),
    }
}

fn parse_threshold_logit(key: &'static str, value: &str) -> Result<f32, MetadataError> {
    match value.trim().parse::<f32>() {
        Ok(threshold) if threshold.is_finite() => Ok(threshold),
        _ => Err(invalid(key, value, "a finite number")),
    }
}

fn parse_mask_dilation(value: &str) -> Result<u16, MetadataError> {
    match value.trim().parse::<u16>() {
        Ok(radius) if radius <= MAX_KEEP_DILATION_PX => Ok(radius),
        _ => Err(invalid(
            KEY_KEEP_DILATION_PX,
            value,
            format!("a whole number of pixels from 0 to {MAX_KEEP_DILATION_PX}"),
        )),
    }
}

/// Written instead of a manifest hash for freshly initialised weights.
pub const UNTRAINED_MANIFEST: &str = "untrained";

fn parse_sha256(value: &str) -> Result<Option<String>, MetadataError> {
    let trimmed = value.trim();
    if trimmed == UNTRAINED_MANIFEST {
        Ok(None)
    } else if trimmed.len() == 64 && trimmed.bytes().all(|b| b.is_ascii_hexdigit()) {
        Ok(Some(trimmed.to_ascii_lowercase()))
    } else {
        Err(invalid(
            KEY_TRAIN_MANIFEST_SHA256,
            value,
            format!("64 hexadecimal digits or `{UNTRAINED_MANIFEST}`"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    fn valid() -> HashMap<&'static str, String> {
        [
            (KEY_MODEL_SIZE, "S"),
            (KEY_BASE_CHANNELS, "16"),
            (KEY_STATE_CHANNELS, "16,32,64,128"),
            (KEY_BINS, "2"),
            (KEY_WINDOW_MS, "50"),
            (KEY_INPUT_HEIGHT, "272"),
            (KEY_INPUT_WIDTH, "352"),
            (KEY_MAX_HORIZON_MS, "100"),
            (KEY_ATC, "position-aware"),
            (KEY_TRAIN_MANIFEST_SHA256, &"ab".repeat(32)),
            (KEY_TRAIN_STEPS, "6000"),
        ]
        .into_iter()
        .map(|(k, v)| (k, v.to_owned()))
        .collect()
    }

    fn parse(map: &HashMap<&'static str, String>) -> Result<ModelMetadata, MetadataError> {
        ModelMetadata::from_lookup(|key| map.get(key).cloned())
    }

    #[test]
    fn parses_the_contract_example() {
        let metadata = parse(&valid()).unwrap();
        assert_eq!(metadata.model_size, ModelSize::Small);
        assert_eq!(metadata.state_channels, [16, 32, 64, 128]);
        assert_eq!(metadata.state_shape(0), [1, 16, 136, 176]);
        assert_eq!(metadata.state_shape(3), [1, 128, 17, 22]);
        assert_eq!(metadata.atc, AtcVariant::PositionAware);
        assert_eq!(metadata.train_manifest_sha256, Some("ab".repeat(32)));
        assert_eq!(metadata.flow_size(), (272, 352));
    }

    #[test]
    fn flow_stride_sets_the_flow_size_and_defaults_to_full_resolution() {
        let mut map = valid();
        assert_eq!(parse(&map).unwrap().flow_stride, 1);
        map.insert(KEY_FLOW_STRIDE, "8".to_owned());
        let metadata = parse(&map).unwrap();
        assert_eq!(metadata.flow_stride, 8);
        assert_eq!(metadata.flow_size(), (34, 44));
    }

    #[test]
    fn the_threshold_logit_defaults_to_zero_and_must_be_finite() {
        let mut map = valid();
        assert_eq!(parse(&map).unwrap().threshold_logit, 0.0);
        map.insert(KEY_THRESHOLD_LOGIT, "-0.75".to_owned());
        assert_eq!(parse(&map).unwrap().threshold_logit, -0.75);
        map.insert(KEY_THRESHOLD_LOGIT, "nan".to_owned());
        assert_eq!(
            parse(&map).unwrap_err().to_string(),
            "metadata key `evgate.threshold-logit` has value \"nan\"; expected a finite number"
        );
    }

    #[test]
    fn the_mask_dilation_defaults_to_none_and_is_bounded() {
        let mut map = valid();
        assert_eq!(parse(&map).unwrap().keep_dilation_px, 0);
        map.insert(KEY_KEEP_DILATION_PX, "3".to_owned());
        assert_eq!(parse(&map).unwrap().keep_dilation_px, 3);
        for bad in ["17", "-1", "2.5", "wide"] {
            map.insert(KEY_KEEP_DILATION_PX, bad.to_owned());
            assert_eq!(
                parse(&map).unwrap_err().to_string(),
                format!(
                    "metadata key `evgate.keep-dilation-px` has value \"{bad}\"; expected a \
                     whole number of pixels from 0 to 16"
                )
            );
        }
    }

    #[test]
    fn untrained_exports_have_no_manifest() {
        let mut map = valid();
        map.insert(KEY_TRAIN_MANIFEST_SHA256, UNTRAINED_MANIFEST.to_owned());
        assert_eq!(parse(&map).unwrap().train_manifest_sha256, None);
    }

    #[test]
    fn every_missing_key_is_named() {
        for key in REQUIRED_KEYS {
            let mut map = valid();
            map.remove(key);
            assert_eq!(parse(&map).unwrap_err(), MetadataError::Missing { key });
        }
    }

    #[test]
    fn bad_values_name_key_value_and_accepted_values() {
        let cases = [
            (KEY_MODEL_SIZE, "XL", "XS, S, M, L"),
            (KEY_STATE_CHANNELS, "16,32,64", "four comma-separated"),
            (KEY_BINS, "5", "2"),
            (KEY_INPUT_HEIGHT, "260", "multiple of 16"),
            (KEY_INPUT_WIDTH, "0", "multiple of 16"),
            (KEY_MAX_HORIZON_MS, "-3", "positive"),
            (KEY_ATC, "global", "position-aware, reference, none"),
            (KEY_TRAIN_MANIFEST_SHA256, "xyz", "64 hexadecimal"),
            (KEY_TRAIN_STEPS, "many", "non-negative integer"),
            (KEY_FLOW_STRIDE, "3", "1, 2, 4, 8, 16"),
        ];
        for (key, value, accepted) in cases {
            let mut map = valid();
            map.insert(key, value.to_owned());
            let message = parse(&map).unwrap_err().to_string();
            assert!(message.contains(key), "{message}");
            assert!(message.contains(value), "{message}");
            assert!(message.contains(accepted), "{message}");
        }
    }
}
