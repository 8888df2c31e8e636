//! The real ingest and gate binaries under failures: crashes, restarts and stuck consumers.
//! Every wait is bounded; a process still running at the end of a test is killed.

use std::time::{Duration, Instant};

use evgate_core::Event;
use evgate_e2e::{start_service, u64_at, unique_names, wait_until, Process};
use evgate_ipc::{
    create_node, BatchHeader, LatestSubscriber, PipelineNames, PipelineStats, Qos, SlicePublisher,
    SliceSubscriber, Stream,
};

const TIMEOUT: Duration = Duration::from_secs(90);

fn start_gate(names: &PipelineNames, extra: &[&str]) -> Process {
    start_service("evgate-gate", names, &[&["--json"], extra].concat()).unwrap()
}

fn start_ingest(names: &PipelineNames, sim_seconds: &str, extra: &[&str]) -> Process {
    let fast_simulation = [
        "--json",
        "--fast",
        "--sim-duration-s",
        sim_seconds,
        "--wait-for-subscribers",
        "1",
    ];
    start_service(
        "evgate-ingest",
        names,
        &[&fast_simulation[..], extra].concat(),
    )
    .unwrap()
}

/// Counts the subscribers of the events stream through a publisher of our own.
fn events_probe(
    node: &evgate_ipc::Node,
    names: &PipelineNames,
) -> SlicePublisher<Event, BatchHeader> {
    SlicePublisher::open(node, names, Stream::Events, &Qos::default()).unwrap()
}

fn wait_for_stats(
    stats: &LatestSubscriber<PipelineStats>,
    what: &str,
    mut accept: impl FnMut(&PipelineStats) -> bool,
) {
    wait_until(what, TIMEOUT, || {
        stats.latest().unwrap().is_some_and(|s| accept(&s))
    })
    .unwrap();
}

#[test]
fn every_simulated_event_is_accounted_for_from_ingest_to_gate() {
    let names = unique_names("account");
    let mut gate = start_gate(&names, &["--exit-at-end-of-stream"]);
    let mut ingest = start_ingest(&names, "0.1", &[]);
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    let published = u64_at(&ingest_summary, "/events-published");
    assert!(
        published > 1_000,
        "the simulated camera produced only {published} events"
    );
    assert_eq!(u64_at(&gate_summary, "/stats/input-events"), published);
    assert_eq!(u64_at(&gate_summary, "/stats/dropped-events"), 0);
    assert_eq!(
        u64_at(&gate_summary, "/stats/input-batches"),
        u64_at(&ingest_summary, "/batches-published")
    );
    assert_eq!(gate_summary["balanced"], true);
}

#[test]
fn killing_the_gate_never_blocks_the_ingest() {
    let names = unique_names("killgate");
    let node = create_node("killgate-test").unwrap();
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let mut gate = start_gate(&names, &["--stats-interval-ms", "10"]);
    // Block (the default) with a short timeout: a dead reader costs at most one timeout.
    let mut ingest = start_ingest(&names, "0.6", &["--block-timeout-ms", "200"]);
    wait_for_stats(&stats, "the gate gating its first events", |s| {
        s.input_events > 0
    });
    gate.signal(libc::SIGKILL);
    let killed_at = Instant::now();
    let summary = ingest.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "end-of-stream");
    assert!(u64_at(&summary, "/events-published") > 0);
    // The ingest went on without its reader: it finished, bounded by the watchdog above.
    assert!(!gate.is_running());
    eprintln!(
        "ingest finished {:?} after the gate was killed",
        killed_at.elapsed()
    );
}

#[test]
fn a_stuck_consumer_never_blocks_the_gate_and_its_losses_are_counted() {
    for (overflow, extra) in [
        ("drop-and-count", vec![]),
        ("block", vec!["--block-timeout-ms", "5"]),
    ] {
        let names = unique_names("stuck");
        let node = create_node("stuck-test").unwrap();
        // Subscribed, never read: its one-sample buffer is full after the first batch.
        let stuck = SliceSubscriber::<Event, BatchHeader>::open(
            &node,
            &names,
            Stream::Kept,
            &Qos {
                buffer_size: 1,
                ..Qos::default()
            },
        )
        .unwrap();
        let mut args = vec![
            "--exit-at-end-of-stream",
            "--outputs",
            "kept",
            "--overflow",
            overflow,
        ];
        args.extend_from_slice(&extra);
        let mut gate = start_gate(&names, &args);
        let mut ingest = start_ingest(&names, "0.05", &[]);
        let ingest_summary = ingest.summary(TIMEOUT).unwrap();
        let gate_summary = gate.summary(TIMEOUT).unwrap();
        let published = u64_at(&ingest_summary, "/events-published");
        assert_eq!(
            u64_at(&gate_summary, "/stats/input-events"),
            published,
            "overflow {overflow}"
        );
        assert_eq!(
            u64_at(&gate_summary, "/stats/dropped-events"),
            0,
            "overflow {overflow}"
        );
        assert_eq!(gate_summary["balanced"], true, "overflow {overflow}");
        let batches = u64_at(&ingest_summary, "/batches-published");
        assert_eq!(
            u64_at(&gate_summary, "/stats/output-samples-undelivered"),
            batches - 1,
            "overflow {overflow}"
        );
        drop(stuck);
    }
}

#[test]
fn a_crashed_gate_is_cleaned_up_and_its_replacement_serves_a_restarted_ingest() {
    let names = unique_names("crash");
    let node = create_node("crash-test").unwrap();
    let probe = events_probe(&node, &names);
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();

    let mut crashed = start_gate(&names, &[]);
    wait_until("the first gate subscribing", TIMEOUT, || {
        probe.subscriber_count() == 1
    })
    .unwrap();
    // Killed right after its first port, the gate is often in the middle of creating its other
    // services: the replacement must cope with a half-created service too.
    crashed.signal(libc::SIGKILL);
    crashed.wait(TIMEOUT).unwrap();
    // Whatever the crashed gate published must not pass for the replacement's stats.
    stats.latest().unwrap();

    let mut gate = start_gate(
        &names,
        &["--exit-at-end-of-stream", "--stats-interval-ms", "10"],
    );
    wait_for_stats(&stats, "the replacement gate publishing stats", |_| true);
    // The replacement removed the dead gate's ports when it started: one subscriber, not two.
    assert_eq!(probe.subscriber_count(), 1);

    // An ingest that crashes mid-stream, then a fresh one: the gate follows the new stream.
    let mut first = start_ingest(&names, "5", &[]);
    wait_for_stats(&stats, "the gate gating the first stream", |s| {
        s.input_events > 0
    });
    first.signal(libc::SIGKILL);
    first.wait(TIMEOUT).unwrap();
    let mut second = start_ingest(&names, "0.05", &[]);
    let ingest_summary = second.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(
        u64_at(&gate_summary, "/stats/stream-id"),
        u64_at(&ingest_summary, "/stream-id")
    );
    assert_eq!(
        u64_at(&gate_summary, "/stats/input-events"),
        u64_at(&ingest_summary, "/events-published")
    );
    assert_eq!(gate_summary["balanced"], true);
}

/// Issue 15: under a flood the gate's drain loop never returned to its waitset, so SIGTERM
/// was ignored for as long as input kept coming.
#[test]
fn the_gate_ends_on_sigterm_under_a_flood() {
    let names = unique_names("flood");
    let node = create_node("flood-test").unwrap();
    let mut gate = start_gate(&names, &[]);
    let events = SlicePublisher::<Event, BatchHeader>::open(
        &node,
        &names,
        Stream::Events,
        &Qos::with_overflow(evgate_ipc::Overflow::DropAndCount),
    )
    .unwrap();
    wait_until("the gate subscribes", TIMEOUT, || {
        events.subscriber_count() > 0
    })
    .unwrap();
    // Large batches in bursts: each costs the gate a judgement and two copies, the test one
    // copy, so the gate's queue never empties.
    let batch: Vec<Event> = (0..4096).map(|i| Event::new(i, 1, 1, true)).collect();
    let started = Instant::now();
    let mut signalled = false;
    let mut sequence = 0u64;
    while gate.is_running() {
        assert!(
            started.elapsed() < TIMEOUT,
            "the gate still runs {TIMEOUT:?} after SIGTERM under a flood"
        );
        let header = BatchHeader {
            stream_id: 3,
            sequence,
            first_event_index: sequence * batch.len() as u64,
            event_count: batch.len() as u64,
            t_begin_us: 0,
            t_end_us: 4096,
            width: 8,
            height: 8,
            ..Default::default()
        };
        for burst in 0..16 {
            let header = BatchHeader {
                sequence: sequence + burst,
                first_event_index: (sequence + burst) * batch.len() as u64,
                ..header
            };
            events.publish(header, &batch).unwrap();
        }
        sequence += 16;
        if !signalled && started.elapsed() > Duration::from_secs(1) {
            gate.signal(libc::SIGTERM);
            signalled = true;
        }
    }
    let summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "signal");
    assert_eq!(summary["balanced"], true);
}

/// The fault soak's finding: SIGCONT after a SIGSTOP (job control, a debugger, a supervisor
/// pausing a process) cut a service's wait short, and every service took that for SIGINT or
/// SIGTERM and ended the stream in the middle. Paused and continued again and again, the ingest,
/// infer and gate must carry the whole stream to its end.
#[test]
fn services_paused_and_continued_carry_the_whole_stream() {
    let names = unique_names("sigcont");
    let node = create_node("sigcont-test").unwrap();
    let probe = events_probe(&node, &names);
    let model = evgate_e2e::test_model_path();
    let mut gate = start_gate(&names, &["--exit-at-end-of-stream"]);
    let mut infer = start_service(
        "evgate-infer",
        &names,
        &[
            "--model",
            model.to_str().unwrap(),
            "--exit-at-end",
            "--stats-interval-s",
            "0",
        ],
    )
    .unwrap();
    wait_until("the gate and infer subscribing", TIMEOUT, || {
        probe.subscriber_count() == 2
    })
    .unwrap();
    // Paced at real time, so the stream is still running while the services are paused.
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &["--json", "--sim-duration-s", "1.5"],
    )
    .unwrap();
    for round in 0..4 {
        for service in [&mut ingest, &mut infer, &mut gate] {
            service.signal(libc::SIGSTOP);
            std::thread::sleep(Duration::from_millis(20));
            service.signal(libc::SIGCONT);
        }
        std::thread::sleep(Duration::from_millis(50 + 20 * round));
    }
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    let infer_summary = infer.summary(TIMEOUT).unwrap();
    assert_eq!(ingest_summary["ended-by"], "end-of-stream");
    assert_eq!(gate_summary["ended-by"], "end-of-stream");
    let published = u64_at(&ingest_summary, "/events-published");
    assert_eq!(u64_at(&gate_summary, "/stats/input-events"), published);
    assert_eq!(u64_at(&infer_summary, "/events-received"), published);
    assert_eq!(gate_summary["balanced"], true);
}
