//! AEDAT 4 over the network against the real peer, iniVation's dv-processing 2.0.4 from PyPI
//! (tests/dv/setup.sh makes its environment): its NetworkWriter serves a known pattern of
//! events and evgate-ingest publishes exactly those, across a reconnection; its NetworkReader
//! reads the kept events evgate-gate serves.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use evgate_core::Event;
use evgate_e2e::{
    binary, free_local_address, metric_sample, scrape_metrics, start_service,
    start_simulated_burst, test_model_path, u64_at, unique_names, wait_until, workspace_root,
    Process,
};
use evgate_ipc::{create_node, BatchHeader, PipelineNames, Qos, SliceSubscriber, Stream};

const TIMEOUT: Duration = Duration::from_secs(90);
/// tests/dv/serve_events.py's first event time.
const FIRST_T: i64 = 1_700_000_000_000_000;
const WIDTH: u16 = 320;
const HEIGHT: u16 = 240;

/// Event `i` of the served pattern.
fn served(i: u64) -> Event {
    Event::new(
        FIRST_T + 10 * i as i64,
        ((7 * i) % u64::from(WIDTH)) as u16,
        ((13 * i) % u64::from(HEIGHT)) as u16,
        i.is_multiple_of(2),
    )
}

fn dv_python() -> &'static str {
    static PYTHON: OnceLock<String> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let setup = Command::new(workspace_root().join("tests/dv/setup.sh"))
            .output()
            .expect("tests/dv/setup.sh runs");
        assert!(
            setup.status.success(),
            "tests/dv/setup.sh failed: {}",
            String::from_utf8_lossy(&setup.stderr)
        );
        String::from_utf8(setup.stdout).unwrap().trim().to_owned()
    })
}

/// Starts tests/dv/serve_events.py on `endpoint_args` for events `first..first + count` and
/// waits until it listens.
fn serve(endpoint_args: &[&str], first: u64, count: u64) -> Process {
    let ready = tempfile::NamedTempFile::new().unwrap().into_temp_path();
    let ready_path: PathBuf = ready.to_path_buf();
    std::fs::remove_file(&ready_path).unwrap();
    let script = workspace_root().join("tests/dv/serve_events.py");
    let (first, count) = (first.to_string(), count.to_string());
    let mut args = vec![script.to_str().unwrap()];
    args.extend_from_slice(endpoint_args);
    args.extend([
        "--first",
        &first,
        "--count",
        &count,
        "--ready-file",
        ready_path.to_str().unwrap(),
    ]);
    let server = Process::start(Path::new(dv_python()), &args).unwrap();
    wait_until("the dv-processing server listening", TIMEOUT, || {
        ready_path.exists()
    })
    .unwrap();
    server
}

/// A free TCP port on the loopback.
fn free_port() -> u16 {
    free_local_address()
        .rsplit_once(':')
        .and_then(|(_, port)| port.parse().ok())
        .expect("an address with a port")
}

/// Reads the pipeline's events stream, checking each event against the served pattern.
struct PatternReader {
    events: SliceSubscriber<Event, BatchHeader>,
    received: u64,
}

impl PatternReader {
    fn open(names: &PipelineNames) -> Self {
        let node = Box::leak(Box::new(create_node("dv-network-test").unwrap()));
        Self {
            events: SliceSubscriber::open(node, names, Stream::Events, &Qos::default()).unwrap(),
            received: 0,
        }
    }

    fn drain(&mut self) {
        while let Some(sample) = self.events.receive().unwrap() {
            assert_eq!(sample.user_header().sensor().width, WIDTH);
            assert_eq!(sample.user_header().sensor().height, HEIGHT);
            for event in sample.payload() {
                assert_eq!(*event, served(self.received), "event {}", self.received);
                self.received += 1;
            }
        }
    }

    /// Reads while `server` serves, until it has exited.
    fn read_while_serving(&mut self, server: &mut Process) {
        wait_until("the dv-processing server finishing", TIMEOUT, || {
            self.drain();
            !server.is_running()
        })
        .unwrap();
        server.summary(TIMEOUT).unwrap();
    }

    /// Reads until `expected` events arrived; fails on more.
    fn read_until(&mut self, expected: u64) {
        wait_until(&format!("{expected} events published"), TIMEOUT, || {
            self.drain();
            self.received >= expected
        })
        .unwrap();
        assert_eq!(self.received, expected);
    }
}

/// `evgate-ingest` on the stream at `endpoint`, publishing once the test's reader subscribed.
fn start_network_ingest(names: &PipelineNames, endpoint: &str) -> Process {
    start_service(
        "evgate-ingest",
        names,
        &["--input", endpoint, "--wait-for-subscribers", "1", "--json"],
    )
    .unwrap()
}

#[test]
fn dv_processing_events_are_published_exactly_across_a_reconnection() {
    let port = free_port().to_string();
    let endpoint = format!("tcp://127.0.0.1:{port}");
    let names = unique_names("dv-tcp");
    let mut reader = PatternReader::open(&names);
    let mut first_session = serve(&["--tcp", &port], 0, 3000);
    let mut ingest = start_network_ingest(&names, &endpoint);
    reader.read_while_serving(&mut first_session);
    // The peer dropped every client; the ingest reconnects to the next server on the port.
    let mut second_session = serve(&["--tcp", &port], 3000, 2000);
    reader.read_while_serving(&mut second_session);
    reader.read_until(5000);
    ingest.signal(libc::SIGTERM);
    let summary = ingest.summary(TIMEOUT).unwrap();
    assert_eq!(u64_at(&summary, "/events-published"), 5000);
    assert_eq!(summary["source"], endpoint);
}

#[test]
fn a_unix_socket_stream_is_read_too() {
    let socket = tempfile::tempdir().unwrap();
    let socket = socket.path().join("dv.sock");
    let endpoint = format!("unix://{}", socket.display());
    let names = unique_names("dv-unix");
    let mut reader = PatternReader::open(&names);
    let mut server = serve(&["--unix", socket.to_str().unwrap()], 0, 1000);
    let mut ingest = start_network_ingest(&names, &endpoint);
    reader.read_while_serving(&mut server);
    reader.read_until(1000);
    ingest.signal(libc::SIGTERM);
    assert_eq!(
        u64_at(&ingest.summary(TIMEOUT).unwrap(), "/events-published"),
        1000
    );
}

#[test]
fn evgate_run_gates_a_dv_processing_stream() {
    let port = free_port().to_string();
    let endpoint = format!("tcp://127.0.0.1:{port}");
    let mut server = serve(&["--tcp", &port], 0, 2000);
    let model = test_model_path();
    let mut run = Process::start(
        &binary("evgate").unwrap(),
        &[
            "run",
            "--input",
            &endpoint,
            "--model",
            model.to_str().unwrap(),
            "--duration",
            "4",
            "--serve-kept",
            &format!("tcp://127.0.0.1:{}", free_port()),
            "--json",
        ],
    )
    .unwrap();
    server.summary(TIMEOUT).unwrap();
    let summary = run.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "duration");
    assert_eq!(u64_at(&summary, "/stats/input-events"), 2000);
    // The gate served the kept events (to no client here) and reports it.
    assert_eq!(
        summary["services"]["evgate-gate"]["kept-stream-batches-not-sent"],
        0
    );
}

#[test]
fn a_server_that_is_not_there_is_a_clear_error() {
    let endpoint = format!("tcp://127.0.0.1:{}", free_port());
    let output = Command::new(binary("evgate-ingest").unwrap())
        .args([
            "--input",
            &endpoint,
            "--domain",
            "dv-absent",
            "--camera",
            "cam",
        ])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(
        message.contains("cannot connect to an AEDAT 4 server") && message.contains(&endpoint),
        "{message}"
    );
}

#[test]
fn dv_processing_reads_the_kept_events_the_gate_serves() {
    use evgate_ipc::consumer::{EventBatches, EventStream};

    let names = unique_names("dv-serve");
    let port = free_port().to_string();
    let metrics = free_local_address();
    let node = create_node("dv-serve-test").unwrap();
    let kept = EventBatches::open(&node, &names, EventStream::Kept).unwrap();
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &[
            "--serve-kept",
            &format!("tcp://127.0.0.1:{port}"),
            "--metrics-addr",
            &metrics,
            // This test's own kept subscriber and the network reader must see every batch, on a
            // loaded machine too.
            "--overflow",
            "block",
            "--block-timeout-ms",
            "30000",
            // The reader discards what it has not yet handed out once the gate closes.
            "--serve-kept-linger-ms",
            "10000",
            "--exit-at-end-of-stream",
            "--json",
        ],
    )
    .unwrap();
    let script = workspace_root().join("tests/dv/read_events.py");
    let mut reader = Process::start(
        Path::new(dv_python()),
        &[script.to_str().unwrap(), "--tcp", &port],
    )
    .unwrap();
    // The reader's constructor waits for the header, so the gate's side tells it connected.
    wait_until("the dv-processing reader connecting", TIMEOUT, || {
        scrape_metrics(&metrics).and_then(|text| metric_sample(&text, "evgate_kept_stream_clients"))
            == Some(1.0)
    })
    .unwrap();
    let mut ingest = start_simulated_burst(&names, 1).unwrap();

    let (mut events, mut on, mut sum_t, mut sum_x, mut sum_y) = (0u64, 0u64, 0i64, 0u64, 0u64);
    let mut end_of_stream = false;
    wait_until("the kept stream's end", TIMEOUT, || {
        while let Some(batch) = kept.try_next().unwrap() {
            for event in batch.events() {
                events += 1;
                on += u64::from(event.is_on());
                sum_t += event.t;
                sum_x += u64::from(event.x);
                sum_y += u64::from(event.y);
            }
            end_of_stream |= batch.header().is_end_of_stream();
        }
        end_of_stream
    })
    .unwrap();
    ingest.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    let read = reader.summary(TIMEOUT).unwrap();
    assert!(events > 0);
    assert_eq!(
        events,
        u64_at(&gate_summary, "/stats/kept-events")
            + u64_at(&gate_summary, "/stats/unjudged-passed-events")
    );
    assert_eq!(u64_at(&gate_summary, "/kept-stream-batches-not-sent"), 0);
    // Under --overflow block a slow reader delays the stream instead of losing it.
    assert_eq!(u64_at(&gate_summary, "/kept-stream-clients-dropped"), 0);
    assert_eq!(read["ended-by"], "closed");
    assert_eq!(
        (read["width"].as_u64(), read["height"].as_u64()),
        (Some(346), Some(260))
    );
    assert_eq!(u64_at(&read, "/events"), events);
    assert_eq!(u64_at(&read, "/on-events"), on);
    assert_eq!(read["sum-t"].as_i64(), Some(sum_t));
    assert_eq!(u64_at(&read, "/sum-x"), sum_x);
    assert_eq!(u64_at(&read, "/sum-y"), sum_y);
}
