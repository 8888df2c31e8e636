//! Helpers shared by the end-to-end tests: the service binaries (built on demand next to the
//! test executable), child processes that can never outlive a test, unique pipeline names and
//! a bounded wait for everything that could hang.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{ChildStderr, Command, ExitStatus};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use evgate_ipc::PipelineNames;
use evgate_supervise::{StderrTo, Supervised};

/// Harness failures. Their `Debug` is their message, so `unwrap()` prints the children's report
/// readably.
#[derive(thiserror::Error)]
pub enum HarnessError {
    #[error("cargo build {packages} failed ({status}); see its output above")]
    Build {
        packages: String,
        status: ExitStatus,
    },
    #[error("cannot run {program}: {source}")]
    Spawn {
        program: String,
        source: std::io::Error,
    },
    #[error(transparent)]
    Supervise(#[from] evgate_supervise::SuperviseError),
    #[error("{what} did not happen within {timeout:?}{children}")]
    Timeout {
        what: String,
        timeout: Duration,
        /// [`children_report`] of the test that waited.
        children: String,
    },
    #[error("{binary} printed no JSON summary ({reason}); stdout was: {stdout:?}{report}")]
    Summary {
        binary: String,
        reason: String,
        stdout: String,
        /// The process's exit status and last stderr lines.
        report: String,
    },
}

impl std::fmt::Debug for HarnessError {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Display::fmt(self, formatter)
    }
}

/// The workspace root (the parent of this package).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lies inside the workspace")
        .to_path_buf()
}

/// The exported network the tests run: `EVGATE_TEST_MODEL`, or else the committed
/// `models/evgate-S.onnx`; a missing file fails the test that asked.
pub fn test_model_path() -> PathBuf {
    let path = std::env::var_os("EVGATE_TEST_MODEL")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("models/evgate-S.onnx"));
    assert!(
        path.is_file(),
        "these tests need the exported network {} (committed as models/evgate-S.onnx; \
         EVGATE_TEST_MODEL overrides the path) and it is missing",
        path.display()
    );
    path
}

/// target/<profile>/, where cargo puts the binaries of the profile the tests were built with.
pub fn binary_directory() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable has a path");
    // target/<profile>/deps/<test>-<hash>
    exe.parent()
        .and_then(Path::parent)
        .expect("test executables live in target/<profile>/deps")
        .to_path_buf()
}

/// The packages whose binaries the end-to-end tests start. scripts/test.sh builds exactly this
/// set (same command, same features) before `cargo test`, so the build below finds everything
/// fresh and compiles nothing while tests run: a build started from inside a test would resolve
/// features differently from the test build and compile (and execute) build scripts anew.
pub const SERVICE_PACKAGES: [&str; 4] = ["evgate", "evgate-gate", "evgate-infer", "evgate-ingest"];

/// The package of the Rust examples; scripts/test.sh builds its examples beside the services.
pub const EXAMPLES_PACKAGE: &str = "evgate-examples";

/// Runs `cargo build` with `target_args` in the tests' profile, once per `built` flag per test
/// process (cargo itself skips up-to-date work).
fn build_once(
    built: &'static OnceLock<Mutex<bool>>,
    target_args: &[&str],
) -> Result<(), HarnessError> {
    let mut built = built
        .get_or_init(|| Mutex::new(false))
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if *built {
        return Ok(());
    }
    let mut command = Command::new(env!("CARGO"));
    command
        .current_dir(workspace_root())
        .arg("build")
        .args(target_args);
    if binary_directory()
        .file_name()
        .is_some_and(|name| name == "release")
    {
        command.arg("--release");
    }
    let status = command.status().map_err(|source| HarnessError::Spawn {
        program: "cargo".to_owned(),
        source,
    })?;
    if !status.success() {
        return Err(HarnessError::Build {
            packages: target_args.join(" "),
            status,
        });
    }
    *built = true;
    Ok(())
}

/// Builds the binaries of [`SERVICE_PACKAGES`] with the profile of the tests (once per test
/// process) and returns the path of `binary`.
pub fn binary(binary: &str) -> Result<PathBuf, HarnessError> {
    static BUILT: OnceLock<Mutex<bool>> = OnceLock::new();
    let mut args = vec!["--bins"];
    for package in SERVICE_PACKAGES {
        args.extend(["-p", package]);
    }
    build_once(&BUILT, &args)?;
    Ok(binary_directory().join(binary))
}

/// Builds the examples of [`EXAMPLES_PACKAGE`] with the profile of the tests (once per test
/// process) and returns the path of `example`.
pub fn example(example: &str) -> Result<PathBuf, HarnessError> {
    static BUILT: OnceLock<Mutex<bool>> = OnceLock::new();
    build_once(&BUILT, &["--examples", "-p", EXAMPLES_PACKAGE])?;
    Ok(binary_directory().join("examples").join(example))
}

/// Starts the service binary of `package` (named like the package) on the pipeline `names`,
/// with `args` after the `--domain` and `--camera` that every service takes.
pub fn start_service(
    package: &str,
    names: &PipelineNames,
    args: &[&str],
) -> Result<Process, HarnessError> {
    let program = binary(package)?;
    let pipeline = [
        "--domain",
        names.domain.as_str(),
        "--camera",
        names.camera.as_str(),
    ];
    Process::start(&program, &[&pipeline[..], args].concat())
}

/// Pipeline names no other test (or test run) uses.
pub fn unique_names(test: &str) -> PipelineNames {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.subsec_nanos())
        .unwrap_or(0);
    PipelineNames::new(&format!("e2e-{test}-{}-{nanos}", std::process::id()), "cam")
        .expect("test names are valid")
}

/// Starts `evgate-ingest` publishing 50 ms of the simulated camera as fast as it can, once
/// `subscribers` listen to the events stream, with a JSON summary at the end.
pub fn start_simulated_burst(
    names: &PipelineNames,
    subscribers: usize,
) -> Result<Process, HarnessError> {
    let subscribers = subscribers.to_string();
    start_service(
        "evgate-ingest",
        names,
        &[
            "--json",
            "--fast",
            "--sim-duration-s",
            "0.05",
            "--wait-for-subscribers",
            &subscribers,
        ],
    )
}

/// What [`consume_kept_stream`] returns: the JSON summaries of the consumer, the gate and the
/// ingest.
pub struct ConsumerRun {
    pub consumer: serde_json::Value,
    pub gate: serde_json::Value,
    pub ingest: serde_json::Value,
}

impl ConsumerRun {
    /// Events the gate passed on its kept stream.
    pub fn passed(&self) -> u64 {
        u64_at(&self.gate, "/stats/kept-events")
            + u64_at(&self.gate, "/stats/unjudged-passed-events")
    }
}

/// Runs `consumer` (its arguments built from the pipeline's names) as a reader of a gate's kept
/// stream fed with 50 ms of the simulated camera, the gate started with
/// `--json --exit-at-end-of-stream --overflow block --block-timeout-ms 30000` (a consumer slowed
/// by a loaded machine then delays the gate instead of losing batches); waits until the consumer
/// subscribed before any event flows.
pub fn consume_kept_stream(
    consumer: &Path,
    consumer_args: impl FnOnce(&PipelineNames) -> Vec<String>,
) -> ConsumerRun {
    const TIMEOUT: Duration = Duration::from_secs(90);
    let names = unique_names("consumer");
    let gate_args = [
        "--json",
        "--exit-at-end-of-stream",
        "--overflow",
        "block",
        "--block-timeout-ms",
        "30000",
    ];
    let mut gate = start_service("evgate-gate", &names, &gate_args).unwrap();
    let args = consumer_args(&names);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut consumer = Process::start(consumer, &args).unwrap();
    let node = evgate_ipc::create_node("consumer-probe").unwrap();
    let kept_probe =
        evgate_ipc::SlicePublisher::<evgate_core::Event, evgate_ipc::BatchHeader>::open(
            &node,
            &names,
            evgate_ipc::Stream::Kept,
            &evgate_ipc::Qos::default(),
        )
        .unwrap();
    wait_until("the consumer subscribing", TIMEOUT, || {
        kept_probe.subscriber_count() == 1
    })
    .unwrap();
    let ingest = start_simulated_burst(&names, 1)
        .unwrap()
        .summary(TIMEOUT)
        .unwrap();
    let consumer = consumer.summary(TIMEOUT).unwrap();
    let gate = gate.summary(TIMEOUT).unwrap();
    ConsumerRun {
        consumer,
        gate,
        ingest,
    }
}

/// The body of `GET /metrics` from a service's `--metrics-addr`, or None while nothing answers.
pub fn scrape_metrics(address: &str) -> Option<String> {
    use std::io::Write;
    let mut stream = std::net::TcpStream::connect(address).ok()?;
    write!(stream, "GET /metrics HTTP/1.0\r\nHost: localhost\r\n\r\n").ok()?;
    let mut response = String::new();
    stream.read_to_string(&mut response).ok()?;
    Some(response)
}

/// The value of the sample `name` (no labels) in a scrape.
pub fn metric_sample(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find_map(|line| line.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
}

/// A loopback address nobody listens on now (a service binds it a moment later).
pub fn free_local_address() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("a free loopback port");
    listener.local_addr().expect("a bound address").to_string()
}

/// Polls `condition` every 10 ms until it holds; fails after `timeout`.
pub fn wait_until(
    what: &str,
    timeout: Duration,
    mut condition: impl FnMut() -> bool,
) -> Result<(), HarnessError> {
    let deadline = Instant::now() + timeout;
    while !condition() {
        if Instant::now() >= deadline {
            return Err(HarnessError::Timeout {
                what: what.to_owned(),
                timeout,
                children: children_report(),
            });
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

/// Stderr lines of a child kept for failure messages: enough for an error and its context.
const STDERR_TAIL_LINES: usize = 40;

/// The last stderr lines of a child; `closed` once the pipe reached its end.
#[derive(Default)]
struct StderrTail {
    lines: VecDeque<String>,
    closed: bool,
}

/// A child and what a failure message tells of it.
struct Watched {
    process: Supervised,
    stderr_tail: Arc<Mutex<StderrTail>>,
}

impl Watched {
    fn try_status(&mut self) -> Option<ExitStatus> {
        self.process.try_status().ok().flatten()
    }

    /// `--- name (pid N): state`, then its last stderr lines.
    fn report(&mut self) -> String {
        let state = match self.try_status() {
            Some(status) => {
                // The last lines of an exited child may still be in the pipe (or held open by a
                // grandchild, hence the bound).
                let deadline = Instant::now() + Duration::from_secs(1);
                while !lock(&self.stderr_tail).closed && Instant::now() < deadline {
                    std::thread::sleep(Duration::from_millis(10));
                }
                format!("exited, {status}")
            }
            None => "still running".to_owned(),
        };
        let tail = lock(&self.stderr_tail);
        let mut report = format!(
            "\n--- {} (pid {}): {state}; last {} stderr lines:",
            self.process.name(),
            self.process.pid(),
            tail.lines.len()
        );
        for line in tail.lines.iter() {
            report.push_str("\n    ");
            report.push_str(line);
        }
        report
    }
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

thread_local! {
    /// The children started by this thread, i.e. by one test: tests run in parallel threads and
    /// a failure reports its own children only.
    static STARTED_HERE: RefCell<Vec<Weak<Mutex<Watched>>>> = const { RefCell::new(Vec::new()) };
}

/// Exit status (or "still running") and last stderr lines of every child this thread started
/// and still holds, for failure messages.
pub fn children_report() -> String {
    STARTED_HERE.with(|started| {
        started
            .borrow()
            .iter()
            .filter_map(Weak::upgrade)
            .map(|watched| lock(&watched).report())
            .collect()
    })
}

/// Echoes the child's stderr through `eprintln!` (shown with the output of the test that
/// started it) and keeps its last lines.
fn forward_stderr(name: String, stderr: ChildStderr, tail: Arc<Mutex<StderrTail>>) {
    for line in BufReader::new(stderr).lines() {
        let Ok(line) = line else { break };
        eprintln!("[{name}] {line}");
        let mut tail = lock(&tail);
        if tail.lines.len() == STDERR_TAIL_LINES {
            tail.lines.pop_front();
        }
        tail.lines.push_back(line);
    }
    lock(&tail).closed = true;
}

/// A child process that is killed when dropped (`evgate_supervise`, with no grace), so a failing
/// test leaves nothing running.
pub struct Process {
    pub name: String,
    watched: Arc<Mutex<Watched>>,
}

impl Process {
    /// Starts `program` with `args`; stdout is captured (the JSON summary), stderr is echoed and
    /// its tail kept for failure messages.
    pub fn start(program: &Path, args: &[&str]) -> Result<Self, HarnessError> {
        Self::start_with(program, args, |_| {})
    }

    /// As [`Process::start`], after `adjust` has set up the command (working directory,
    /// environment).
    pub fn start_with(
        program: &Path,
        args: &[&str],
        adjust: impl FnOnce(&mut Command),
    ) -> Result<Self, HarnessError> {
        let mut process =
            Supervised::start(program, args, StderrTo::Pipe, Duration::ZERO, |command| {
                // An error's backtrace would push the error itself out of the kept stderr tail.
                if std::env::var_os("RUST_LIB_BACKTRACE").is_none() {
                    command.env("RUST_LIB_BACKTRACE", "0");
                }
                adjust(command);
            })
            .map_err(|source| HarnessError::Spawn {
                program: program.display().to_string(),
                source: std::io::Error::other(source.to_string()),
            })?;
        let name = process.name().to_owned();
        let stderr_tail = Arc::new(Mutex::new(StderrTail::default()));
        if let Some(stderr) = process.take_stderr() {
            let (label, tail) = (
                format!("{name} {}", process.pid()),
                Arc::clone(&stderr_tail),
            );
            std::thread::spawn(move || forward_stderr(label, stderr, tail));
        }
        let watched = Arc::new(Mutex::new(Watched {
            process,
            stderr_tail,
        }));
        STARTED_HERE.with(|started| {
            let mut started = started.borrow_mut();
            started.retain(|watched| watched.strong_count() > 0);
            started.push(Arc::downgrade(&watched));
        });
        Ok(Self { name, watched })
    }

    pub fn pid(&self) -> u32 {
        lock(&self.watched).process.pid()
    }

    /// Exit status once the process ended.
    pub fn try_status(&mut self) -> Option<ExitStatus> {
        lock(&self.watched).try_status()
    }

    pub fn is_running(&mut self) -> bool {
        self.try_status().is_none()
    }

    /// Sends `signal` (e.g. `libc::SIGKILL` to simulate a crash, `libc::SIGTERM` to stop).
    pub fn signal(&mut self, signal: libc::c_int) {
        let _ = lock(&self.watched).process.signal(signal);
    }

    /// Waits for the exit (at most `timeout`) and returns the status and the stdout.
    pub fn wait(&mut self, timeout: Duration) -> Result<(ExitStatus, String), HarnessError> {
        let what = format!("exit of {} (pid {})", self.name, self.pid());
        wait_until(&what, timeout, || self.try_status().is_some())?;
        Ok(lock(&self.watched).process.finish(Duration::ZERO)?)
    }

    /// Waits for a successful exit and parses the JSON summary printed on stdout.
    pub fn summary(&mut self, timeout: Duration) -> Result<serde_json::Value, HarnessError> {
        let (status, stdout) = self.wait(timeout)?;
        let failure = |reason: String, stdout: String| HarnessError::Summary {
            binary: self.name.clone(),
            reason,
            stdout,
            report: lock(&self.watched).report(),
        };
        if !status.success() {
            return Err(failure(format!("exit status {status}"), stdout));
        }
        serde_json::from_str(&stdout).map_err(|error| failure(error.to_string(), stdout))
    }
}

/// Reads an unsigned counter of a JSON summary, e.g. `u64_at(&gate, "/stats/input-events")`.
pub fn u64_at(summary: &serde_json::Value, pointer: &str) -> u64 {
    summary
        .pointer(pointer)
        .and_then(serde_json::Value::as_u64)
        .unwrap_or_else(|| panic!("summary has no unsigned number at {pointer}: {summary}"))
}
