//! A library path that does not exist is a load error naming it. This is its own test binary
//! because ONNX Runtime can be loaded only once per process.

use evgate_model::{ModelRuntime, RuntimeOptions};

#[test]
fn a_missing_runtime_library_is_an_error_naming_the_path() {
    let directory = tempfile::tempdir().unwrap();
    let model = directory.path().join("model.onnx");
    std::fs::write(&model, b"the library is loaded before the model is parsed").unwrap();
    let library = directory.path().join("missing/libonnxruntime.so");
    let options = RuntimeOptions {
        library: Some(library.clone()),
        ..RuntimeOptions::default()
    };
    let error = ModelRuntime::load(&model, options).err().unwrap();
    let message = error.to_string();
    assert!(
        message.contains(&library.display().to_string()),
        "{message}"
    );
    assert!(
        message.contains("cannot load the onnx runtime library"),
        "{message}"
    );
}
