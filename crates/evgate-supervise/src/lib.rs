//! The child processes evgate starts, by `evgate run`, the end-to-end tests and the benches
//! alike: stdin closed, stdout captured (a service prints its JSON summary there), stopped with
//! SIGTERM, killed with SIGKILL when it outlives a grace period, and never outliving its owner.

use std::ffi::OsStr;
use std::io::Read;
use std::path::Path;
use std::process::{Child, ChildStderr, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Why a child could not be started or watched.
#[derive(Debug, thiserror::Error)]
pub enum SuperviseError {
    #[error("cannot start {program}: {source}")]
    Spawn {
        program: String,
        source: std::io::Error,
    },
    #[error("cannot query the state of {name} (pid {pid}): {source}")]
    Wait {
        name: String,
        pid: u32,
        source: std::io::Error,
    },
}

/// Where a child's stderr goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StderrTo {
    /// Shared with the owner's (its log lines show with the owner's).
    Inherit,
    /// A pipe the owner reads ([`Supervised::take_stderr`]).
    Pipe,
}

/// A started child.
pub struct Supervised {
    name: String,
    child: Child,
    status: Option<ExitStatus>,
    /// How long dropping it waits after SIGTERM before SIGKILL (zero: SIGKILL at once).
    grace_on_drop: Duration,
}

impl Supervised {
    /// Starts `program` with `args`; `adjust` may set up the command further (environment,
    /// working directory). Unless the caller set `RUST_LOG`, the child logs warnings only.
    pub fn start(
        program: &Path,
        args: &[impl AsRef<OsStr>],
        stderr: StderrTo,
        grace_on_drop: Duration,
        adjust: impl FnOnce(&mut Command),
    ) -> Result<Self, SuperviseError> {
        let name = program
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_else(|| program.display().to_string());
        let mut command = Command::new(program);
        command
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(match stderr {
                StderrTo::Inherit => Stdio::inherit(),
                StderrTo::Pipe => Stdio::piped(),
            });
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "warn,iceoryx2_bb_loggers=error");
        }
        adjust(&mut command);
        let child = command.spawn().map_err(|source| SuperviseError::Spawn {
            program: program.display().to_string(),
            source,
        })?;
        Ok(Self {
            name,
            child,
            status: None,
            grace_on_drop,
        })
    }

    /// The program's file name.
    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The stderr pipe under [`StderrTo::Pipe`], once.
    pub fn take_stderr(&mut self) -> Option<ChildStderr> {
        self.child.stderr.take()
    }

    /// The exit status once the child ended (kept once seen).
    pub fn try_status(&mut self) -> Result<Option<ExitStatus>, SuperviseError> {
        if self.status.is_none() {
            self.status = self
                .child
                .try_wait()
                .map_err(|source| SuperviseError::Wait {
                    name: self.name.clone(),
                    pid: self.child.id(),
                    source,
                })?;
        }
        Ok(self.status)
    }

    /// Sends `signal` while the child runs (SIGTERM asks an evgate service to stop cleanly).
    pub fn signal(&mut self, signal: libc::c_int) -> Result<(), SuperviseError> {
        if self.try_status()?.is_none() {
            // SAFETY: kill(2) on the pid of a child that has not been reaped yet.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, signal);
            }
        }
        Ok(())
    }

    /// Waits up to `grace` for the child to end, then kills it; its status and stdout (empty
    /// for a killed child, whose summary was never written and whose pipe a grandchild may
    /// still hold open).
    pub fn finish(&mut self, grace: Duration) -> Result<(ExitStatus, String), SuperviseError> {
        let deadline = Instant::now() + grace;
        let status = loop {
            if let Some(status) = self.try_status()? {
                break status;
            }
            if Instant::now() >= deadline {
                // It outlived the grace period: SIGKILL cannot be ignored.
                let _ = self.child.kill();
                let status = self.child.wait().map_err(|source| SuperviseError::Wait {
                    name: self.name.clone(),
                    pid: self.child.id(),
                    source,
                })?;
                self.status = Some(status);
                return Ok((status, String::new()));
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let mut stdout = String::new();
        if let Some(pipe) = self.child.stdout.as_mut() {
            let _ = pipe.read_to_string(&mut stdout);
        }
        Ok((status, stdout))
    }
}

impl Drop for Supervised {
    /// A child must never outlive its owner, whatever path leaves it.
    fn drop(&mut self) {
        if matches!(self.try_status(), Ok(None)) {
            if !self.grace_on_drop.is_zero() {
                let _ = self.signal(libc::SIGTERM);
            }
            let _ = self.finish(self.grace_on_drop);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shell(script: &str, grace: Duration) -> Supervised {
        Supervised::start(
            Path::new("/bin/sh"),
            &["-c", script],
            StderrTo::Pipe,
            grace,
            |_| {},
        )
        .unwrap()
    }

    #[test]
    fn stdout_and_status_come_back_at_the_end() {
        let mut child = shell("echo '{\"done\": true}'; exit 3", Duration::ZERO);
        let (status, stdout) = child.finish(Duration::from_secs(30)).unwrap();
        assert_eq!(status.code(), Some(3));
        assert_eq!(stdout.trim(), "{\"done\": true}");
        assert_eq!(child.name(), "sh");
    }

    #[test]
    fn sigterm_stops_and_a_child_that_ignores_it_is_killed_after_the_grace() {
        let mut stops = shell("exec sleep 60", Duration::ZERO);
        stops.signal(libc::SIGTERM).unwrap();
        let (status, _) = stops.finish(Duration::from_secs(30)).unwrap();
        assert!(!status.success());

        let mut stubborn = shell(
            "trap '' TERM; echo ready >&2; exec sleep 60",
            Duration::ZERO,
        );
        // Signalled only once the trap is set.
        let mut ready = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(stubborn.take_stderr().unwrap()),
            &mut ready,
        )
        .unwrap();
        assert_eq!(ready.trim(), "ready");
        stubborn.signal(libc::SIGTERM).unwrap();
        let started = Instant::now();
        let (status, _) = stubborn.finish(Duration::from_millis(200)).unwrap();
        assert!(!status.success());
        assert!(started.elapsed() >= Duration::from_millis(200));
    }

    #[test]
    fn dropping_a_running_child_ends_it() {
        let child = shell("exec sleep 60", Duration::ZERO);
        let pid = child.pid() as libc::pid_t;
        drop(child);
        // SAFETY: signal 0 only asks whether the pid exists.
        assert_eq!(unsafe { libc::kill(pid, 0) }, -1, "pid {pid} still exists");
    }
}
