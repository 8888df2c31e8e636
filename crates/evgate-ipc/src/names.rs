//! Service names of one pipeline: `<domain>/<camera>/<stream>`.

use iceoryx2::prelude::ServiceName;
use serde::{Deserialize, Serialize};

/// Naming failures.
#[derive(Debug, thiserror::Error)]
pub enum NameError {
    #[error("pipeline name part {field} = {value:?} is invalid: use 1 to 64 characters from [A-Za-z0-9_.-]")]
    InvalidPart { field: &'static str, value: String },
    #[error("service name {name:?} is rejected by iceoryx2: {reason}")]
    Rejected { name: String, reason: String },
}

/// The streams a pipeline publishes. Each is one publish-subscribe service plus an event service
/// of the same name that carries the wake-up notifications.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stream {
    /// Input events: `[Event]` with a [`crate::BatchHeader`], published by the ingest.
    Events,
    /// Ground-truth object id per input event (`[u16]`, 0 = background), same header and
    /// sequence as the events batch; only published when the source knows the labels (simulator).
    Labels,
    /// Forecast masks: `[u64]` with a [`crate::ForecastHeader`], published by the inference.
    Forecast,
    /// Events the gate let through: `[Event]` with the header of their input batch.
    Kept,
    /// Events the gate suppressed: `[Event]` with the header of their input batch.
    Suppressed,
    /// One bit per input event (1 = kept), `[u64]` with the header of the input batch.
    KeepBitmap,
    /// The gate's counters: [`crate::PipelineStats`].
    Stats,
}

impl Stream {
    /// Every stream, in pipeline order.
    pub const ALL: [Stream; 7] = [
        Stream::Events,
        Stream::Labels,
        Stream::Forecast,
        Stream::Kept,
        Stream::Suppressed,
        Stream::KeepBitmap,
        Stream::Stats,
    ];

    /// The last component of the service name.
    pub const fn suffix(self) -> &'static str {
        match self {
            Stream::Events => "events",
            Stream::Labels => "labels",
            Stream::Forecast => "forecast",
            Stream::Kept => "kept",
            Stream::Suppressed => "suppressed",
            Stream::KeepBitmap => "keep-bitmap",
            Stream::Stats => "stats",
        }
    }
}

/// Identifies one pipeline: a domain (one per deployment or test) and a camera within it.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct PipelineNames {
    /// The first part of every service name (`--domain` of the services).
    pub domain: String,
    /// The second part of every service name (`--camera` of the services).
    pub camera: String,
}

impl PipelineNames {
    /// Validates both parts; they become path components of shared-memory resources.
    pub fn new(domain: &str, camera: &str) -> Result<Self, NameError> {
        validate_part("domain", domain)?;
        validate_part("camera", camera)?;
        Ok(Self {
            domain: domain.to_owned(),
            camera: camera.to_owned(),
        })
    }

    /// `<domain>/<camera>/<stream>` as text (what a Python or C++ consumer opens).
    pub fn path(&self, stream: Stream) -> String {
        format!("{}/{}/{}", self.domain, self.camera, stream.suffix())
    }

    /// The iceoryx2 service name of a stream.
    pub fn service(&self, stream: Stream) -> Result<ServiceName, NameError> {
        let name = self.path(stream);
        ServiceName::new(&name).map_err(|error| NameError::Rejected {
            reason: format!("{error:?}"),
            name,
        })
    }
}

fn validate_part(field: &'static str, value: &str) -> Result<(), NameError> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-');
    if value.is_empty() || value.len() > 64 || !value.chars().all(allowed) {
        return Err(NameError::InvalidPart {
            field,
            value: value.to_owned(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names_follow_domain_camera_stream() {
        let names = PipelineNames::new("lab", "cam0").unwrap();
        assert_eq!(names.path(Stream::KeepBitmap), "lab/cam0/keep-bitmap");
        let service = names.service(Stream::Events).unwrap();
        assert_eq!(service.as_str(), "lab/cam0/events");
    }

    #[test]
    fn distinct_streams_have_distinct_names() {
        let names = PipelineNames::new("d", "c").unwrap();
        let mut paths: Vec<_> = Stream::ALL.iter().map(|s| names.path(*s)).collect();
        paths.sort();
        paths.dedup();
        assert_eq!(paths.len(), Stream::ALL.len());
    }

    #[test]
    fn rejects_separators_and_empty_parts() {
        assert!(matches!(
            PipelineNames::new("a/b", "c"),
            Err(NameError::InvalidPart {
                field: "domain",
                ..
            })
        ));
        assert!(matches!(
            PipelineNames::new("a", ""),
            Err(NameError::InvalidPart {
                field: "camera",
                ..
            })
        ));
    }
}
