//! One forecast: the network's outputs for one window, borrowed straight from ONNX Runtime's
//! buffers (no copy), plus how long the run took.

use std::time::Duration;

use ort::value::Tensor;

/// Outputs of [`crate::ModelRuntime::forecast`]. Mask planes are row-major `height × width` at
/// the padded input size; flow planes `flow_height × flow_width` (the input size divided by the
/// model's `evgate.flow-stride`).
#[derive(Debug)]
pub struct ForecastOutput {
    pub(crate) height: usize,
    pub(crate) width: usize,
    pub(crate) horizons_ms: Vec<f32>,
    pub(crate) mask_logits: Tensor<f32>,
    pub(crate) future_mask_logits: Tensor<f32>,
    pub(crate) future_flow: Tensor<f32>,
    pub(crate) flow_height: usize,
    pub(crate) flow_width: usize,
    pub(crate) inference_time: Duration,
}

impl ForecastOutput {
    pub fn height(&self) -> usize {
        self.height
    }

    pub fn width(&self) -> usize {
        self.width
    }

    /// The horizons (ms) this forecast was asked for, in the caller's order.
    pub fn horizons_ms(&self) -> &[f32] {
        &self.horizons_ms
    }

    pub fn horizon_count(&self) -> usize {
        self.horizons_ms.len()
    }

    /// Mask logits at the window's reference time (logit > 0 ⇔ independently moving).
    pub fn mask_logits(&self) -> &[f32] {
        self.mask_logits.extract_tensor().1
    }

    /// Mask logits at reference time + h for every requested horizon h, in `horizons_ms()` order.
    pub fn future_mask_logits(&self) -> std::slice::ChunksExact<'_, f32> {
        self.future_mask_logits
            .extract_tensor()
            .1
            .chunks_exact(self.height * self.width)
    }

    /// Height of each flow plane: `height()` divided by the model's flow stride.
    pub fn flow_height(&self) -> usize {
        self.flow_height
    }

    /// Width of each flow plane: `width()` divided by the model's flow stride.
    pub fn flow_width(&self) -> usize {
        self.flow_width
    }

    /// Predicted displacement in input pixels over each horizon, as (dx plane, dy plane) of
    /// `flow_height() × flow_width()`, in `horizons_ms()` order.
    pub fn future_flows(&self) -> impl Iterator<Item = (&[f32], &[f32])> {
        let plane = self.flow_height * self.flow_width;
        self.future_flow
            .extract_tensor()
            .1
            .chunks_exact(2 * plane)
            .map(move |pair| pair.split_at(plane))
    }

    /// Wall time of the ONNX Runtime call.
    pub fn inference_time(&self) -> Duration {
        self.inference_time
    }
}
