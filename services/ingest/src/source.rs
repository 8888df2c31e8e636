//! Where events come from: the built-in simulated camera or a file, delivered in chunks with a
//! watermark (no later event is older than it), so batches can be cut by time.

use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use evgate_io::{EventReader, LabelledSequence};
use evgate_sim::{LabelledEvent, Preset, Simulator};

/// Source failures.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("cannot read labelled sequence {path}: {reason}")]
    Sequence { path: PathBuf, reason: String },
    #[error("input {path} has no events{dropped}")]
    Empty { path: PathBuf, dropped: String },
    #[error(
        "input {path} does not give its sensor size (text event files carry none); pass \
         --sensor WIDTHxHEIGHT"
    )]
    UnknownSensor { path: PathBuf },
    #[error(transparent)]
    Decode(#[from] evgate_io::DecodeError),
    #[error(transparent)]
    Network(#[from] evgate_io::network::NetworkError),
    #[error(
        "{endpoint} came back with a {after} sensor after serving a {before} one; a new camera \
         needs a new ingest"
    )]
    SensorChanged {
        endpoint: String,
        before: SensorSize,
        after: SensorSize,
    },
    #[error("--loop replays files; {endpoint} is a live network stream")]
    LoopNetwork { endpoint: String },
}

/// A chunk appended by [`EventSource::next_chunk`].
pub enum Chunk {
    /// Events were appended; every later event has `t >= watermark_us`.
    Events { watermark_us: i64 },
    /// The source is exhausted.
    End,
}

/// Produces events in time order, with their ground-truth labels when known.
pub trait EventSource {
    fn sensor(&self) -> SensorSize;
    /// True when the source knows which object caused each event.
    fn has_labels(&self) -> bool;
    /// Appends the next chunk of events (and labels, when known) to the buffers.
    fn next_chunk(
        &mut self,
        events: &mut Vec<Event>,
        labels: &mut Vec<u16>,
    ) -> Result<Chunk, SourceError>;
    /// Starts pass number `pass` (1 for the first repetition) over from the first event, shifted
    /// by `pass` times the source's span so stream time keeps increasing across loops.
    fn restart(&mut self, pass: i64) -> Result<(), SourceError>;
    /// What the decoder of a file dropped, skipped or found out of order in the current pass.
    fn decode_report(&self) -> Option<evgate_io::DecodeReport> {
        None
    }
}

/// The built-in simulated camera, generating events incrementally for `duration_us`.
pub struct SimulatedCamera {
    preset: Preset,
    seed: u64,
    simulator: Simulator,
    duration_us: i64,
    step_us: i64,
    offset_us: i64,
    threads: usize,
    scratch: Vec<LabelledEvent>,
}

impl SimulatedCamera {
    /// `step_us` is how much simulated time one chunk covers.
    pub fn new(preset: Preset, seed: u64, duration_us: i64, step_us: i64) -> Self {
        Self {
            preset,
            seed,
            simulator: Simulator::from_preset(preset, seed),
            duration_us,
            step_us: step_us.max(1),
            offset_us: 0,
            threads: 1,
            scratch: Vec::new(),
        }
    }

    /// Limits the renderer to `threads` worker threads.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
        self.simulator.set_threads(self.threads);
    }
}

impl EventSource for SimulatedCamera {
    fn sensor(&self) -> SensorSize {
        self.simulator.sensor()
    }

    fn has_labels(&self) -> bool {
        true
    }

    fn next_chunk(
        &mut self,
        events: &mut Vec<Event>,
        labels: &mut Vec<u16>,
    ) -> Result<Chunk, SourceError> {
        let now = self.simulator.time_us();
        if now >= self.duration_us {
            return Ok(Chunk::End);
        }
        let until = (now + self.step_us).min(self.duration_us);
        self.scratch.clear();
        self.simulator.advance(until, &mut self.scratch);
        for labelled in &self.scratch {
            let mut event = labelled.event;
            event.t += self.offset_us;
            events.push(event);
            labels.push(labelled.label);
        }
        // `advance` delivered every event up to `until` inclusive.
        Ok(Chunk::Events {
            watermark_us: until + 1 + self.offset_us,
        })
    }

    fn restart(&mut self, pass: i64) -> Result<(), SourceError> {
        let threads = self.threads;
        self.simulator = Simulator::from_preset(self.preset, self.seed);
        self.simulator.set_threads(threads);
        // One pass delivers the events of (0, duration].
        self.offset_us = pass * self.duration_us;
        Ok(())
    }
}

/// Events held in memory (a decoded file), handed out in fixed-size chunks.
pub struct InMemory {
    events: Vec<Event>,
    labels: Option<Vec<u16>>,
    sensor: SensorSize,
    next: usize,
    offset_us: i64,
}

/// Events per chunk of an in-memory source: small enough to start publishing at once.
const IN_MEMORY_CHUNK: usize = 65_536;

impl InMemory {
    /// Reads a labelled-sequence `.npz` (docs/sequence-format.md): events with labels.
    pub fn labelled_sequence(path: &Path) -> Result<Self, SourceError> {
        let sequence = LabelledSequence::read(path).map_err(|error| SourceError::Sequence {
            path: path.to_owned(),
            reason: error.to_string(),
        })?;
        if sequence.events.is_empty() {
            return Err(SourceError::Empty {
                path: path.to_owned(),
                dropped: String::new(),
            });
        }
        Ok(Self {
            events: sequence.events,
            labels: Some(sequence.labels),
            sensor: sequence.sensor_size,
            next: 0,
            offset_us: 0,
        })
    }

    /// Time from the first to one past the last event.
    pub fn span_us(&self) -> i64 {
        match (self.events.first(), self.events.last()) {
            (Some(first), Some(last)) => last.t - first.t + 1,
            _ => 0,
        }
    }
}

impl EventSource for InMemory {
    fn sensor(&self) -> SensorSize {
        self.sensor
    }

    fn has_labels(&self) -> bool {
        self.labels.is_some()
    }

    fn next_chunk(
        &mut self,
        events: &mut Vec<Event>,
        labels: &mut Vec<u16>,
    ) -> Result<Chunk, SourceError> {
        if self.next >= self.events.len() {
            return Ok(Chunk::End);
        }
        let end = (self.next + IN_MEMORY_CHUNK).min(self.events.len());
        let offset = self.offset_us;
        events.extend(self.events[self.next..end].iter().map(|event| Event {
            t: event.t + offset,
            ..*event
        }));
        if let Some(known) = &self.labels {
            labels.extend_from_slice(&known[self.next..end]);
        }
        self.next = end;
        // Files are in time order, so nothing later is older than the last event handed out.
        Ok(Chunk::Events {
            watermark_us: self.events[end - 1].t + offset,
        })
    }

    fn restart(&mut self, pass: i64) -> Result<(), SourceError> {
        self.next = 0;
        self.offset_us = pass * self.span_us();
        Ok(())
    }
}

/// An event file of any format evgate-io decodes, streamed chunk by chunk (no labels).
pub struct Recording {
    path: PathBuf,
    options: evgate_io::reader::OpenOptions,
    reader: Box<dyn EventReader>,
    chunk: Vec<Event>,
    offset_us: i64,
    /// First and last event time of the first pass: the span a loop shifts by.
    first_t: Option<i64>,
    last_t: i64,
    span_us: Option<i64>,
}

impl Recording {
    /// Opens `path`; `sensor` is required where the file gives no size and overrides it
    /// otherwise.
    pub fn open(path: &Path, sensor: Option<SensorSize>) -> Result<Self, SourceError> {
        let options = evgate_io::reader::OpenOptions {
            sensor_size: sensor,
            ..Default::default()
        };
        let reader = evgate_io::open_with(path, &options)?;
        if reader.sensor_size() == evgate_io::reader::UNBOUNDED_SENSOR {
            return Err(SourceError::UnknownSensor {
                path: path.to_owned(),
            });
        }
        Ok(Self {
            path: path.to_owned(),
            options,
            reader,
            chunk: Vec::new(),
            offset_us: 0,
            first_t: None,
            last_t: 0,
            span_us: None,
        })
    }
}

impl EventSource for Recording {
    fn sensor(&self) -> SensorSize {
        self.reader.sensor_size()
    }

    fn decode_report(&self) -> Option<evgate_io::DecodeReport> {
        Some(self.reader.report().clone())
    }

    fn has_labels(&self) -> bool {
        false
    }

    fn next_chunk(
        &mut self,
        events: &mut Vec<Event>,
        _labels: &mut Vec<u16>,
    ) -> Result<Chunk, SourceError> {
        if self.reader.read_chunk(&mut self.chunk)? == 0 {
            if self.first_t.is_none() {
                let report = self.reader.report();
                return Err(SourceError::Empty {
                    path: self.path.clone(),
                    dropped: format!(
                        " ({} dropped outside the sensor, {} outside ±2^60 µs)",
                        report.dropped_out_of_sensor, report.dropped_out_of_time_range
                    ),
                });
            }
            return Ok(Chunk::End);
        }
        self.first_t.get_or_insert(self.chunk[0].t);
        self.last_t = self.chunk[self.chunk.len() - 1].t;
        let offset = self.offset_us;
        events.extend(self.chunk.iter().map(|event| Event {
            t: event.t + offset,
            ..*event
        }));
        // Decoders deliver events in time order (repairs are reported, not passed on).
        Ok(Chunk::Events {
            watermark_us: self.last_t + offset,
        })
    }

    fn restart(&mut self, pass: i64) -> Result<(), SourceError> {
        let span = *self
            .span_us
            .get_or_insert(self.last_t - self.first_t.unwrap_or(self.last_t) + 1);
        self.reader = evgate_io::open_with(&self.path, &self.options)?;
        self.offset_us = pass * span;
        Ok(())
    }
}
