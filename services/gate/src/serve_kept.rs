//! `--serve-kept tcp://HOST:PORT` (or `unix:///PATH`): the kept events as an AEDAT 4 network
//! stream, so that DV tools and dv-processing's `NetworkReader` read evgate's output as they
//! read a camera. A client gets the stream header as soon as the sensor size is known (at once,
//! or with the first batch), then one packet per gated batch.
//!
//! The gate hands each batch's kept events to a thread of its own through a bounded queue. It
//! follows the gate's `--overflow`: under drop-and-count it never waits for the network (when
//! the queue is full the batch is not sent and is counted, and a client that does not take a
//! packet within a second is disconnected); under block it waits up to `--block-timeout-ms`
//! for room in the queue, and a client gets that long (at least a second) to take a packet.
//!
//! After the last batch the connections stay open for a linger period before they close:
//! dv-processing 2.0.4's `NetworkReader` discards the packets it received but has not yet
//! handed out once its server closes, so a reader that lags behind the stream would lose its
//! tail.

use std::io::Write;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam::channel::{Receiver, SendTimeoutError, Sender, TrySendError};
use evgate_core::{Event, SensorSize};
use evgate_io::aedat4_stream_writer::{push_event_packet, stream_header};
use evgate_io::network::Endpoint;
use evgate_ipc::Overflow;
use prometheus_client::metrics::gauge::Gauge;
use tracing::{info, warn};

/// Batches that may wait for the network thread.
const QUEUE_BATCHES: usize = 256;
/// The least time a client gets to take a packet.
const WRITE_TIMEOUT: Duration = Duration::from_secs(1);
const ACCEPT_POLL: Duration = Duration::from_millis(20);

#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("--serve-kept: {0}")]
    Address(#[from] evgate_io::network::NetworkError),
    #[error("--serve-kept {endpoint}: {problem}")]
    NotAnEndpoint { endpoint: String, problem: String },
    #[error("cannot listen on --serve-kept {endpoint}: {source}")]
    Listen {
        endpoint: Endpoint,
        source: std::io::Error,
    },
}

enum Listener {
    Tcp(std::net::TcpListener),
    Unix(std::os::unix::net::UnixListener),
}

impl Listener {
    fn bind(endpoint: &Endpoint) -> std::io::Result<Self> {
        let listener = match endpoint {
            Endpoint::Tcp { address } => Self::Tcp(std::net::TcpListener::bind(address)?),
            Endpoint::Unix { path } => Self::Unix(std::os::unix::net::UnixListener::bind(path)?),
        };
        match &listener {
            Self::Tcp(listener) => listener.set_nonblocking(true)?,
            Self::Unix(listener) => listener.set_nonblocking(true)?,
        }
        Ok(listener)
    }

    /// A waiting client, if any, set up for blocking writes with `write_timeout`.
    fn accept(&self, write_timeout: Duration) -> std::io::Result<Option<Box<dyn Write + Send>>> {
        let accepted: std::io::Result<Box<dyn Write + Send>> = match self {
            Self::Tcp(listener) => listener.accept().and_then(|(stream, _)| {
                stream.set_nonblocking(false)?;
                stream.set_write_timeout(Some(write_timeout))?;
                stream.set_nodelay(true)?;
                Ok(Box::new(stream) as Box<dyn Write + Send>)
            }),
            Self::Unix(listener) => listener.accept().and_then(|(stream, _)| {
                stream.set_nonblocking(false)?;
                stream.set_write_timeout(Some(write_timeout))?;
                Ok(Box::new(stream) as Box<dyn Write + Send>)
            }),
        };
        match accepted {
            Ok(client) => Ok(Some(client)),
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => Ok(None),
            Err(error) => Err(error),
        }
    }
}

/// What the network thread is given.
enum Message {
    Kept {
        sensor: SensorSize,
        events: Vec<Event>,
    },
}

/// The clients and what they were sent.
struct Clients {
    /// Connected clients: those with the header (`true`) and those still waiting for it.
    connected: Vec<(Box<dyn Write + Send>, bool)>,
    header: Option<(SensorSize, Vec<u8>)>,
    gauge: Option<Gauge>,
    /// Clients disconnected because a write failed or timed out.
    dropped: Arc<AtomicU64>,
}

impl Clients {
    fn update_gauge(&self) {
        if let Some(gauge) = &self.gauge {
            gauge.set(self.connected.len() as i64);
        }
    }

    /// Sends the header to every client still without it, when the sensor is known.
    fn send_headers(&mut self) {
        let Some((_, header)) = &self.header else {
            return;
        };
        self.connected.retain_mut(|(client, has_header)| {
            if *has_header {
                return true;
            }
            *has_header = client.write_all(header).is_ok();
            *has_header
        });
        self.update_gauge();
    }

    /// Sends `bytes` to every client with the header, dropping those that fail.
    fn broadcast(&mut self, bytes: &[u8]) {
        let before = self.connected.len();
        self.connected
            .retain_mut(|(client, has_header)| !*has_header || client.write_all(bytes).is_ok());
        if self.connected.len() < before {
            let dropped = before - self.connected.len();
            self.dropped.fetch_add(dropped as u64, Ordering::Relaxed);
            warn!(
                dropped,
                "--serve-kept: disconnected clients that did not take a packet"
            );
            self.update_gauge();
        }
    }
}

/// The serving side of `--serve-kept`; stops, after sending what was queued, when dropped.
pub struct KeptServer {
    queue: Option<Sender<Message>>,
    /// How long `send` waits for room in the queue (`None`: not at all).
    queue_wait: Option<Duration>,
    threads: Vec<JoinHandle<()>>,
    stop_accepting: Arc<AtomicBool>,
    batches_not_sent: Arc<AtomicU64>,
    clients_dropped: Arc<AtomicU64>,
    endpoint: Endpoint,
}

impl KeptServer {
    /// Listens on `endpoint`; `clients_gauge`, when given, follows the number of clients.
    /// Under `Overflow::Block` a batch waits up to `block_timeout` for the network. Clients
    /// still connected after the last batch are closed `linger` later.
    pub fn start(
        endpoint: &str,
        clients_gauge: Option<Gauge>,
        overflow: Overflow,
        block_timeout: Duration,
        linger: Duration,
    ) -> Result<Self, ServeError> {
        let queue_wait = (overflow == Overflow::Block).then_some(block_timeout);
        let write_timeout = queue_wait.map_or(WRITE_TIMEOUT, |wait| wait.max(WRITE_TIMEOUT));
        let endpoint = Endpoint::parse(endpoint).ok_or_else(|| ServeError::NotAnEndpoint {
            endpoint: endpoint.to_owned(),
            problem: "expected tcp://HOST:PORT or unix:///PATH".to_owned(),
        })??;
        let listener = Listener::bind(&endpoint).map_err(|source| ServeError::Listen {
            endpoint: endpoint.clone(),
            source,
        })?;
        let clients_dropped = Arc::new(AtomicU64::new(0));
        let clients = Arc::new(Mutex::new(Clients {
            connected: Vec::new(),
            header: None,
            gauge: clients_gauge,
            dropped: Arc::clone(&clients_dropped),
        }));
        let stop_accepting = Arc::new(AtomicBool::new(false));
        let (queue, received) = crossbeam::channel::bounded(QUEUE_BATCHES);
        let accepting = {
            let (clients, stop) = (Arc::clone(&clients), Arc::clone(&stop_accepting));
            let endpoint = endpoint.clone();
            std::thread::Builder::new()
                .name("evgate-serve-accept".to_owned())
                .spawn(move || accept_clients(&listener, &clients, &stop, &endpoint, write_timeout))
                .expect("spawning a thread")
        };
        let sending = std::thread::Builder::new()
            .name("evgate-serve-send".to_owned())
            .spawn(move || send_packets(&received, &clients, linger))
            .expect("spawning a thread");
        info!(%endpoint, "serving the kept events as an AEDAT 4 network stream");
        Ok(Self {
            queue: Some(queue),
            queue_wait,
            threads: vec![accepting, sending],
            stop_accepting,
            batches_not_sent: Arc::new(AtomicU64::new(0)),
            clients_dropped,
            endpoint,
        })
    }

    /// Queues a batch's kept events; a queue still full after the wait the overflow policy
    /// allows drops the batch and counts it.
    pub fn send(&self, sensor: SensorSize, events: Vec<Event>) {
        let Some(queue) = &self.queue else { return };
        let message = Message::Kept { sensor, events };
        let full = match self.queue_wait {
            None => matches!(queue.try_send(message), Err(TrySendError::Full(_))),
            Some(wait) => matches!(
                queue.send_timeout(message, wait),
                Err(SendTimeoutError::Timeout(_))
            ),
        };
        if full {
            self.batches_not_sent.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Batches the network thread could not keep up with.
    pub fn batches_not_sent(&self) -> u64 {
        self.batches_not_sent.load(Ordering::Relaxed)
    }

    /// The count of clients disconnected for not taking a packet; it is final once the server
    /// is dropped.
    pub fn clients_dropped(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.clients_dropped)
    }
}

impl Drop for KeptServer {
    fn drop(&mut self) {
        // Closing the queue lets the sender finish what is queued and return.
        self.queue.take();
        self.stop_accepting.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
        if let Endpoint::Unix { path } = &self.endpoint {
            let _ = std::fs::remove_file(path);
        }
    }
}

fn lock(clients: &Mutex<Clients>) -> std::sync::MutexGuard<'_, Clients> {
    clients.lock().unwrap_or_else(PoisonError::into_inner)
}

fn accept_clients(
    listener: &Listener,
    clients: &Mutex<Clients>,
    stop: &AtomicBool,
    endpoint: &Endpoint,
    write_timeout: Duration,
) {
    while !stop.load(Ordering::Relaxed) {
        match listener.accept(write_timeout) {
            Ok(Some(client)) => {
                let mut clients = lock(clients);
                clients.connected.push((client, false));
                clients.send_headers();
                clients.update_gauge();
                info!(%endpoint, clients = clients.connected.len(), "AEDAT 4 client connected");
            }
            Ok(None) => std::thread::sleep(ACCEPT_POLL),
            Err(error) => {
                warn!(%endpoint, %error, "accepting a client failed");
                std::thread::sleep(ACCEPT_POLL);
            }
        }
    }
}

fn send_packets(received: &Receiver<Message>, clients: &Mutex<Clients>, linger: Duration) {
    let mut packet = Vec::new();
    for Message::Kept { sensor, events } in received {
        let mut clients = lock(clients);
        if clients.header.as_ref().map(|(known, _)| *known) != Some(sensor) {
            clients.header = Some((sensor, stream_header(sensor, "evgate kept events")));
            // A stream has one sensor: clients of the old one reconnect for the new header.
            clients.connected.retain(|(_, has_header)| !*has_header);
        }
        clients.send_headers();
        if events.is_empty() {
            continue;
        }
        packet.clear();
        push_event_packet(&events, &mut packet);
        clients.broadcast(&packet);
    }
    if !lock(clients).connected.is_empty() {
        std::thread::sleep(linger);
    }
    let mut clients = lock(clients);
    clients.connected.clear();
    clients.update_gauge();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A server on a Unix socket in a fresh folder, and one accepted client.
    struct Served {
        directory: tempfile::TempDir,
        endpoint: String,
        server: KeptServer,
        client: std::os::unix::net::UnixStream,
    }

    fn serve_one_client(overflow: Overflow, block_timeout: Duration, linger: Duration) -> Served {
        let directory = tempfile::tempdir().unwrap();
        let path = directory.path().join("kept.sock");
        let endpoint = format!("unix://{}", path.display());
        let gauge = Gauge::default();
        let server = KeptServer::start(
            &endpoint,
            Some(gauge.clone()),
            overflow,
            block_timeout,
            linger,
        )
        .unwrap();
        let client = std::os::unix::net::UnixStream::connect(&path).unwrap();
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while gauge.get() != 1 {
            assert!(
                std::time::Instant::now() < deadline,
                "the client was never accepted"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        Served {
            directory,
            endpoint,
            server,
            client,
        }
    }

    #[test]
    fn a_unix_socket_client_gets_the_header_then_every_batch() {
        let Served {
            directory,
            endpoint,
            server,
            client,
        } = serve_one_client(Overflow::DropAndCount, Duration::ZERO, Duration::ZERO);
        let path = directory.path().join("kept.sock");
        let sensor = SensorSize::new(320, 240);
        let batches = [
            vec![Event::new(10, 1, 2, true), Event::new(11, 3, 4, false)],
            vec![],
            vec![Event::new(20, 319, 239, true)],
        ];
        for batch in &batches {
            server.send(sensor, batch.clone());
        }
        // Dropping the server sends what is queued, then closes the stream.
        drop(server);
        let endpoint = Endpoint::parse(&endpoint).unwrap().unwrap();
        let mut decoder = endpoint.decoder(Box::new(client), None).unwrap();
        assert_eq!(decoder.sensor_size(), sensor);
        let (mut decoded, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            decoded.extend_from_slice(&chunk);
        }
        assert_eq!(decoded, batches.concat());
        assert!(!path.exists(), "the socket file is removed at the end");
    }

    #[test]
    fn a_client_stays_connected_for_the_linger_after_the_last_batch() {
        let linger = Duration::from_secs(2);
        let Served {
            directory: _directory,
            endpoint,
            server,
            client,
        } = serve_one_client(Overflow::DropAndCount, Duration::ZERO, linger);
        let sent = vec![Event::new(10, 1, 2, true)];
        let last_batch_queued = std::time::Instant::now();
        server.send(SensorSize::new(320, 240), sent.clone());
        let closing = std::thread::spawn(move || drop(server));
        let endpoint = Endpoint::parse(&endpoint).unwrap().unwrap();
        let mut decoder = endpoint.decoder(Box::new(client), None).unwrap();
        let (mut decoded, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            decoded.extend_from_slice(&chunk);
        }
        assert!(last_batch_queued.elapsed() >= linger);
        assert_eq!(decoded, sent);
        closing.join().unwrap();
    }

    #[test]
    fn under_block_a_client_slower_than_the_write_timeout_loses_nothing() {
        let Served {
            directory: _directory,
            endpoint,
            server,
            client,
        } = serve_one_client(Overflow::Block, Duration::from_secs(60), Duration::ZERO);
        let sensor = SensorSize::new(320, 240);
        let batch: Vec<Event> = (0..1000)
            .map(|i| Event::new(i, (i % 320) as u16, 7, true))
            .collect();
        // More than the queue and the socket buffer hold, so the sender waits on the client,
        // which takes nothing for longer than the drop-and-count write timeout.
        let reader = std::thread::spawn(move || {
            std::thread::sleep(WRITE_TIMEOUT + Duration::from_millis(500));
            let endpoint = Endpoint::parse(&endpoint).unwrap().unwrap();
            let mut decoder = endpoint.decoder(Box::new(client), None).unwrap();
            let (mut events, mut chunk) = (0usize, Vec::new());
            while decoder.read_chunk(&mut chunk).unwrap() > 0 {
                events += chunk.len();
            }
            events
        });
        let batches = QUEUE_BATCHES * 4;
        for _ in 0..batches {
            server.send(sensor, batch.clone());
        }
        let dropped = server.clients_dropped();
        assert_eq!(server.batches_not_sent(), 0);
        drop(server);
        assert_eq!(dropped.load(Ordering::Relaxed), 0);
        assert_eq!(reader.join().unwrap(), batches * batch.len());
    }

    #[test]
    fn a_bad_endpoint_is_refused_naming_it() {
        let message = KeptServer::start(
            "http://localhost:80",
            None,
            Overflow::DropAndCount,
            Duration::ZERO,
            Duration::ZERO,
        )
        .err()
        .unwrap()
        .to_string();
        assert!(message.contains("http://localhost:80") && message.contains("tcp://"));
    }
}
