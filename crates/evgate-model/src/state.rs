//! The ConvGRU hidden states carried from one window to the next.
//!
//! The tensors a run returns as `new_state_i` become the next run's `state_i` as they are, so
//! carrying the state costs no copy.

use ort::value::Tensor;

use crate::metadata::{ModelMetadata, STATE_COUNT};

pub struct RecurrentState {
    shapes: [[usize; 4]; STATE_COUNT],
    tensors: [Tensor<f32>; STATE_COUNT],
    windows_carried: u64,
}

impl RecurrentState {
    /// Zero states, the contract's start of a stream.
    pub fn zeros(metadata: &ModelMetadata) -> ort::Result<Self> {
        let shapes: [[usize; 4]; STATE_COUNT] =
            std::array::from_fn(|stage| metadata.state_shape(stage));
        Ok(Self {
            shapes,
            tensors: zero_tensors(&shapes)?,
            windows_carried: 0,
        })
    }

    pub fn reset(&mut self) -> ort::Result<()> {
        self.tensors = zero_tensors(&self.shapes)?;
        self.windows_carried = 0;
        Ok(())
    }

    pub fn tensors(&self) -> &[Tensor<f32>; STATE_COUNT] {
        &self.tensors
    }

    pub fn shape(&self, stage: usize) -> [usize; 4] {
        self.shapes[stage]
    }

    /// Installs the states a run produced.
    pub fn advance(&mut self, next: [Tensor<f32>; STATE_COUNT]) {
        self.tensors = next;
        self.windows_carried += 1;
    }

    /// Counts a window whose states were kept elsewhere (bound to the session's device), so
    /// these tensors stay the zero states.
    pub fn count_window(&mut self) {
        self.windows_carried += 1;
    }

    /// Windows seen since the last reset.
    pub fn windows_carried(&self) -> u64 {
        self.windows_carried
    }
}

fn zero_tensors(shapes: &[[usize; 4]; STATE_COUNT]) -> ort::Result<[Tensor<f32>; STATE_COUNT]> {
    let [a, b, c, d] = shapes.map(|shape| {
        let elements = shape.iter().product::<usize>();
        Tensor::from_array((shape, vec![0.0_f32; elements]))
    });
    Ok([a?, b?, c?, d?])
}
