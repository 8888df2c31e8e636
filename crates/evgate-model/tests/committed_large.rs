//! The committed L network (`models/evgate-L.onnx`, trained on a leased GPU) loads through the
//! same runtime as S and honours the contract: its metadata, state shapes and outputs.

use std::path::PathBuf;

use evgate_model::{ModelRuntime, ModelSize, RuntimeOptions};

const COMMITTED_LARGE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/evgate-L.onnx");

#[test]
fn the_committed_large_model_is_the_papers_width_and_forecasts_every_horizon() {
    let path = PathBuf::from(COMMITTED_LARGE);
    assert!(path.is_file(), "models/evgate-L.onnx is missing");
    let mut runtime = ModelRuntime::load(&path, RuntimeOptions::default()).unwrap();
    let metadata = runtime.metadata().clone();
    assert_eq!(metadata.model_size, ModelSize::Large);
    assert_eq!(metadata.base_channels, 64);
    assert_eq!(metadata.state_channels, [64, 128, 256, 512]);
    assert!(
        metadata.train_steps > 0,
        "an untrained export was committed"
    );
    let size = runtime.input_size();
    assert_eq!((size.width, size.height), (352, 272));
    // A moving square's events: the forecast must exist for each horizon and be finite.
    let plane = size.pixels();
    let mut voxel = vec![0.0f32; 2 * plane];
    for y in 120..150 {
        for x in 160..164 {
            voxel[y * usize::from(size.width) + x] = 2.0;
            voxel[plane + y * usize::from(size.width) + x + 3] = -2.0;
        }
    }
    let horizons = [25.0, 100.0];
    let output = runtime.forecast(&voxel, &horizons).unwrap();
    assert_eq!(output.future_mask_logits().count(), horizons.len());
    assert!(output.mask_logits().iter().all(|v| v.is_finite()));
    assert!(output
        .future_mask_logits()
        .all(|f| f.len() == plane && f.iter().all(|v| v.is_finite())));
}
