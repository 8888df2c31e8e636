//! NumPy (the training code's reader) must load a written sequence with the documented dtypes
//! and shapes, and a NumPy-written `.npz` must load here.

use std::path::{Path, PathBuf};
use std::process::Command;

use evgate_core::{Event, SensorSize};
use evgate_io::LabelledSequence;

/// The training virtual environment first (it is where NumPy is installed for this project),
/// then `$EVGATE_PYTHON`, then `python3` on the PATH.
fn python_with_numpy() -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/training/.venv/bin/python");
    let candidates = [
        std::env::var_os("EVGATE_PYTHON").map(PathBuf::from),
        Some(venv),
        Some(PathBuf::from("python3")),
    ];
    candidates.into_iter().flatten().find(|python| {
        Command::new(python)
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|out| out.status.success())
    })
}

fn sequence() -> LabelledSequence {
    let sensor_size = SensorSize::new(6, 4);
    let pixels = sensor_size.pixels();
    LabelledSequence {
        events: (0..50)
            .map(|i| Event::new(i * 100, (i % 6) as u16, (i % 4) as u16, i % 3 == 0))
            .collect(),
        labels: (0..50).map(|i| (i % 3) as u16).collect(),
        sensor_size,
        intrinsics: [[100.0, 0.0, 3.0], [0.0, 100.0, 2.0], [0.0, 0.0, 1.0]],
        gt_ts: vec![0, 10_000],
        masks: (0..2 * pixels).map(|i| (i % 4) as u8).collect(),
        depth: (0..2 * pixels).map(|i| 1.0 + i as f32 * 0.125).collect(),
        ref_ts: vec![50_000],
        horizons_per_reference: 2,
        horizon_us: vec![20_000, 80_000],
        future_mask: (0..2 * pixels).map(|i| (i % 2) as u8).collect(),
        future_flow: (0..4 * pixels).map(|i| i as f32 * 0.25).collect(),
        meta: r#"{"preset":"numpy-check","seed":1}"#.into(),
    }
}

const CHECK: &str = r#"
import json, sys
import numpy as np
d = np.load(sys.argv[1])
expected = {
    "events_t": ("int64", (50,)), "events_xy": ("uint16", (50, 2)), "events_p": ("uint8", (50,)),
    "events_label": ("uint16", (50,)), "resolution": ("int64", (2,)), "K": ("float64", (3, 3)),
    "gt_ts": ("int64", (2,)), "mask": ("uint8", (2, 4, 6)), "depth": ("float16", (2, 4, 6)),
    "ref_ts": ("int64", (1,)), "horizon_us": ("int64", (1, 2)),
    "future_mask": ("uint8", (1, 2, 4, 6)), "future_flow": ("float16", (1, 2, 4, 6, 2)),
}
for key, (dtype, shape) in expected.items():
    a = d[key]
    assert str(a.dtype) == dtype and a.shape == shape, (key, a.dtype, a.shape)
assert list(d["resolution"]) == [6, 4]
assert d["events_xy"][7].tolist() == [1, 3]
assert float(d["depth"][1, 0, 1]) == 1.0 + 25 * 0.125
assert float(d["future_flow"][0, 1, 3, 5, 1]) == (((1 * 4 + 3) * 6 + 5) * 2 + 1) * 0.25
assert json.loads(bytes(d["meta"]).decode())["preset"] == "numpy-check"
np.savez_compressed(sys.argv[2], **{k: d[k] for k in d.files})
print("numpy", np.__version__, "read", len(d.files), "arrays")
"#;

#[test]
fn numpy_loads_documented_dtypes_and_shapes_and_writes_back() {
    let Some(python) = python_with_numpy() else {
        eprintln!(
            "skipped: no python with numpy (tried $EVGATE_PYTHON, models/training/.venv/bin/python, python3)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let written = dir.path().join("rust.npz");
    let rewritten = dir.path().join("numpy.npz");
    let original = sequence();
    original.write(&written).unwrap();
    let out = Command::new(&python)
        .arg("-c")
        .arg(CHECK)
        .arg(&written)
        .arg(&rewritten)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{} failed: {}",
        python.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());
    assert_eq!(LabelledSequence::read(&rewritten).unwrap(), original);
}
