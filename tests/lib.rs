//! Helpers shared by the end-to-end tests: the service binaries (built on demand next to the
//! test executable), child processes that can never outlive a test, unique pipeline names and
//! a bounded wait for everything that could hang.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStderr, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use evgate_ipc::PipelineNames;

/// Harness failures. Their `Debug` is their message, so `unwrap()` prints the children's report
/// readably.
#[derive(thiserror::Error)]
pub enum HarnessError {
    #[error("cargo build -p {packages} failed ({status}); see its output above")]
    Build {
        packages: String,
        status: ExitStatus,
    },
    #[error("cannot run {program}: {source}")]
    Spawn {
        program: String,
        source: std::io::Error,
    },
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

/// Builds the binaries of [`SERVICE_PACKAGES`] with the profile of the tests (once per test
/// process; cargo itself skips up-to-date work) and returns the path of `binary`.
pub fn binary(binary: &str) -> Result<PathBuf, HarnessError> {
    static BUILT: OnceLock<Mutex<bool>> = OnceLock::new();
    let mut built = BUILT
        .get_or_init(|| Mutex::new(false))
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if !*built {
        let directory = binary_directory();
        let mut command = Command::new(env!("CARGO"));
        command
            .current_dir(workspace_root())
            .args(["build", "--bins"]);
        for package in SERVICE_PACKAGES {
            command.args(["-p", package]);
        }
        if directory.file_name().is_some_and(|name| name == "release") {
            command.arg("--release");
        }
        let status = command.status().map_err(|source| HarnessError::Spawn {
            program: "cargo".to_owned(),
            source,
        })?;
        if !status.success() {
            return Err(HarnessError::Build {
                packages: SERVICE_PACKAGES.join(" -p "),
                status,
            });
        }
        *built = true;
    }
    Ok(binary_directory().join(binary))
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
    name: String,
    child: Child,
    status: Option<ExitStatus>,
    stderr_tail: Arc<Mutex<StderrTail>>,
}

impl Watched {
    fn try_status(&mut self) -> Option<ExitStatus> {
        if self.status.is_none() {
            self.status = self.child.try_wait().ok().flatten();
        }
        self.status
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
            self.name,
            self.child.id(),
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

/// A child process that is killed when dropped, so a failing test leaves nothing running.
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
        let name = program
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut command = Command::new(program);
        command
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "warn,iceoryx2_bb_loggers=error");
        }
        // An error's backtrace would push the error itself out of the kept stderr tail.
        if std::env::var_os("RUST_LIB_BACKTRACE").is_none() {
            command.env("RUST_LIB_BACKTRACE", "0");
        }
        adjust(&mut command);
        let mut child = command.spawn().map_err(|source| HarnessError::Spawn {
            program: program.display().to_string(),
            source,
        })?;
        let stderr_tail = Arc::new(Mutex::new(StderrTail::default()));
        if let Some(stderr) = child.stderr.take() {
            let (name, tail) = (format!("{name} {}", child.id()), Arc::clone(&stderr_tail));
            std::thread::spawn(move || forward_stderr(name, stderr, tail));
        }
        let watched = Arc::new(Mutex::new(Watched {
            name: name.clone(),
            child,
            status: None,
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
        lock(&self.watched).child.id()
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
        if self.is_running() {
            // SAFETY: kill(2) on our own unreaped child.
            unsafe {
                libc::kill(self.pid() as libc::pid_t, signal);
            }
        }
    }

    /// Waits for the exit (at most `timeout`) and returns the status and the stdout.
    pub fn wait(&mut self, timeout: Duration) -> Result<(ExitStatus, String), HarnessError> {
        let what = format!("exit of {} (pid {})", self.name, self.pid());
        wait_until(&what, timeout, || self.try_status().is_some())?;
        let mut watched = lock(&self.watched);
        let mut stdout = String::new();
        if let Some(pipe) = watched.child.stdout.as_mut() {
            let _ = pipe.read_to_string(&mut stdout);
        }
        Ok((watched.status.expect("waited for it"), stdout))
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

impl Drop for Process {
    fn drop(&mut self) {
        let mut watched = lock(&self.watched);
        if watched.try_status().is_none() {
            let _ = watched.child.kill();
            let _ = watched.child.wait();
        }
    }
}

/// Reads an unsigned counter of a JSON summary, e.g. `u64_at(&gate, "/stats/input-events")`.
pub fn u64_at(summary: &serde_json::Value, pointer: &str) -> u64 {
    summary
        .pointer(pointer)
        .and_then(serde_json::Value::as_u64)
        .unwrap_or_else(|| panic!("summary has no unsigned number at {pointer}: {summary}"))
}
