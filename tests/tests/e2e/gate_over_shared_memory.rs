//! The real gate binary driven by in-test publishers: known events and known forecast masks in,
//! exact kept and suppressed streams and counters out.

use std::time::Duration;

use evgate_core::{BitMask, Event, SensorSize};
use evgate_e2e::{binary, start_service, u64_at, unique_names, wait_until, Process};
use evgate_ipc::{
    create_node, BatchFlags, BatchHeader, ForecastHeader, LatestSubscriber, PipelineNames,
    PipelineStats, Qos, SlicePublisher, SliceSubscriber, Stream,
};
use iceoryx2::prelude::SemanticString;

const SENSOR: SensorSize = SensorSize::new(32, 16);
const TIMEOUT: Duration = Duration::from_secs(60);

/// Test-side ports of one pipeline.
struct Harness {
    node: evgate_ipc::Node,
    names: PipelineNames,
    events: SlicePublisher<Event, BatchHeader>,
    kept: SliceSubscriber<Event, BatchHeader>,
    suppressed: SliceSubscriber<Event, BatchHeader>,
    stats: LatestSubscriber<PipelineStats>,
    sequence: u64,
    published: u64,
}

impl Harness {
    fn new(test: &str) -> Self {
        let names = unique_names(test);
        let node = create_node(&format!("{test}-harness")).unwrap();
        let events = SlicePublisher::open(&node, &names, Stream::Events, &Qos::default()).unwrap();
        let kept = SliceSubscriber::open(&node, &names, Stream::Kept, &Qos::default()).unwrap();
        let suppressed =
            SliceSubscriber::open(&node, &names, Stream::Suppressed, &Qos::default()).unwrap();
        let stats = LatestSubscriber::open(&node, &names, Stream::Stats).unwrap();
        Self {
            node,
            names,
            events,
            kept,
            suppressed,
            stats,
            sequence: 0,
            published: 0,
        }
    }

    fn forecast_publisher(&self) -> SlicePublisher<u64, ForecastHeader> {
        SlicePublisher::open(&self.node, &self.names, Stream::Forecast, &Qos::default()).unwrap()
    }

    fn start_gate(&self, extra: &[&str]) -> Process {
        let until_end_of_stream = [
            "--exit-at-end-of-stream",
            "--json",
            "--stats-interval-ms",
            "10",
        ];
        let process = start_service(
            "evgate-gate",
            &self.names,
            &[&until_end_of_stream[..], extra].concat(),
        )
        .unwrap();
        wait_until("the gate subscribing to the events", TIMEOUT, || {
            self.events.subscriber_count() == 1
        })
        .unwrap();
        process
    }

    fn publish(&mut self, events: &[Event], flags: u32) {
        let header = self.next_header(events, flags);
        self.events.publish(header, events).unwrap();
    }

    /// The header of the next batch, counted as published.
    fn next_header(&mut self, events: &[Event], flags: u32) -> BatchHeader {
        let header = BatchHeader {
            stream_id: 77,
            sequence: self.sequence,
            first_event_index: self.published,
            event_count: events.len() as u64,
            t_begin_us: events.first().map_or(0, |e| e.t),
            t_end_us: events.last().map_or(0, |e| e.t + 1),
            published_at_monotonic_ns: evgate_ipc::clock::monotonic_ns(),
            width: SENSOR.width,
            height: SENSOR.height,
            flags,
        };
        self.sequence += 1;
        self.published += events.len() as u64;
        header
    }

    fn drain(subscriber: &SliceSubscriber<Event, BatchHeader>) -> Vec<Event> {
        let mut out = Vec::new();
        while let Some(sample) = subscriber.receive().unwrap() {
            out.extend_from_slice(sample.payload());
        }
        out
    }

    /// Waits until the gate has counted `events` input events and returns its stats.
    fn stats_after(&self, events: u64) -> PipelineStats {
        let mut latest = None;
        wait_until(
            "the gate's stats reaching the published events",
            TIMEOUT,
            || {
                if let Some(stats) = self.stats.latest().unwrap() {
                    latest = Some(stats);
                }
                latest.is_some_and(|s| s.input_events == events && s.is_balanced())
            },
        )
        .unwrap();
        latest.unwrap()
    }
}

/// Masks: current = nothing; horizon 1 = left half; horizon 2 = right half.
fn publish_forecast(
    publisher: &SlicePublisher<u64, ForecastHeader>,
    reference_time_us: i64,
    sequence: u64,
) {
    let mut words = BitMask::new(SENSOR).unwrap().as_words().to_vec();
    for left in [true, false] {
        let mut mask = BitMask::new(SENSOR).unwrap();
        for y in 0..SENSOR.height {
            for x in 0..SENSOR.width {
                if (x < SENSOR.width / 2) == left {
                    mask.set(x, y, true).unwrap();
                }
            }
        }
        words.extend_from_slice(mask.as_words());
    }
    let mut header = ForecastHeader {
        sequence,
        source_stream_id: 77,
        reference_time_us,
        window_start_us: reference_time_us - 50_000,
        horizon_count: 2,
        words_per_mask: evgate_core::words_for(SENSOR.pixels()) as u32,
        width: SENSOR.width,
        height: SENSOR.height,
        model_runtime_us: 1234,
        ..Default::default()
    };
    header.horizons_us[..2].copy_from_slice(&[10_000, 20_000]);
    publisher.publish(header, &words).unwrap();
}

/// Events every 100 µs from `start_us`, sweeping the columns.
fn sweep(start_us: i64, count: usize) -> Vec<Event> {
    (0..count)
        .map(|i| {
            Event::new(
                start_us + 100 * i as i64,
                (i % SENSOR.width as usize) as u16,
                (i % 7) as u16,
                i % 2 == 0,
            )
        })
        .collect()
}

/// The events `publish_forecast`'s masks keep: mask 1 (left half) judges d < 15 ms, mask 2
/// (right half) up to 25 ms.
fn kept_by_the_forecast(events: &[Event], reference: i64) -> Vec<Event> {
    events
        .iter()
        .copied()
        .filter(|e| {
            let d = e.t - reference;
            let left = e.x < SENSOR.width / 2;
            (d < 15_000 && left) || ((15_000..=25_000).contains(&d) && !left)
        })
        .collect()
}

#[test]
fn a_busy_polling_pinned_gate_splits_exactly_and_stops_on_sigterm() {
    let mut harness = Harness::new("busy-poll");
    let forecasts = harness.forecast_publisher();
    let mut gate =
        harness.start_gate(&["--no-forecast", "drop", "--wait", "busy-poll", "--cpu", "0"]);
    wait_until("the gate subscribing to forecasts", TIMEOUT, || {
        forecasts.subscriber_count() == 1
    })
    .unwrap();
    let reference = 1_000_000;
    publish_forecast(&forecasts, reference, 0);
    let events = sweep(reference, 300);
    for batch in events.chunks(50) {
        harness.publish(batch, 0);
    }
    harness.stats_after(300);
    let kept = Harness::drain(&harness.kept);
    let suppressed = Harness::drain(&harness.suppressed);
    assert_eq!(kept, kept_by_the_forecast(&events, reference));
    assert_eq!(kept.len() + suppressed.len(), 300);
    // No end of stream: only the signal ends a busy-polling gate here.
    gate.signal(libc::SIGTERM);
    let summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "signal");
    assert_eq!(summary["balanced"], true);
    assert_eq!(u64_at(&summary, "/stats/input-events"), 300);
    assert_eq!(u64_at(&summary, "/stats/kept-events"), kept.len() as u64);
}

#[test]
fn forecast_masks_split_events_exactly_and_every_event_is_accounted_for() {
    let mut harness = Harness::new("split");
    let forecasts = harness.forecast_publisher();
    let mut gate = harness.start_gate(&["--no-forecast", "drop"]);
    wait_until("the gate subscribing to forecasts", TIMEOUT, || {
        forecasts.subscriber_count() == 1
    })
    .unwrap();

    let reference = 1_000_000;
    publish_forecast(&forecasts, reference, 0);
    // d = 0 .. 29.9 ms: mask 1 judges d < 15 ms, mask 2 up to 25 ms, the rest is unjudged.
    let events = sweep(reference, 300);
    let before = sweep(reference - 5_000, 10); // before the forecast: unjudged
    harness.publish(&before, 0);
    harness.publish(&events[..150], 0);
    harness.publish(&events[150..], 0);
    harness.stats_after(310);
    // Read the outputs while the gate lives: samples are in its shared memory.
    let kept = Harness::drain(&harness.kept);
    let suppressed = Harness::drain(&harness.suppressed);
    harness.publish(&[], BatchFlags::END_OF_STREAM);
    let summary = gate.summary(TIMEOUT).unwrap();

    let expected_kept = kept_by_the_forecast(&events, reference);
    assert_eq!(kept, expected_kept);
    assert_eq!(kept.len() + suppressed.len(), 310);
    let unjudged =
        before.len() as u64 + events.iter().filter(|e| e.t - reference > 25_000).count() as u64;
    assert_eq!(u64_at(&summary, "/stats/input-events"), 310);
    assert_eq!(
        u64_at(&summary, "/stats/kept-events"),
        expected_kept.len() as u64
    );
    assert_eq!(u64_at(&summary, "/stats/unjudged-dropped-events"), unjudged);
    assert_eq!(
        u64_at(&summary, "/stats/suppressed-events"),
        310 - unjudged - expected_kept.len() as u64
    );
    assert_eq!(u64_at(&summary, "/stats/forecasts-received"), 1);
    assert_eq!(summary["balanced"], true);
}

#[test]
fn gate_falls_back_to_its_policy_when_forecasts_stop_and_resumes_when_they_return() {
    let mut harness = Harness::new("resume");
    let mut gate = harness.start_gate(&["--no-forecast", "pass"]);

    // Phase 1: forecasts flow.
    let forecasts = harness.forecast_publisher();
    wait_until("the gate subscribing to forecasts", TIMEOUT, || {
        forecasts.subscriber_count() == 1
    })
    .unwrap();
    publish_forecast(&forecasts, 1_000_000, 0);
    harness.publish(&sweep(1_000_000, 100), 0);
    let phase1 = harness.stats_after(100);
    assert_eq!(phase1.kept_events + phase1.suppressed_events, 100);

    // Phase 2: the forecast publisher is gone (inference stopped); later events pass unjudged.
    drop(forecasts);
    harness.publish(&sweep(2_000_000, 100), 0);
    let phase2 = harness.stats_after(200);
    assert_eq!(phase2.unjudged_passed_events, 100);
    assert!(
        gate.is_running(),
        "the gate must keep running without forecasts"
    );

    // Phase 3: inference is back with fresh forecasts; events are judged again.
    let forecasts = harness.forecast_publisher();
    wait_until("the gate reconnecting to forecasts", TIMEOUT, || {
        forecasts.subscriber_count() == 1
    })
    .unwrap();
    publish_forecast(&forecasts, 3_000_000, 1);
    harness.publish(&sweep(3_000_000, 100), 0);
    let phase3 = harness.stats_after(300);
    assert_eq!(phase3.kept_events + phase3.suppressed_events, 200);
    assert_eq!(phase3.unjudged_passed_events, 100);

    harness.publish(&[], BatchFlags::END_OF_STREAM);
    let summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(summary["balanced"], true);
    assert_eq!(u64_at(&summary, "/stats/forecasts-received"), 2);
}

/// An iceoryx2 0.10 listener can lose every notification after a race with its notifier
/// (`evgate_ipc::MISSED_WAKEUP_POLL`): the gate must still read each batch. Its batches come
/// from a publisher that never notifies, the worst case of that race.
#[test]
fn a_gate_reads_batches_whose_notifications_never_come() {
    let mut harness = Harness::new("silent");
    let mut gate = harness.start_gate(&["--no-forecast", "pass"]);
    let service = harness
        .node
        .service_builder(&harness.names.service(Stream::Events).unwrap())
        .publish_subscribe::<[Event]>()
        .user_header::<BatchHeader>()
        .open()
        .unwrap();
    let silent = service
        .publisher_builder()
        .initial_max_slice_len(100)
        .create()
        .unwrap();
    let mut publish_silently = |events: &[Event], flags: u32| {
        let header = harness.next_header(events, flags);
        let mut sample = silent.loan_slice_uninit(events.len()).unwrap();
        *sample.user_header_mut() = header;
        sample.write_from_slice(events).send().unwrap();
    };
    for batch in sweep(1_000_000, 300).chunks(100) {
        publish_silently(batch, 0);
    }
    publish_silently(&[], BatchFlags::END_OF_STREAM);

    let summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "end-of-stream");
    assert_eq!(u64_at(&summary, "/stats/input-events"), 300);
    assert_eq!(u64_at(&summary, "/stats/unjudged-passed-events"), 300);
    assert_eq!(summary["balanced"], true);
}

/// A `config/iceoryx2.toml` in the working directory, which iceoryx2 on its defaults loads first,
/// must not move a service to a root another user chose: evgate's services use evgate's own
/// configuration (per-user root), say nothing of config files, and still meet their peers.
#[test]
fn services_ignore_an_iceoryx2_config_planted_in_their_working_directory() {
    let planted = tempfile::tempdir().unwrap();
    let decoy_root = planted.path().join("decoy-root");
    let config_file = planted.path().join("config/iceoryx2.toml");
    std::fs::create_dir(config_file.parent().unwrap()).unwrap();
    std::fs::write(
        &config_file,
        format!(
            "[global]\nroot-path = \"{}/\"\nprefix = \"planted_\"\n",
            decoy_root.display()
        ),
    )
    .unwrap();
    // The plant is one iceoryx2 itself would honour.
    let honoured = iceoryx2::config::Config::from_file(
        &iceoryx2::prelude::FilePath::new(config_file.to_str().unwrap().as_bytes()).unwrap(),
    )
    .unwrap();
    assert_eq!(honoured.global.prefix.to_string(), "planted_");

    let names = unique_names("planted-config");
    let node = create_node("planted-config-harness").unwrap();
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let stderr_path = planted.path().join("gate.stderr");
    let stderr = std::fs::File::create(&stderr_path).unwrap();
    let mut gate = Process::start_with(
        &binary("evgate-gate").unwrap(),
        &[
            "--domain",
            &names.domain,
            "--camera",
            &names.camera,
            "--stats-interval-ms",
            "10",
        ],
        |command| {
            command
                .current_dir(planted.path())
                .env("RUST_LOG", "info")
                .stderr(stderr);
        },
    )
    .unwrap();
    wait_until("the gate's stats in evgate's own root", TIMEOUT, || {
        stats.latest().unwrap().is_some()
    })
    .unwrap();
    gate.signal(libc::SIGTERM);
    let (status, _) = gate.wait(TIMEOUT).unwrap();
    assert!(status.success(), "gate: {status}");

    assert!(
        !decoy_root.exists(),
        "the gate created the planted root {}",
        decoy_root.display()
    );
    let log = std::fs::read_to_string(&stderr_path).unwrap();
    assert!(
        !log.to_lowercase().contains("config file"),
        "the gate looked for iceoryx2 config files:\n{log}"
    );
}
