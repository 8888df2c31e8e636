//! The helper thread that inflates an EVIMO `.npz` member ends with its reader. Found by the
//! `evimo_npz` fuzz target as a leak: the detached helper went on inflating after the reader was
//! dropped. Alone in its test binary, so that no other test's threads change the count.

use evgate_io::npz::{NpzCompression, NpzWriter};

fn threads_of_this_process() -> usize {
    std::fs::read_dir("/proc/self/task").unwrap().count()
}

#[test]
fn dropping_a_reader_ends_its_helper_thread() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.npz");
    // Far more inflated blocks than the helper may hold in flight, so it is still working when
    // the reader goes.
    let rows: Vec<f64> = (0..400_000)
        .flat_map(|i| {
            [
                i as f64 * 1e-6,
                (i % 300) as f64,
                (i % 200) as f64,
                (i % 2) as f64,
            ]
        })
        .collect();
    let mut npz = NpzWriter::create(&path, NpzCompression::Deflated).unwrap();
    npz.add("events", &[400_000, 4], &rows).unwrap();
    npz.finish().unwrap();

    let before = threads_of_this_process();
    let options = evgate_io::OpenOptions {
        sensor_size: Some(evgate_core::SensorSize::new(300, 200)),
        ..Default::default()
    };
    let mut reader = evgate_io::open_with(&path, &options).unwrap();
    let mut chunk = Vec::new();
    assert!(reader.read_chunk(&mut chunk).unwrap() > 0);
    assert!(
        threads_of_this_process() > before,
        "no helper thread to check"
    );
    drop(reader);
    assert_eq!(threads_of_this_process(), before);
}
