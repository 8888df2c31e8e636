//! The real `evgate-infer` binary over real shared memory: events in, forecasts out, clean
//! exits. Uses the committed `models/evgate-S.onnx` (`EVGATE_TEST_MODEL` overrides the path);
//! the synthetic stream is 346 × 260, the sensor that model is exported for.

use std::process::Command;
use std::time::Duration;

use evgate_core::{words_for, Event, SensorSize};
use evgate_e2e::{binary, start_service, test_model_path, unique_names, wait_until, Process};
use evgate_ipc::{
    create_node, BatchFlags, BatchHeader, ForecastHeader, PipelineNames, Qos, SlicePublisher,
    SliceSubscriber, Stream, MAX_HORIZONS,
};

const SENSOR: SensorSize = SensorSize::new(346, 260);
const BATCH_US: i64 = 10_000;
const TIMEOUT: Duration = Duration::from_secs(60);

/// `evgate-infer` with the test model on one thread, and `extra` flags.
fn start_infer(names: &PipelineNames, extra: &[&str]) -> Process {
    let model = test_model_path();
    let mut args = vec!["--model", model.to_str().unwrap(), "--threads", "1"];
    args.extend_from_slice(extra);
    start_service("evgate-infer", names, &args).unwrap()
}

fn wait_for_subscriber(publisher: &SlicePublisher<Event, BatchHeader>) {
    wait_until("evgate-infer subscribing to the events", TIMEOUT, || {
        publisher.subscriber_count() > 0
    })
    .unwrap();
}

/// A 20 × 20 block of events moving right 1 px per ms over a sparse background.
fn batch_events(t_begin: i64) -> Vec<Event> {
    let mut events = Vec::new();
    for step in 0..BATCH_US / 1000 {
        let t = t_begin + step * 1000;
        let left = (t / 1000) as u16 % 300;
        for dy in 0..20u16 {
            for dx in [0u16, 19] {
                events.push(Event::new(t, left + dx, 100 + dy, dx == 0));
            }
        }
        events.push(Event::new(
            t,
            (t / 997 % 346) as u16,
            (t / 389 % 260) as u16,
            true,
        ));
    }
    events
}

#[test]
fn windows_become_forecasts_and_the_service_exits_at_the_end_of_the_stream() {
    forecasts_until_the_end_of_the_stream("event", &[]);
}

#[test]
fn a_busy_polling_pinned_service_forecasts_every_window_too() {
    forecasts_until_the_end_of_the_stream("busy-poll", &["--wait", "busy-poll", "--cpu", "0"]);
}

fn forecasts_until_the_end_of_the_stream(name: &str, extra: &[&str]) {
    let names = unique_names(&format!("infer-{name}"));
    let node = create_node("infer-e2e-test").unwrap();
    let publisher =
        SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &Qos::default())
            .unwrap();
    let forecasts = SliceSubscriber::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )
    .unwrap();
    let stats_file = tempfile::NamedTempFile::new().unwrap();
    let mut args = vec![
        "--exit-at-end",
        "--stats-json",
        stats_file.path().to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let mut child = start_infer(&names, &args);
    wait_for_subscriber(&publisher);

    let batches = 30;
    let mut received = Vec::new();
    let mut receive_forecasts = || {
        while let Some(sample) = forecasts.receive().unwrap() {
            received.push((*sample.user_header(), sample.payload().to_vec()));
        }
    };
    let mut first_event_index = 0;
    for sequence in 0..batches {
        let t_begin = sequence as i64 * BATCH_US;
        let events = batch_events(t_begin);
        let header = BatchHeader {
            stream_id: 42,
            sequence,
            first_event_index,
            event_count: events.len() as u64,
            t_begin_us: t_begin,
            t_end_us: t_begin + BATCH_US,
            width: SENSOR.width,
            height: SENSOR.height,
            flags: if sequence == batches - 1 {
                BatchFlags::END_OF_STREAM
            } else {
                0
            },
            ..Default::default()
        };
        first_event_index += events.len() as u64;
        publisher.publish(header, &events).unwrap();
        // Real time, so that the model keeps up on a loaded machine most of the time.
        std::thread::sleep(Duration::from_millis(10));
        receive_forecasts();
    }
    // The forecasts vanish with their publisher, so keep reading until the service exits.
    wait_until(
        "evgate-infer exiting at the end of the stream",
        TIMEOUT,
        || {
            receive_forecasts();
            !child.is_running()
        },
    )
    .unwrap();
    let report = child.summary(TIMEOUT).unwrap();

    // Windows end at 50, 100, … 250 ms: the 300 ms one never closes because the stream ends
    // at 300 ms exclusive.
    assert_eq!(report["windows-closed"], 5, "{report}");
    let published = report["forecasts-published"].as_u64().unwrap();
    let skipped = report["windows-skipped-busy"].as_u64().unwrap();
    assert_eq!(published + skipped, 5, "{report}");
    assert_eq!(report["events-received"], first_event_index, "{report}");
    assert_eq!(report["gaps-detected"], 0, "{report}");
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(stats_file.path()).unwrap()).unwrap();
    assert_eq!(written["forecasts-published"], published);

    // Only the last forecast can be published so close to the exit that it is gone before it
    // is read.
    assert!(
        !received.is_empty() && received.len() as u64 + 1 >= published,
        "received {} of {published} forecasts",
        received.len()
    );
    let words = words_for(SENSOR.pixels());
    for (index, (header, payload)) in received.iter().enumerate() {
        header.validate(words, payload.len()).unwrap();
        assert_eq!(header.sequence, index as u64);
        assert_eq!(header.source_stream_id, 42);
        assert_eq!(header.horizon_count as usize, MAX_HORIZONS);
        assert_eq!(*header.horizons().last().unwrap(), 100_000);
        assert_eq!(header.reference_time_us % 50_000, 0);
        assert_eq!(header.window_start_us, header.reference_time_us - 50_000);
        assert!(header.model_runtime_us > 0);
        assert_eq!((header.width, header.height), (SENSOR.width, SENSOR.height));
    }
}

#[test]
fn sigint_stops_the_service_cleanly_with_its_stats() {
    let report = stops_cleanly_on_sigint("event", &[]);
    // The model's own rule (that it is applied is checked against `evgate eval` by
    // run_command's lock-step test).
    for key in ["threshold-logit", "keep-threshold-logit"] {
        assert!(report[key].as_f64().is_some_and(f64::is_finite), "{report}");
    }
    assert!(
        report["keep-dilation-px"]
            .as_u64()
            .is_some_and(|px| px <= 16),
        "{report}"
    );
}

#[test]
fn sigint_stops_a_busy_polling_service_cleanly_too() {
    stops_cleanly_on_sigint("busy-poll", &["--wait", "busy-poll"]);
}

#[test]
fn the_mask_rule_flags_override_the_models() {
    let report = stops_cleanly_on_sigint(
        "mask-rule",
        &[
            "--threshold-logit",
            "-0.5",
            "--keep-threshold-logit",
            "1.25",
            "--keep-dilation-px",
            "3",
        ],
    );
    assert_eq!(report["threshold-logit"], -0.5, "{report}");
    assert_eq!(report["keep-threshold-logit"], 1.25, "{report}");
    assert_eq!(report["keep-dilation-px"], 3, "{report}");
}

fn stops_cleanly_on_sigint(name: &str, extra: &[&str]) -> serde_json::Value {
    let names = unique_names(&format!("infer-sigint-{name}"));
    let node = create_node("infer-sigint-test").unwrap();
    let publisher =
        SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &Qos::default())
            .unwrap();
    let mut child = start_infer(&names, extra);
    wait_for_subscriber(&publisher);
    child.signal(libc::SIGINT);
    let report = child.summary(TIMEOUT).unwrap();
    assert_eq!(report["windows-closed"], 0, "{report}");
    assert_eq!(
        report["model"].as_str(),
        test_model_path().to_str(),
        "{report}"
    );
    assert!(report["inference"]["count"] == 0, "{report}");
    report
}

#[test]
fn bad_settings_fail_with_the_value_at_fault() {
    let missing = std::env::temp_dir().join("evgate-infer-no-such-model.onnx");
    let infer = binary("evgate-infer").unwrap();
    let output = Command::new(&infer)
        .arg("--model")
        .arg(&missing)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains(&missing.display().to_string()), "{stderr}");

    let output = Command::new(&infer)
        .arg("--model")
        .arg(test_model_path())
        .args(["--domain", "infer-bad-horizons", "--horizons-ms", "10,500"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("#1 = 500"), "{stderr}");

    let output = Command::new(&infer)
        .args(["--keep-dilation-px", "17"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("--keep-dilation-px") && stderr.contains("17") && stderr.contains("0..=16"),
        "{stderr}"
    );
}
