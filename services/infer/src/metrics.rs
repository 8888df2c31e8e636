//! What `--metrics-addr` serves: how long each forecast took and how many went out.

use evgate_ipc::metrics::{duration_histogram, MetricsError, MetricsServer};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;

use crate::worker::ForecastReady;

pub struct InferMetrics {
    processing: Histogram,
    latency: Histogram,
    windows_closed: Counter,
    windows_skipped: Counter,
    forecasts_published: Counter,
    events_received: Counter,
    _server: MetricsServer,
}

impl InferMetrics {
    pub fn serve(addr: &str) -> Result<Self, MetricsError> {
        let processing = duration_histogram();
        let latency = duration_histogram();
        let [windows_closed, windows_skipped, forecasts_published, events_received] =
            std::array::from_fn(|_| Counter::default());
        let mut registry = Registry::default();
        registry.register(
            "evgate_inference_seconds",
            "model runtime per window: voxelisation, inference and thresholding",
            processing.clone(),
        );
        registry.register(
            "evgate_forecast_latency_seconds",
            "window closed to its forecast published (the runtime plus any queueing)",
            latency.clone(),
        );
        registry.register(
            "evgate_windows_closed",
            "windows of events closed for inference",
            windows_closed.clone(),
        );
        registry.register(
            "evgate_windows_skipped",
            "closed windows displaced by a newer one while the model was busy",
            windows_skipped.clone(),
        );
        registry.register(
            "evgate_forecasts_published",
            "forecasts published",
            forecasts_published.clone(),
        );
        registry.register(
            "evgate_infer_events_received",
            "events the inference service received",
            events_received.clone(),
        );
        Ok(Self {
            processing,
            latency,
            windows_closed,
            windows_skipped,
            forecasts_published,
            events_received,
            _server: MetricsServer::serve(addr, registry)?,
        })
    }

    pub fn record_events(&self, count: u64) {
        self.events_received.inc_by(count);
    }

    pub fn record_window(&self, skipped: bool) {
        self.windows_closed.inc();
        if skipped {
            self.windows_skipped.inc();
        }
    }

    pub fn record_forecast(&self, ready: &ForecastReady) {
        self.forecasts_published.inc();
        self.processing.observe(ready.processing().as_secs_f64());
        self.latency
            .observe(ready.closed_at.elapsed().as_secs_f64());
    }
}
