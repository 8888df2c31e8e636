//! `--input tcp://HOST:PORT` or `unix:///PATH`: the events of an AEDAT 4 network stream (a DV
//! camera through the DV runtime's network output, or dv-processing's `NetworkWriter`),
//! published as they arrive. When the peer drops, the stream reconnects with back-off and goes
//! on; SIGINT or SIGTERM ends it, also in the middle of a wait for data or for the peer.

use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use evgate_core::{Event, SensorSize};
use evgate_io::aedat4::Aedat4Decoder;
use evgate_io::network::Endpoint;
use evgate_io::DecodeError;
use tracing::{info, warn};

use crate::source::{Chunk, EventSource, SourceError};
use crate::RunError;

/// How long a read waits before looking for a stop request.
const READ_TIMEOUT: Duration = Duration::from_millis(100);
/// Waits between reconnection attempts: doubling from the first to the last.
const FIRST_BACKOFF: Duration = Duration::from_millis(100);
const LAST_BACKOFF: Duration = Duration::from_secs(2);

/// A flag that a thread of its own raises when SIGINT or SIGTERM asks the process to stop, so
/// that a read blocked on the socket can give up.
pub fn stop_flag() -> Result<Arc<AtomicBool>, RunError> {
    let flag = Arc::new(AtomicBool::new(false));
    let raised = Arc::clone(&flag);
    let node = evgate_ipc::create_node("evgate-ingest-network-stop")?;
    std::thread::Builder::new()
        .name("evgate-ingest-stop".to_owned())
        .spawn(move || {
            while !evgate_ipc::stop_requested(&node, Duration::from_millis(50)) {}
            raised.store(true, Ordering::Relaxed);
        })
        .map_err(RunError::StopWatcher)?;
    Ok(flag)
}

/// A socket whose reads wait out their timeouts until data comes or a stop is requested, which
/// reads as the end of the stream.
struct StoppableConnection {
    socket: Box<dyn Read + Send>,
    stop: Arc<AtomicBool>,
}

impl Read for StoppableConnection {
    fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
        loop {
            match self.socket.read(buffer) {
                Err(error)
                    if matches!(
                        error.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    if self.stop.load(Ordering::Relaxed) {
                        return Ok(0);
                    }
                }
                other => return other,
            }
        }
    }
}

pub struct NetworkStream {
    endpoint: Endpoint,
    sensor_flag: Option<SensorSize>,
    sensor: SensorSize,
    /// None between a dropped connection and the next.
    decoder: Option<Aedat4Decoder>,
    /// What the last connection's decoder dropped or repaired.
    report: evgate_io::DecodeReport,
    stop: Arc<AtomicBool>,
    chunk: Vec<Event>,
}

impl NetworkStream {
    /// Connects to `endpoint` and reads its header; a server that is not there or speaks
    /// another protocol is an error at once.
    pub fn connect(
        endpoint: Endpoint,
        sensor_flag: Option<SensorSize>,
        stop: Arc<AtomicBool>,
    ) -> Result<Self, SourceError> {
        let decoder = open(&endpoint, sensor_flag, &stop)?;
        let sensor = decoder.sensor_size();
        info!(%endpoint, %sensor, "connected to the AEDAT 4 stream");
        Ok(Self {
            endpoint,
            sensor_flag,
            sensor,
            report: decoder.report().clone(),
            decoder: Some(decoder),
            stop,
            chunk: Vec::new(),
        })
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Connects again after the peer dropped, waiting longer after each failure; false when a
    /// stop was requested first.
    fn reconnect(&mut self) -> Result<bool, SourceError> {
        // Closed before the next attempt: a server may wait for its clients to leave before it
        // can listen again.
        if let Some(dropped) = self.decoder.take() {
            self.report = dropped.report().clone();
        }
        let mut backoff = FIRST_BACKOFF;
        loop {
            if self.sleep_unless_stopped(backoff) {
                return Ok(false);
            }
            match open(&self.endpoint, self.sensor_flag, &self.stop) {
                Ok(decoder) if decoder.sensor_size() != self.sensor => {
                    return Err(SourceError::SensorChanged {
                        endpoint: self.endpoint.to_string(),
                        before: self.sensor,
                        after: decoder.sensor_size(),
                    })
                }
                Ok(decoder) => {
                    info!(endpoint = %self.endpoint, "reconnected to the AEDAT 4 stream");
                    self.decoder = Some(decoder);
                    return Ok(true);
                }
                Err(error) => {
                    warn!(%error, retry_in_ms = backoff.as_millis() as u64, "reconnection failed");
                    backoff = (backoff * 2).min(LAST_BACKOFF);
                }
            }
        }
    }

    /// Sleeps `duration` in short steps; true when a stop was requested meanwhile.
    fn sleep_unless_stopped(&self, duration: Duration) -> bool {
        let step = Duration::from_millis(20);
        let mut slept = Duration::ZERO;
        while slept < duration {
            if self.stopping() {
                return true;
            }
            std::thread::sleep(step);
            slept += step;
        }
        self.stopping()
    }
}

fn open(
    endpoint: &Endpoint,
    sensor_flag: Option<SensorSize>,
    stop: &Arc<AtomicBool>,
) -> Result<Aedat4Decoder, SourceError> {
    let socket = endpoint.connect(Some(READ_TIMEOUT))?;
    let connection = StoppableConnection {
        socket,
        stop: Arc::clone(stop),
    };
    Ok(endpoint.decoder(Box::new(connection), sensor_flag)?)
}

impl EventSource for NetworkStream {
    fn sensor(&self) -> SensorSize {
        self.sensor
    }

    fn has_labels(&self) -> bool {
        false
    }

    fn next_chunk(
        &mut self,
        events: &mut Vec<Event>,
        _labels: &mut Vec<u16>,
    ) -> Result<Chunk, SourceError> {
        loop {
            // Only a stop leaves the stream without a connection.
            let Some(decoder) = self.decoder.as_mut() else {
                return Ok(Chunk::End);
            };
            let dropped = match decoder.read_chunk(&mut self.chunk) {
                Ok(0) => None,
                Ok(_) => {
                    events.extend_from_slice(&self.chunk);
                    // The next packet may start at the same time, never earlier.
                    let watermark_us = self.chunk[self.chunk.len() - 1].t;
                    return Ok(Chunk::Events { watermark_us });
                }
                // A connection cut in the middle of a packet reads as a truncated packet.
                Err(error @ (DecodeError::Io { .. } | DecodeError::Truncated { .. })) => {
                    Some(error)
                }
                Err(error) => return Err(error.into()),
            };
            if self.stopping() {
                return Ok(Chunk::End);
            }
            match dropped {
                Some(error) => warn!(endpoint = %self.endpoint, %error, "connection lost"),
                None => warn!(endpoint = %self.endpoint, "the peer closed the connection"),
            }
            if !self.reconnect()? {
                return Ok(Chunk::End);
            }
        }
    }

    fn restart(&mut self, _pass: i64) -> Result<(), SourceError> {
        Err(SourceError::LoopNetwork {
            endpoint: self.endpoint.to_string(),
        })
    }

    fn decode_report(&self) -> Option<evgate_io::DecodeReport> {
        Some(
            self.decoder
                .as_ref()
                .map_or(&self.report, |decoder| decoder.report())
                .clone(),
        )
    }
}
