//! What `evgate run --metrics-addr` serves: the gate's counters from the stats stream, and the
//! model runtime and prediction age that each stats publication carries, as histograms
//! sampled once per publication (the gate publishes every 100 ms).

use evgate_ipc::metrics::{duration_histogram, MetricsError, MetricsServer, PipelineCounters};
use evgate_ipc::stats::NOT_MEASURED;
use evgate_ipc::PipelineStats;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;

pub struct RunMetrics {
    counters: PipelineCounters,
    model_runtime: Histogram,
    prediction_age: Histogram,
    last_sequence: Option<u64>,
    _server: MetricsServer,
}

impl RunMetrics {
    pub fn serve(addr: &str) -> Result<Self, MetricsError> {
        let counters = PipelineCounters::default();
        let model_runtime = duration_histogram();
        let prediction_age = duration_histogram();
        let mut registry = Registry::default();
        counters.register(&mut registry);
        registry.register(
            "evgate_inference_seconds",
            "model runtime of the latest forecast, sampled at each stats publication",
            model_runtime.clone(),
        );
        registry.register(
            "evgate_prediction_age_seconds",
            "age of the forecast that judged the latest batch, sampled at each stats publication",
            prediction_age.clone(),
        );
        Ok(Self {
            counters,
            model_runtime,
            prediction_age,
            last_sequence: None,
            _server: MetricsServer::serve(addr, registry)?,
        })
    }

    /// Takes a stats sample; one already taken changes nothing.
    pub fn update(&mut self, stats: &PipelineStats) {
        if self.last_sequence == Some(stats.sequence) {
            return;
        }
        self.last_sequence = Some(stats.sequence);
        self.counters.update(stats);
        for (value_us, histogram) in [
            (stats.latest_model_runtime_us, &self.model_runtime),
            (stats.latest_prediction_age_us, &self.prediction_age),
        ] {
            if value_us != NOT_MEASURED {
                histogram.observe(value_us as f64 * 1e-6);
            }
        }
    }
}
