//! The recurrent state bound to the session's device with ONNX Runtime's I/O binding, so that a
//! CUDA session keeps it in GPU memory between windows instead of copying every state tensor to
//! the host and back each run (37 MB each way for L at 640×480).
//!
//! Two sets of state tensors alternate: a run reads one set and writes the other, because a
//! tensor bound as both input and output of one run could be overwritten while the graph still
//! reads it (ONNX Runtime promises nothing about the order). The set written becomes the next run's input only once the run succeeded, so
//! a failed run leaves the state as it was. Until the first run after load or reset, the inputs
//! are the host's zero tensors, which ONNX Runtime copies to the device once.

use ort::memory::{AllocationDevice, Allocator, AllocatorType, MemoryInfo, MemoryType};
use ort::session::{IoBinding, Session};
use ort::value::Tensor;

use crate::contract::{
    INPUT_HORIZONS, INPUT_STATES, INPUT_VOXEL, OUTPUT_FUTURE_FLOW, OUTPUT_FUTURE_MASK, OUTPUT_MASK,
    OUTPUT_STATES,
};
use crate::metadata::STATE_COUNT;
use crate::options::ActiveProvider;

pub struct BoundState {
    binding: IoBinding,
    sets: [[Tensor<f32>; STATE_COUNT]; 2],
    /// The set holding the last successful run's states; `None` means zero states.
    latest: Option<usize>,
    host_memory: MemoryInfo<'static>,
}

impl BoundState {
    /// Allocates both state sets on the memory of `provider` (device `cuda_device` for CUDA).
    pub fn new(
        session: &Session,
        shapes: &[[usize; 4]; STATE_COUNT],
        provider: ActiveProvider,
        cuda_device: i32,
    ) -> ort::Result<Self> {
        let host_memory = MemoryInfo::new(
            AllocationDevice::CPU,
            0,
            AllocatorType::Device,
            MemoryType::Default,
        )?;
        let state_memory = match provider {
            ActiveProvider::Cpu => host_memory.clone(),
            ActiveProvider::Cuda => MemoryInfo::new(
                AllocationDevice::CUDA,
                cuda_device,
                AllocatorType::Device,
                MemoryType::Default,
            )?,
        };
        let allocator = Allocator::new(session, state_memory)?;
        let allocate_set = || -> ort::Result<[Tensor<f32>; STATE_COUNT]> {
            let [a, b, c, d] = shapes.map(|shape| Tensor::<f32>::new(&allocator, shape));
            Ok([a?, b?, c?, d?])
        };
        let sets = [allocate_set()?, allocate_set()?];
        Ok(Self {
            binding: session.create_binding()?,
            sets,
            latest: None,
            host_memory,
        })
    }

    /// The next run starts from zero states.
    pub fn reset(&mut self) {
        self.latest = None;
    }

    /// Binds one run's inputs and outputs: the state tensors of the last run (or `zeros`) in,
    /// the other set out, and the forecast outputs to host memory.
    pub fn bind(
        &mut self,
        voxel: &Tensor<f32>,
        horizons: &Tensor<f32>,
        zeros: &[Tensor<f32>; STATE_COUNT],
    ) -> ort::Result<&IoBinding> {
        self.binding.bind_input(INPUT_VOXEL, voxel)?;
        self.binding.bind_input(INPUT_HORIZONS, horizons)?;
        for stage in 0..STATE_COUNT {
            let source = match self.latest {
                Some(latest) => &self.sets[latest][stage],
                None => &zeros[stage],
            };
            self.binding.bind_input(INPUT_STATES[stage], source)?;
        }
        let target = self.target();
        for (stage, tensor) in self.sets[target].iter_mut().enumerate() {
            self.binding.bind_output(OUTPUT_STATES[stage], tensor)?;
        }
        // Rebound every run: an output left bound keeps its buffer, whose shape is wrong once
        // the number of horizons changes.
        for name in [OUTPUT_MASK, OUTPUT_FUTURE_MASK, OUTPUT_FUTURE_FLOW] {
            self.binding
                .bind_output_to_device(name, &self.host_memory)?;
        }
        Ok(&self.binding)
    }

    /// Makes the states the run just wrote the next run's inputs.
    pub fn commit(&mut self) {
        self.latest = Some(self.target());
    }

    /// The set the next run writes: the one the last run did not.
    fn target(&self) -> usize {
        self.latest.map_or(0, |latest| 1 - latest)
    }
}
