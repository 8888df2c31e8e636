//! AEDAT 4 over a socket, as iniVation's DV runtime and dv-processing's `NetworkWriter` and
//! `NetworkReader` speak it: a size-prefixed `IOHE` header, then packets of a 32-bit stream id, a
//! 32-bit size and a size-prefixed FlatBuffer, the AEDAT 4 file layout without its magic line
//! and data table. Endpoints are written `tcp://HOST:PORT` or `unix:///PATH`.

use std::io::Read;
use std::path::PathBuf;
use std::time::Duration;

use evgate_core::SensorSize;

use crate::aedat4::Aedat4Decoder;
use crate::error::DecodeError;
use crate::source::ByteSource;

/// Where an AEDAT 4 network stream is served.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Endpoint {
    /// `tcp://HOST:PORT`.
    Tcp { address: String },
    /// `unix:///PATH`: a local (UNIX domain) socket.
    Unix { path: PathBuf },
}

/// Why a network stream could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    #[error("{input:?} is not an endpoint: {problem} (accepted: tcp://HOST:PORT, unix:///PATH)")]
    Address {
        input: String,
        problem: &'static str,
    },
    #[error(
        "cannot connect to an AEDAT 4 server at {endpoint}: {source} (is dv-processing's \
         NetworkWriter or a DV runtime network output serving there?)"
    )]
    Connect {
        endpoint: Endpoint,
        source: std::io::Error,
    },
    #[error("cannot set up the socket to {endpoint}: {source}")]
    Socket {
        endpoint: Endpoint,
        source: std::io::Error,
    },
    #[error("{endpoint} does not speak the AEDAT 4 network protocol: {source}")]
    Protocol {
        endpoint: Endpoint,
        source: DecodeError,
    },
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Tcp { address } => write!(f, "tcp://{address}"),
            Self::Unix { path } => write!(f, "unix://{}", path.display()),
        }
    }
}

impl Endpoint {
    /// The endpoint `input` names, or `None` when it names neither scheme (a file path).
    pub fn parse(input: &str) -> Option<Result<Self, NetworkError>> {
        let bad = |problem| {
            Some(Err(NetworkError::Address {
                input: input.to_owned(),
                problem,
            }))
        };
        if let Some(address) = input.strip_prefix("tcp://") {
            let Some((host, port)) = address.rsplit_once(':') else {
                return bad("no port");
            };
            if host.is_empty() {
                return bad("no host");
            }
            if port.parse::<u16>().is_err() {
                return bad("the port is not a number from 0 to 65535");
            }
            return Some(Ok(Self::Tcp {
                address: address.to_owned(),
            }));
        }
        if let Some(path) = input.strip_prefix("unix://") {
            if !path.starts_with('/') {
                return bad("the socket path must be absolute (unix:///PATH)");
            }
            return Some(Ok(Self::Unix { path: path.into() }));
        }
        None
    }

    /// Connects; reads then time out after `read_timeout` (so that a reader can look for a
    /// stop request between them) where given.
    pub fn connect(
        &self,
        read_timeout: Option<Duration>,
    ) -> Result<Box<dyn Read + Send>, NetworkError> {
        let connect_error = |source| NetworkError::Connect {
            endpoint: self.clone(),
            source,
        };
        let socket_error = |source| NetworkError::Socket {
            endpoint: self.clone(),
            source,
        };
        match self {
            Self::Tcp { address } => {
                let stream = std::net::TcpStream::connect(address).map_err(connect_error)?;
                stream
                    .set_read_timeout(read_timeout)
                    .map_err(socket_error)?;
                // Packets are small and latency matters more than a few saved segments.
                stream.set_nodelay(true).map_err(socket_error)?;
                Ok(Box::new(stream))
            }
            Self::Unix { path } => {
                let stream =
                    std::os::unix::net::UnixStream::connect(path).map_err(connect_error)?;
                stream
                    .set_read_timeout(read_timeout)
                    .map_err(socket_error)?;
                Ok(Box::new(stream))
            }
        }
    }

    /// Reads the stream header from `connection` and returns the decoder of its event packets;
    /// `sensor_size` overrides the header's.
    pub fn decoder(
        &self,
        connection: Box<dyn Read + Send>,
        sensor_size: Option<SensorSize>,
    ) -> Result<Aedat4Decoder, NetworkError> {
        let source = ByteSource::new(PathBuf::from(self.to_string()), connection);
        Aedat4Decoder::network_stream(source, sensor_size).map_err(|source| {
            NetworkError::Protocol {
                endpoint: self.clone(),
                source,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn endpoints_parse_or_say_what_is_wrong() {
        assert_eq!(
            Endpoint::parse("tcp://127.0.0.1:7777").unwrap().unwrap(),
            Endpoint::Tcp {
                address: "127.0.0.1:7777".into()
            }
        );
        assert_eq!(
            Endpoint::parse("unix:///tmp/dv.sock").unwrap().unwrap(),
            Endpoint::Unix {
                path: "/tmp/dv.sock".into()
            }
        );
        assert!(Endpoint::parse("recording.aedat4").is_none());
        for (input, problem) in [
            ("tcp://localhost", "no port"),
            ("tcp://:80", "no host"),
            ("tcp://host:99999", "not a number"),
            ("unix://relative.sock", "absolute"),
        ] {
            let message = Endpoint::parse(input).unwrap().unwrap_err().to_string();
            assert!(
                message.contains(problem) && message.contains(input),
                "{message}"
            );
        }
    }

    #[test]
    fn a_server_that_is_not_there_is_named() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap().to_string();
        drop(listener);
        let endpoint = Endpoint::parse(&format!("tcp://{address}"))
            .unwrap()
            .unwrap();
        let message = endpoint.connect(None).err().unwrap().to_string();
        assert!(
            message.contains(&address) && message.contains("cannot connect"),
            "{message}"
        );
    }

    #[test]
    fn a_peer_speaking_something_else_is_refused() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap().to_string();
        let server = std::thread::spawn(move || {
            let (mut peer, _) = listener.accept().unwrap();
            peer.write_all(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n")
                .unwrap();
        });
        let endpoint = Endpoint::parse(&format!("tcp://{address}"))
            .unwrap()
            .unwrap();
        let connection = endpoint.connect(None).unwrap();
        let message = endpoint
            .decoder(connection, None)
            .err()
            .unwrap()
            .to_string();
        assert!(
            message.contains("does not speak the AEDAT 4 network protocol")
                && message.contains(&address),
            "{message}"
        );
        server.join().unwrap();
    }
}
