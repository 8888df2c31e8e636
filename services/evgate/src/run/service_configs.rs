//! How `evgate run` hands each service its typed configuration: serialised as the service's own
//! `--config` file, in a directory private to the run and removed with it.

use std::os::unix::fs::DirBuilderExt;
use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

pub struct ServiceConfigs {
    directory: PathBuf,
}

impl ServiceConfigs {
    /// A fresh directory (mode 0700) under the system's temporary directory.
    pub fn new() -> anyhow::Result<Self> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |elapsed| elapsed.subsec_nanos());
        let directory =
            std::env::temp_dir().join(format!("evgate-run-{}-{nanos}", std::process::id()));
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&directory)
            .with_context(|| format!("cannot create {}", directory.display()))?;
        Ok(Self { directory })
    }

    /// Writes `config` as `<service>.toml`; the arguments that start the service with it.
    pub fn arguments(&self, service: &str, config: &impl Serialize) -> anyhow::Result<Vec<String>> {
        let path = self.directory.join(format!("{service}.toml"));
        evgate_ipc::config_file::write_config_file(config, &path)?;
        Ok(vec!["--config".to_owned(), path.display().to_string()])
    }
}

impl Drop for ServiceConfigs {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.directory);
    }
}
