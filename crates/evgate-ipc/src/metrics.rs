//! `--metrics-addr HOST:PORT`: Prometheus text at `/metrics` (prometheus-client's OpenMetrics
//! encoding, served by tiny_http on a thread of its own), so a service's numbers can be scraped
//! while it runs. Every name starts with `evgate_`; docs/pipeline.md lists them.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;

use crate::stats::PipelineStats;

/// Why the metrics endpoint could not start.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("cannot serve metrics on --metrics-addr {addr}: {source}")]
    Bind {
        addr: String,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// The endpoint; stops serving when dropped.
pub struct MetricsServer {
    server: Arc<tiny_http::Server>,
    thread: Option<JoinHandle<()>>,
    local_addr: Option<SocketAddr>,
}

impl MetricsServer {
    /// Serves `registry` at `http://addr/metrics` (404 elsewhere) until dropped.
    pub fn serve(addr: &str, registry: Registry) -> Result<Self, MetricsError> {
        let server = tiny_http::Server::http(addr).map_err(|source| MetricsError::Bind {
            addr: addr.to_owned(),
            source,
        })?;
        let server = Arc::new(server);
        let local_addr = server.server_addr().to_ip();
        let serving = Arc::clone(&server);
        let thread = std::thread::Builder::new()
            .name("evgate-metrics".to_owned())
            .spawn(move || answer_requests(&serving, &registry))
            .map_err(|source| MetricsError::Bind {
                addr: addr.to_owned(),
                source: Box::new(source),
            })?;
        tracing::info!(addr = ?local_addr, "serving Prometheus metrics at /metrics");
        Ok(Self {
            server,
            thread: Some(thread),
            local_addr,
        })
    }

    /// The address it listens on (the port the system chose for port 0).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }
}

impl Drop for MetricsServer {
    fn drop(&mut self) {
        self.server.unblock();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn answer_requests(server: &tiny_http::Server, registry: &Registry) {
    for request in server.incoming_requests() {
        let response = if request.url() == "/metrics" {
            let mut text = String::new();
            match prometheus_client::encoding::text::encode(&mut text, registry) {
                Ok(()) => tiny_http::Response::from_string(text).with_header(
                    tiny_http::Header::from_bytes(
                        "Content-Type",
                        "application/openmetrics-text; version=1.0.0; charset=utf-8",
                    )
                    .expect("a valid header"),
                ),
                Err(_) => tiny_http::Response::from_string("cannot encode the metrics\n")
                    .with_status_code(500),
            }
        } else {
            tiny_http::Response::from_string("evgate serves /metrics only\n").with_status_code(404)
        };
        // A scraper that hung up needs no answer.
        let _ = request.respond(response);
    }
}

/// Histogram buckets for durations from 100 µs to about 1.6 s, in seconds.
pub fn duration_buckets() -> impl Iterator<Item = f64> {
    prometheus_client::metrics::histogram::exponential_buckets(1e-4, 2.0, 15)
}

/// A histogram of durations in seconds with [`duration_buckets`].
pub fn duration_histogram() -> Histogram {
    Histogram::new(duration_buckets())
}

/// The gate's counters, read from the latest [`PipelineStats`] at each scrape.
#[derive(Debug, Clone, Default)]
pub struct PipelineCounters {
    latest: Arc<Mutex<PipelineStats>>,
}

impl PipelineCounters {
    /// Makes `stats` what the next scrape reports.
    pub fn update(&self, stats: &PipelineStats) {
        *self.latest.lock().unwrap_or_else(PoisonError::into_inner) = *stats;
    }

    /// Registers these counters in `registry`.
    pub fn register(&self, registry: &mut Registry) {
        registry.register_collector(Box::new(self.clone()));
    }
}

impl Collector for PipelineCounters {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let stats = *self.latest.lock().unwrap_or_else(PoisonError::into_inner);
        let counters: [(&str, &str, u64); 10] = [
            (
                "evgate_events_in",
                "events the source published",
                stats.input_events,
            ),
            (
                "evgate_events_kept",
                "events a forecast judged and the mode kept",
                stats.kept_events,
            ),
            (
                "evgate_events_suppressed",
                "events a forecast judged and the mode suppressed",
                stats.suppressed_events,
            ),
            (
                "evgate_events_unjudged_passed",
                "events no valid forecast judged, passed by --no-forecast",
                stats.unjudged_passed_events,
            ),
            (
                "evgate_events_unjudged_dropped",
                "events no valid forecast judged, dropped by --no-forecast",
                stats.unjudged_dropped_events,
            ),
            (
                "evgate_events_dropped",
                "events lost before the gate (a full input buffer or a gap at the source)",
                stats.dropped_events,
            ),
            (
                "evgate_forecasts_received",
                "forecasts the gate received",
                stats.forecasts_received,
            ),
            (
                "evgate_forecasts_used",
                "batches a forecast judged",
                stats.forecasts_used,
            ),
            (
                "evgate_forecasts_rejected",
                "forecasts refused as malformed",
                stats.forecasts_rejected,
            ),
            (
                "evgate_output_samples_undelivered",
                "output samples a full subscriber did not get",
                stats.output_samples_undelivered,
            ),
        ];
        for (name, help, value) in counters {
            let counter = ConstCounter::new(value);
            let metric = encoder.encode_descriptor(name, help, None, counter.metric_type())?;
            counter.encode(metric)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};

    fn get(addr: SocketAddr, path: &str) -> String {
        let mut stream = std::net::TcpStream::connect(addr).unwrap();
        write!(stream, "GET {path} HTTP/1.0\r\nHost: localhost\r\n\r\n").unwrap();
        let mut response = String::new();
        stream.read_to_string(&mut response).unwrap();
        response
    }

    #[test]
    fn a_scrape_reads_the_latest_stats_and_the_histograms() {
        let counters = PipelineCounters::default();
        let latency = duration_histogram();
        let mut registry = Registry::default();
        counters.register(&mut registry);
        registry.register(
            "evgate_test_latency_seconds",
            "a test histogram",
            latency.clone(),
        );
        let server = MetricsServer::serve("127.0.0.1:0", registry).unwrap();
        let addr = server.local_addr().unwrap();

        let stats = PipelineStats {
            input_events: 10,
            kept_events: 3,
            suppressed_events: 7,
            forecasts_received: 2,
            ..PipelineStats::default()
        };
        counters.update(&stats);
        latency.observe(0.002);
        let response = get(addr, "/metrics");
        assert!(response.starts_with("HTTP/1.1 200") || response.starts_with("HTTP/1.0 200"));
        for line in [
            "evgate_events_in_total 10",
            "evgate_events_kept_total 3",
            "evgate_events_suppressed_total 7",
            "evgate_forecasts_received_total 2",
            "evgate_test_latency_seconds_count 1",
            "# TYPE evgate_events_in counter",
        ] {
            assert!(response.contains(line), "{line} missing from\n{response}");
        }
        assert!(get(addr, "/other").contains("404"));
    }

    #[test]
    fn a_taken_address_is_an_error_naming_it() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = taken.local_addr().unwrap().to_string();
        let message = MetricsServer::serve(&addr, Registry::default())
            .err()
            .unwrap()
            .to_string();
        assert!(message.contains(&addr), "{message}");
    }
}
