//! The pipeline's service processes: started next to the current executable, stopped with
//! SIGTERM (then SIGKILL after a grace period), their JSON summaries collected.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Child-process failures.
#[derive(Debug, thiserror::Error)]
pub enum ChildError {
    #[error("cannot locate the running executable: {0}")]
    CurrentExe(std::io::Error),
    #[error("{binary} not found in {directory}: build the services first (cargo build -p {binary}, or --release for target/release)")]
    Missing { binary: String, directory: PathBuf },
    #[error("cannot start {binary}: {source}")]
    Spawn {
        binary: String,
        source: std::io::Error,
    },
    #[error("cannot query the state of {binary} (pid {pid}): {source}")]
    Wait {
        binary: String,
        pid: u32,
        source: std::io::Error,
    },
}

/// Directory of the service binaries: the one holding the running `evgate` (target/<profile>/).
pub fn binary_directory() -> Result<PathBuf, ChildError> {
    let exe = std::env::current_exe().map_err(ChildError::CurrentExe)?;
    Ok(exe
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from(".")))
}

/// One running service.
pub struct Service {
    pub binary: &'static str,
    child: Child,
    /// Exit status once it ended.
    pub status: Option<std::process::ExitStatus>,
}

impl Service {
    /// Starts `binary` from `directory` with `args`; its stdout (the JSON summary) is captured,
    /// its log on stderr is shared with ours.
    pub fn start(
        directory: &Path,
        binary: &'static str,
        args: &[String],
    ) -> Result<Self, ChildError> {
        let path = directory.join(binary);
        if !path.is_file() {
            return Err(ChildError::Missing {
                binary: binary.to_owned(),
                directory: directory.to_owned(),
            });
        }
        let mut command = Command::new(&path);
        command
            .args(args)
            .stdout(Stdio::piped())
            .stdin(Stdio::null());
        if std::env::var_os("RUST_LOG").is_none() {
            // The live status line owns the terminal; children only report problems.
            command.env("RUST_LOG", "warn,iceoryx2_bb_loggers=error");
        }
        let child = command.spawn().map_err(|source| ChildError::Spawn {
            binary: binary.to_owned(),
            source,
        })?;
        Ok(Self {
            binary,
            child,
            status: None,
        })
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// True once the process has ended (its status is kept).
    pub fn has_exited(&mut self) -> Result<bool, ChildError> {
        if self.status.is_some() {
            return Ok(true);
        }
        let pid = self.child.id();
        self.status = self.child.try_wait().map_err(|source| ChildError::Wait {
            binary: self.binary.to_owned(),
            pid,
            source,
        })?;
        Ok(self.status.is_some())
    }

    /// Asks the process to stop (SIGTERM); every evgate service then exits cleanly.
    pub fn request_stop(&mut self) -> Result<(), ChildError> {
        if self.has_exited()? {
            return Ok(());
        }
        // SAFETY: plain kill(2) on the pid of a child we have not reaped yet.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
        }
        Ok(())
    }

    /// Waits up to `grace` for the process to end, then kills it; returns its stdout.
    pub fn finish(&mut self, grace: Duration) -> Result<String, ChildError> {
        let deadline = Instant::now() + grace;
        while !self.has_exited()? {
            if Instant::now() >= deadline {
                // It ignored SIGTERM: SIGKILL cannot be ignored.
                let _ = self.child.kill();
                let pid = self.child.id();
                self.status = Some(self.child.wait().map_err(|source| ChildError::Wait {
                    binary: self.binary.to_owned(),
                    pid,
                    source,
                })?);
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let mut output = String::new();
        if let Some(stdout) = self.child.stdout.as_mut() {
            let _ = stdout.read_to_string(&mut output);
        }
        Ok(output)
    }
}

impl Drop for Service {
    /// A child must never outlive `evgate run`, whatever path leaves it.
    fn drop(&mut self) {
        if matches!(self.has_exited(), Ok(false)) {
            let _ = self.request_stop();
            let _ = self.finish(Duration::from_secs(3));
        }
    }
}
