//! The pipeline's service processes: started next to the current executable, stopped with
//! SIGTERM (then SIGKILL after a grace period), their JSON summaries collected
//! (`evgate_supervise`, the supervisor the tests and benches use too).

use std::path::{Path, PathBuf};
use std::process::ExitStatus;
use std::time::Duration;

use evgate_supervise::{StderrTo, SuperviseError, Supervised};

/// How long a service gets to stop cleanly when `evgate run` leaves by an error.
const GRACE_ON_DROP: Duration = Duration::from_secs(3);

/// Child-process failures.
#[derive(Debug, thiserror::Error)]
pub enum ChildError {
    #[error("cannot locate the running executable: {0}")]
    CurrentExe(std::io::Error),
    #[error("{binary} not found in {directory}: build the services first (cargo build -p {binary}, or --release for target/release)")]
    Missing { binary: String, directory: PathBuf },
    #[error(transparent)]
    Supervise(#[from] SuperviseError),
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
    process: Supervised,
}

impl Service {
    /// Starts `binary` from `directory` with `args`; its stdout (the JSON summary) is captured,
    /// its log on stderr is shared with ours (warnings only: the live status line owns the
    /// terminal).
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
        let process = Supervised::start(&path, args, StderrTo::Inherit, GRACE_ON_DROP, |_| {})?;
        Ok(Self { binary, process })
    }

    pub fn pid(&self) -> u32 {
        self.process.pid()
    }

    /// The exit status once the process has ended.
    pub fn status(&mut self) -> Result<Option<ExitStatus>, ChildError> {
        Ok(self.process.try_status()?)
    }

    /// Asks the process to stop (SIGTERM); every evgate service then exits cleanly.
    pub fn request_stop(&mut self) -> Result<(), ChildError> {
        Ok(self.process.signal(libc::SIGTERM)?)
    }

    /// Waits up to `grace` for the process to end, then kills it; returns its stdout.
    pub fn finish(&mut self, grace: Duration) -> Result<String, ChildError> {
        Ok(self.process.finish(grace)?.1)
    }
}
