//! The runtime against a real exported network: the committed `models/evgate-S.onnx`
//! (`EVGATE_TEST_MODEL=/path/to/model.onnx` points these tests at another export).

use std::path::PathBuf;

use evgate_core::{Event, SensorSize, TimeSpan, VoxelGrid};
use evgate_model::{
    ForecastOutput, Forecaster, MaskRule, ModelError, ModelRuntime, RuntimeOptions,
};

const COMMITTED_MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/evgate-S.onnx");

fn model_path() -> PathBuf {
    let path = std::env::var_os("EVGATE_TEST_MODEL")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(COMMITTED_MODEL));
    assert!(
        path.is_file(),
        "these tests need the exported network {} (committed as models/evgate-S.onnx; \
         EVGATE_TEST_MODEL overrides the path) and it is missing",
        path.display()
    );
    path
}

fn load() -> ModelRuntime {
    ModelRuntime::load(model_path(), RuntimeOptions::default()).unwrap()
}

/// Deterministic voxel-like input: sparse ±values as a normalised voxel grid would hold.
fn pseudo_voxel(length: usize, seed: u64) -> Vec<f32> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..length)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            match x % 10 {
                0 => 1.5,
                1 => -1.5,
                _ => 0.0,
            }
        })
        .collect()
}

fn voxel_length(runtime: &ModelRuntime) -> usize {
    let size = runtime.input_size();
    2 * size.pixels()
}

const HORIZONS: [f32; 3] = [10.0, 50.0, 100.0];

fn max_abs_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn outputs_have_the_contract_shapes() {
    let mut runtime = load();
    let size = runtime.input_size();
    assert_eq!(size.width % 16, 0);
    assert_eq!(size.height % 16, 0);
    let plane = size.pixels();
    let voxel = pseudo_voxel(voxel_length(&runtime), 1);
    let output = runtime.forecast(&voxel, &HORIZONS).unwrap();
    assert_eq!(output.width(), usize::from(size.width));
    assert_eq!(output.height(), usize::from(size.height));
    assert_eq!(output.mask_logits().len(), plane);
    assert_eq!(output.horizons_ms(), HORIZONS);
    let futures: Vec<&[f32]> = output.future_mask_logits().collect();
    assert_eq!(futures.len(), HORIZONS.len());
    assert!(futures.iter().all(|f| f.len() == plane));
    let (flow_height, flow_width) = runtime.metadata().flow_size();
    assert_eq!(
        (output.flow_height(), output.flow_width()),
        (flow_height, flow_width)
    );
    let flow_plane = flow_height * flow_width;
    let flows: Vec<(&[f32], &[f32])> = output.future_flows().collect();
    assert_eq!(flows.len(), HORIZONS.len());
    assert!(flows
        .iter()
        .all(|(dx, dy)| dx.len() == flow_plane && dy.len() == flow_plane));
    assert!(output.mask_logits().iter().all(|v| v.is_finite()));
    assert!(!output.inference_time().is_zero());
    assert_eq!(runtime.windows_carried(), 1);
}

#[test]
fn state_is_carried_between_windows_and_reset_forgets_it() {
    let mut runtime = load();
    let first = pseudo_voxel(voxel_length(&runtime), 1);
    let second = pseudo_voxel(voxel_length(&runtime), 2);

    runtime.forecast(&first, &HORIZONS).unwrap();
    let with_history = runtime
        .forecast(&second, &HORIZONS)
        .unwrap()
        .mask_logits()
        .to_vec();
    assert_eq!(runtime.windows_carried(), 2);

    runtime.reset_state().unwrap();
    assert_eq!(runtime.windows_carried(), 0);
    let without_history = runtime
        .forecast(&second, &HORIZONS)
        .unwrap()
        .mask_logits()
        .to_vec();
    assert!(
        max_abs_difference(&with_history, &without_history) > 1e-4,
        "the second window gave the same logits with and without the first one before it"
    );

    runtime.reset_state().unwrap();
    runtime.forecast(&first, &HORIZONS).unwrap();
    let replayed = runtime
        .forecast(&second, &HORIZONS)
        .unwrap()
        .mask_logits()
        .to_vec();
    assert!(
        max_abs_difference(&with_history, &replayed) < 1e-4,
        "replaying the same two windows after a reset gave different logits"
    );
}

#[test]
fn horizons_change_the_forecast() {
    let mut runtime = load();
    let voxel = pseudo_voxel(voxel_length(&runtime), 3);
    let output = runtime.forecast(&voxel, &[0.0, 100.0]).unwrap();
    let flows: Vec<(&[f32], &[f32])> = output.future_flows().collect();
    // Flow is velocity × horizon, so a zero horizon predicts no displacement.
    assert!(flows[0].0.iter().chain(flows[0].1).all(|v| v.abs() < 1e-4));
    assert!(flows[1].0.iter().chain(flows[1].1).any(|v| v.abs() > 1e-6));
}

#[test]
fn bad_inputs_are_errors_and_leave_the_state_alone() {
    let mut runtime = load();
    let length = voxel_length(&runtime);
    let voxel = pseudo_voxel(length, 4);

    let error = runtime
        .forecast(&voxel[..length - 1], &HORIZONS)
        .unwrap_err();
    assert!(matches!(error, ModelError::VoxelLength { .. }), "{error}");
    let message = error.to_string();
    assert!(message.contains(&(length - 1).to_string()) && message.contains(&length.to_string()));

    let error = runtime.forecast(&voxel, &[]).unwrap_err();
    assert!(matches!(error, ModelError::NoHorizons), "{error}");

    let error = runtime.forecast(&voxel, &[10.0, 250.0]).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("#1") && message.contains("250"),
        "{message}"
    );

    let error = runtime.forecast(&voxel, &[f32::NAN]).unwrap_err();
    assert!(
        matches!(error, ModelError::HorizonOutOfRange { index: 0, .. }),
        "{error}"
    );

    assert_eq!(runtime.windows_carried(), 0);
}

#[test]
fn missing_model_file_is_named() {
    let missing = std::env::temp_dir().join("evgate-no-such-model.onnx");
    let error = ModelRuntime::load(&missing, RuntimeOptions::default())
        .err()
        .unwrap();
    assert!(
        error.to_string().contains(&missing.display().to_string()),
        "{error}"
    );
}

/// The model's bytes with the value of metadata entry `key` changed by `edit`. Protobuf
/// stores the entry as key bytes, then tag 0x12 and a one-byte length for a short value; a
/// same-length edit keeps every enclosing length valid.
fn edit_metadata(key: &str, edit: impl Fn(&mut [u8], &mut [u8])) -> Vec<u8> {
    let mut bytes = std::fs::read(model_path()).unwrap();
    let start = bytes
        .windows(key.len())
        .position(|window| window == key.as_bytes())
        .unwrap_or_else(|| panic!("metadata key {key} not found in the model file"));
    let key_end = start + key.len();
    assert_eq!(bytes[key_end], 0x12, "metadata value tag after {key}");
    let value_length = usize::from(bytes[key_end + 1]);
    let (head, tail) = bytes.split_at_mut(key_end);
    edit(&mut head[start..], &mut tail[2..2 + value_length]);
    bytes
}

fn load_bytes(bytes: &[u8]) -> (PathBuf, ModelError, tempfile::TempDir) {
    let directory = tempfile::tempdir().unwrap();
    let path = directory.path().join("edited.onnx");
    std::fs::write(&path, bytes).unwrap();
    let error = ModelRuntime::load(&path, RuntimeOptions::default())
        .err()
        .expect("the edited model loaded");
    (path, error, directory)
}

#[test]
fn a_missing_metadata_key_names_the_file_and_key() {
    let bytes = edit_metadata("evgate.window-ms", |key, _| {
        let last = key.len() - 1;
        key[last] = b'x';
    });
    let (path, error, _directory) = load_bytes(&bytes);
    let message = error.to_string();
    assert!(message.contains(&path.display().to_string()), "{message}");
    assert!(
        message.contains("`evgate.window-ms` is missing"),
        "{message}"
    );
}

#[test]
fn a_bad_metadata_value_names_the_file_key_value_and_accepted_values() {
    let bytes = edit_metadata("evgate.atc", |_, value| value.fill(b'q'));
    let (path, error, _directory) = load_bytes(&bytes);
    let message = error.to_string();
    assert!(message.contains(&path.display().to_string()), "{message}");
    assert!(
        message.contains("evgate.atc") && message.contains("qqqq"),
        "{message}"
    );
    assert!(
        message.contains("position-aware, reference, none"),
        "{message}"
    );
}

#[test]
fn an_input_size_disagreeing_with_the_graph_breaks_the_contract() {
    // Another multiple of 16 with as many digits: valid on its own, but not the size the graph
    // was exported for.
    let bytes = edit_metadata("evgate.input-height", |_, value| {
        let original = String::from_utf8(value.to_vec()).unwrap();
        let replacement = (16..)
            .step_by(16)
            .map(|side: u32| side.to_string())
            .find(|side| side.len() == original.len() && *side != original)
            .unwrap();
        value.copy_from_slice(replacement.as_bytes());
    });
    let (path, error, _directory) = load_bytes(&bytes);
    let message = error.to_string();
    assert!(matches!(error, ModelError::Contract { .. }), "{message}");
    assert!(
        message.contains(&path.display().to_string()) && message.contains("voxel"),
        "{message}"
    );
}

#[test]
fn cuda_requests_fall_back_to_cpu_when_cuda_cannot_be_used() {
    use evgate_model::{ActiveProvider, Provider};
    for provider in [Provider::Cuda, Provider::Auto] {
        let options = RuntimeOptions {
            provider,
            ..RuntimeOptions::default()
        };
        let mut runtime = ModelRuntime::load(model_path(), options).unwrap();
        if !cuda_library_present() {
            assert_eq!(runtime.active_provider(), ActiveProvider::Cpu);
        }
        let voxel = pseudo_voxel(voxel_length(&runtime), 5);
        runtime.forecast(&voxel, &HORIZONS).unwrap();
    }
}

/// The onnxruntime-gpu wheel ships the CUDA provider as a separate library beside the runtime.
fn cuda_library_present() -> bool {
    evgate_model::locate_onnxruntime()
        .ok()
        .and_then(|library| {
            library
                .parent()
                .map(|d| d.join("libonnxruntime_providers_cuda.so"))
        })
        .is_some_and(|provider| provider.is_file())
}

/// Every output of `runtime` over the windows `seeds`, with a reset before the last one and
/// the horizon count changed in between, flattened for comparison.
fn run_sequence(runtime: &mut ModelRuntime, seeds: &[u64]) -> Vec<Vec<f32>> {
    let mut results = Vec::new();
    for (index, &seed) in seeds.iter().enumerate() {
        if index + 1 == seeds.len() {
            runtime.reset_state().unwrap();
        }
        let horizons: &[f32] = if index % 2 == 0 { &HORIZONS } else { &[100.0] };
        let voxel = pseudo_voxel(voxel_length(runtime), seed);
        let output = runtime.forecast(&voxel, horizons).unwrap();
        results.push(output.mask_logits().to_vec());
        results.push(output.future_mask_logits().flatten().copied().collect());
        results.push(
            output
                .future_flows()
                .flat_map(|(dx, dy)| dx.iter().chain(dy).copied())
                .collect(),
        );
    }
    results
}

/// `EVGATE_TEST_PROVIDER=cuda` runs the state-binding test on a GPU (where binding keeps the
/// state in device memory); CI has none and runs it on the CPU.
fn test_provider() -> evgate_model::Provider {
    std::env::var("EVGATE_TEST_PROVIDER").map_or(evgate_model::Provider::Cpu, |name| {
        name.parse().expect("EVGATE_TEST_PROVIDER")
    })
}

#[test]
fn a_bound_state_forecasts_as_the_state_passed_through_host_memory() {
    use evgate_model::{ActiveProvider, StateBinding};
    let load_with = |state_binding| {
        let options = RuntimeOptions {
            provider: test_provider(),
            state_binding,
            ..RuntimeOptions::default()
        };
        ModelRuntime::load(model_path(), options).unwrap()
    };
    let mut passed = load_with(StateBinding::Never);
    let mut bound = load_with(StateBinding::Always);
    let on_cuda = bound.active_provider() == ActiveProvider::Cuda;
    assert!(!passed.state_bound());
    assert!(bound.state_bound());
    assert_eq!(load_with(StateBinding::Auto).state_bound(), on_cuda);
    // Two CUDA sessions may pick different convolution algorithms; the CPU's are the same.
    let tolerance = if on_cuda { 1e-3 } else { 1e-5 };

    let seeds = [1, 2, 3, 4, 5];
    let expected = run_sequence(&mut passed, &seeds);
    let actual = run_sequence(&mut bound, &seeds);
    assert_eq!(bound.windows_carried(), passed.windows_carried());
    for (index, (a, b)) in expected.iter().zip(&actual).enumerate() {
        assert_eq!(a.len(), b.len(), "output {index}");
        let difference = max_abs_difference(a, b);
        println!("output {index}: bound and passed state differ by at most {difference:e}");
        assert!(
            difference < tolerance,
            "output {index} differs by {difference}"
        );
    }

    // A refused window leaves the bound state as it was.
    let mut refused = load_with(StateBinding::Always);
    let mut reference = load_with(StateBinding::Always);
    let first = pseudo_voxel(voxel_length(&refused), 1);
    let second = pseudo_voxel(voxel_length(&refused), 2);
    refused.forecast(&first, &HORIZONS).unwrap();
    reference.forecast(&first, &HORIZONS).unwrap();
    assert!(refused.forecast(&first, &[10.0, 1e6]).is_err());
    let after_refusal = refused.forecast(&second, &HORIZONS).unwrap();
    let without = reference.forecast(&second, &HORIZONS).unwrap();
    assert!(max_abs_difference(after_refusal.mask_logits(), without.mask_logits()) < tolerance);
}

#[test]
fn warm_up_leaves_the_runtime_as_loaded() {
    let mut warmed = load();
    let mut fresh = load();
    warmed.warm_up(&HORIZONS).unwrap();
    assert_eq!(warmed.windows_carried(), 0);
    let voxel = pseudo_voxel(voxel_length(&fresh), 3);
    let after_warm_up = warmed.forecast(&voxel, &HORIZONS).unwrap();
    let without = fresh.forecast(&voxel, &HORIZONS).unwrap();
    assert!(max_abs_difference(after_warm_up.mask_logits(), without.mask_logits()) < 1e-6);
    assert!(warmed.warm_up(&[]).is_err(), "warm-up accepted no horizons");
}

/// A bar of events drifting right over 50 ms, on EVIMO's sensor.
fn drifting_bar() -> (SensorSize, Vec<Event>, TimeSpan) {
    let sensor = SensorSize::new(346, 260);
    let events = (0..20_000i64)
        .map(|i| {
            let t = i * 50_000 / 20_000;
            let x = (100 + t / 1000 + i % 12) as u16;
            let y = (80 + (i * 7) % 90) as u16;
            Event::new(t, x, y, i % 3 != 0)
        })
        .collect();
    (sensor, events, TimeSpan::new(0, 50_000).unwrap())
}

/// The network's own output for one window, before any forecaster thresholds it.
fn network_output(sensor: SensorSize, events: &[Event], window: TimeSpan) -> ForecastOutput {
    let mut raw = load();
    let mut grid = VoxelGrid::new(sensor, raw.metadata().bins as usize).unwrap();
    grid.accumulate(events, window);
    grid.normalise();
    raw.forecast(&grid.as_input(raw.input_size()).unwrap(), &HORIZONS)
        .unwrap()
}

/// The committed network behind a forecaster with `rule`, the infer service's kind where
/// `keep_regions_only`.
fn forecaster_of(rule: MaskRule, keep_regions_only: bool) -> Forecaster {
    let forecaster = Forecaster::new(load(), rule, 1);
    if keep_regions_only {
        forecaster.keep_regions_only()
    } else {
        forecaster
    }
}

#[test]
fn the_forecasters_current_keep_mask_is_the_current_logits_at_the_keep_threshold() {
    let (sensor, events, window) = drifting_bar();
    let output = network_output(sensor, &events, window);
    let width = output.width();
    let mut sorted: Vec<f32> = output.mask_logits().to_vec();
    sorted.sort_by(f32::total_cmp);
    let threshold_logit = sorted[sorted.len() * 99 / 100];
    let keep_threshold_logit = sorted[sorted.len() * 97 / 100];
    let above = |threshold: f32| -> Vec<bool> {
        (0..usize::from(sensor.height))
            .flat_map(|y| (0..usize::from(sensor.width)).map(move |x| (x, y)))
            .map(|(x, y)| output.mask_logits()[y * width + x] > threshold)
            .collect()
    };
    let (expected_current, expected_keep) = (above(threshold_logit), above(keep_threshold_logit));
    assert_ne!(
        expected_current, expected_keep,
        "the thresholds set the same pixels"
    );

    let current_masks = |keep_threshold_logit, keep_regions_only: bool| {
        let rule = MaskRule {
            threshold_logit,
            keep_threshold_logit,
            keep_dilation_px: 0,
        };
        let mut forecaster = forecaster_of(rule, keep_regions_only);
        let forecast = forecaster
            .forecast(sensor, &events, window, &HORIZONS)
            .unwrap();
        (
            forecast.current.view().to_bools(),
            forecast.current_keep.view().to_bools(),
        )
    };
    assert_eq!(
        current_masks(keep_threshold_logit, false),
        (expected_current.clone(), expected_keep)
    );
    assert_eq!(
        current_masks(threshold_logit, false),
        (expected_current.clone(), expected_current.clone()),
        "where the thresholds agree the current keep mask is the current mask"
    );
    assert_eq!(
        current_masks(keep_threshold_logit, true),
        (expected_current.clone(), expected_current),
        "keep-regions-only thresholded the current mask twice"
    );
}

#[test]
fn the_forecasters_keep_regions_are_its_forecasts_dilated_by_its_rule() {
    let (sensor, events, window) = drifting_bar();
    let output = network_output(sensor, &events, window);
    let (width, height) = (output.width(), output.height());
    // Thresholds that set about 2 % and 1 % of the padded map, so that dilation has room.
    let mut sorted: Vec<f32> = output.future_mask_logits().flatten().copied().collect();
    sorted.sort_by(f32::total_cmp);
    let threshold_logit = sorted[sorted.len() * 98 / 100];
    let keep_threshold_logit = sorted[sorted.len() * 99 / 100];
    let radius = 2;
    // Threshold, then dilate the binary map by the square: the same region as dilating the
    // logits first, since a threshold keeps the order of the maximum.
    let expected: Vec<Vec<bool>> = output
        .future_mask_logits()
        .map(|plane| {
            (0..usize::from(sensor.height))
                .flat_map(|y| (0..usize::from(sensor.width)).map(move |x| (x, y)))
                .map(|(x, y)| {
                    (y.saturating_sub(radius)..=(y + radius).min(height - 1)).any(|yy| {
                        (x.saturating_sub(radius)..=(x + radius).min(width - 1))
                            .any(|xx| plane[yy * width + xx] > keep_threshold_logit)
                    })
                })
                .collect()
        })
        .collect();

    let forecast_with = |rule, keep_regions_only: bool| {
        let mut forecaster = forecaster_of(rule, keep_regions_only);
        let forecast = forecaster
            .forecast(sensor, &events, window, &HORIZONS)
            .unwrap();
        let bools = |masks: &[evgate_core::BitMask]| -> Vec<Vec<bool>> {
            masks.iter().map(|mask| mask.view().to_bools()).collect()
        };
        (
            forecast.current.view().to_bools(),
            bools(forecast.futures),
            bools(forecast.keep),
        )
    };
    let plain_rule = MaskRule {
        threshold_logit,
        keep_threshold_logit: threshold_logit,
        keep_dilation_px: 0,
    };
    let dilating_rule = MaskRule {
        threshold_logit,
        keep_threshold_logit,
        keep_dilation_px: radius as u16,
    };
    let plain = forecast_with(plain_rule, false);
    let dilated = forecast_with(dilating_rule, false);
    assert_eq!(
        forecast_with(plain_rule, true),
        plain,
        "without dilation the keep regions are the forecasts, which it must then threshold"
    );
    let lean = forecast_with(dilating_rule, true);
    assert_eq!(
        lean.0, dilated.0,
        "keep-regions-only changed the current mask"
    );
    assert_eq!(
        lean.2, dilated.2,
        "keep-regions-only changed the keep regions"
    );
    assert!(
        lean.1.is_empty(),
        "keep-regions-only thresholded the forecasts"
    );
    assert_eq!(
        plain.2, plain.1,
        "without dilation the keep regions are the forecasts"
    );
    assert_eq!(dilated.0, plain.0, "the current mask changed");
    assert_eq!(dilated.1, plain.1, "the forecast masks changed");
    for (k, (future, region)) in plain.1.iter().zip(&dilated.2).enumerate() {
        let count = |mask: &[bool]| mask.iter().filter(|&&on| on).count();
        assert!(
            count(future) > 0 && count(region) > 0 && region != future,
            "horizon {k}: {} pixels forecast, {} kept",
            count(future),
            count(region)
        );
        assert!(
            *region == expected[k],
            "horizon {k}: not the dilated region"
        );
    }
}
