//! A loaded network: one ONNX Runtime session, its validated metadata and the recurrent state
//! carried between windows.

use std::path::{Path, PathBuf};
use std::time::Instant;

use evgate_core::SensorSize;
use ort::ep;
use ort::session::builder::{GraphOptimizationLevel, SessionBuilder};
use ort::session::Session;
use ort::value::{Tensor, TensorRef, TensorValueType};

use crate::bound_state::BoundState;
use crate::contract::{
    self, ContractError, INPUT_HORIZONS, INPUT_STATES, INPUT_VOXEL, OUTPUT_FUTURE_FLOW,
    OUTPUT_FUTURE_MASK, OUTPUT_MASK, OUTPUT_STATES,
};
use crate::environment::{shared_environment, EnvironmentError};
use crate::identity;
use crate::library::{locate_onnxruntime, LibraryError};
use crate::metadata::{MetadataError, ModelMetadata};
use crate::options::{ActiveProvider, Provider, RuntimeOptions};
use crate::output::ForecastOutput;
use crate::state::RecurrentState;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error(transparent)]
    Library(#[from] LibraryError),
    #[error(transparent)]
    Environment(#[from] EnvironmentError),
    #[error(
        "model file {} does not exist; the committed model is models/evgate-S.onnx (pass another \
         with --model)",
        path.display()
    )]
    ModelMissing { path: PathBuf },
    #[error("cannot read model file {}: {source}", path.display())]
    ModelUnreadable {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot configure the onnx runtime session for {}: {source}", path.display())]
    Configure { path: PathBuf, source: ort::Error },
    #[error("onnx runtime cannot load the model {}: {source}", path.display())]
    Session { path: PathBuf, source: ort::Error },
    #[error("cannot read the metadata of model {}: {source}", path.display())]
    MetadataUnreadable { path: PathBuf, source: ort::Error },
    #[error("model {}: {source}", path.display())]
    Metadata {
        path: PathBuf,
        source: MetadataError,
    },
    #[error("model {} breaks docs/model-contract.md: {source}", path.display())]
    Contract {
        path: PathBuf,
        source: ContractError,
    },
    #[error(
        "voxel grid has {actual} values; model {} needs 2 × {height} × {width} = {expected} \
         (evgate_core::VoxelGrid::as_slice at the padded input size)",
        path.display()
    )]
    VoxelLength {
        path: PathBuf,
        actual: usize,
        expected: usize,
        height: usize,
        width: usize,
    },
    #[error("no forecast horizon given; pass at least one horizon in milliseconds")]
    NoHorizons,
    #[error(
        "forecast horizon #{index} is {value} ms; model {} accepts 0 to {max} ms",
        path.display()
    )]
    HorizonOutOfRange {
        path: PathBuf,
        index: usize,
        value: f32,
        max: f32,
    },
    #[error("running model {} failed: {source}", path.display())]
    Run { path: PathBuf, source: ort::Error },
    #[error(
        "model {} returned output `{name}` with shape {found:?}; expected {expected:?}",
        path.display()
    )]
    OutputShape {
        path: PathBuf,
        name: &'static str,
        found: Vec<i64>,
        expected: Vec<i64>,
    },
    #[error("model {} returned no float32 output `{name}`: {reason}", path.display())]
    OutputMissing {
        path: PathBuf,
        name: &'static str,
        reason: String,
    },
    #[error("cannot allocate the recurrent state for model {}: {source}", path.display())]
    State { path: PathBuf, source: ort::Error },
}

/// A network ready to forecast, with its recurrent state inside.
pub struct ModelRuntime {
    session: Session,
    model_path: PathBuf,
    model_id: u64,
    metadata: ModelMetadata,
    provider: ActiveProvider,
    state: RecurrentState,
    /// The state bound to the session's device (see [`crate::options::StateBinding`]).
    bound_state: Option<BoundState>,
}

impl ModelRuntime {
    /// Loads ONNX Runtime (once per process), the model, and checks the model against the
    /// contract.
    pub fn load(model_path: impl AsRef<Path>, options: RuntimeOptions) -> Result<Self, ModelError> {
        let path = model_path.as_ref().to_path_buf();
        if !path.is_file() {
            return Err(ModelError::ModelMissing { path });
        }
        let model_id = std::fs::read(&path)
            .map(|bytes| identity::model_id(&bytes))
            .map_err(|source| ModelError::ModelUnreadable {
                path: path.clone(),
                source,
            })?;
        let library = match &options.library {
            Some(library) => library.clone(),
            None => locate_onnxruntime()?,
        };
        let environment = shared_environment(&library)?;
        let configure = |source: ort::Error| ModelError::Configure {
            path: path.clone(),
            source,
        };
        let builder =
            configure_session(Session::builder(&environment).map_err(configure)?, &options)
                .map_err(configure)?;
        let (session, provider) = commit_with_provider(builder, &path, &options, || {
            configure_session(Session::builder(&environment)?, &options)
        })?;

        let raw = session
            .metadata()
            .map_err(|source| ModelError::MetadataUnreadable {
                path: path.clone(),
                source,
            })?;
        let metadata = ModelMetadata::from_lookup(|key| raw.custom(key)).map_err(|source| {
            ModelError::Metadata {
                path: path.clone(),
                source,
            }
        })?;
        drop(raw);
        contract::check_signature(session.inputs(), session.outputs(), &metadata).map_err(
            |source| ModelError::Contract {
                path: path.clone(),
                source,
            },
        )?;
        let state_error = |source: ort::Error| ModelError::State {
            path: path.clone(),
            source,
        };
        let state = RecurrentState::zeros(&metadata).map_err(state_error)?;
        let bound_state = if options.state_binding.binds_on(provider) {
            let shapes = std::array::from_fn(|stage| metadata.state_shape(stage));
            Some(
                BoundState::new(&session, &shapes, provider, options.cuda_device)
                    .map_err(state_error)?,
            )
        } else {
            None
        };
        tracing::info!(
            model = %path.display(),
            model_id = %format!("{model_id:016x}"),
            size = metadata.model_size.label(),
            input = %format!("{}x{}", metadata.input_width, metadata.input_height),
            %provider,
            threads = options.intra_threads,
            state_bound = bound_state.is_some(),
            "model loaded"
        );
        Ok(Self {
            session,
            model_path: path,
            model_id,
            metadata,
            provider,
            state,
            bound_state,
        })
    }

    /// Padded input size (W, H) the graph was exported for.
    pub fn input_size(&self) -> SensorSize {
        SensorSize::new(self.metadata.input_width, self.metadata.input_height)
    }

    pub fn metadata(&self) -> &ModelMetadata {
        &self.metadata
    }

    pub fn model_path(&self) -> &Path {
        &self.model_path
    }

    /// FNV-1a hash of the model file (the forecast header's `model_id`).
    pub fn model_id(&self) -> u64 {
        self.model_id
    }

    /// The execution provider in use after any fall-back.
    pub fn active_provider(&self) -> ActiveProvider {
        self.provider
    }

    /// Whether the recurrent state is bound to the session's device (see
    /// [`crate::options::StateBinding`]).
    pub fn state_bound(&self) -> bool {
        self.bound_state.is_some()
    }

    /// Windows fed since load or the last [`Self::reset_state`].
    pub fn windows_carried(&self) -> u64 {
        self.state.windows_carried()
    }

    /// Forgets the past: the next window starts from zero states (a new stream, a gap).
    pub fn reset_state(&mut self) -> Result<(), ModelError> {
        if let Some(bound) = &mut self.bound_state {
            bound.reset();
        }
        self.state.reset().map_err(|source| ModelError::State {
            path: self.model_path.clone(),
            source,
        })
    }

    /// Runs one empty window with `horizons_ms` and forgets it: ONNX Runtime sets much up on
    /// the first run of a shape (on CUDA, cuDNN's algorithm search), which a stream should not
    /// wait for. Returns how long that run took.
    pub fn warm_up(&mut self, horizons_ms: &[f32]) -> Result<std::time::Duration, ModelError> {
        let length = self.metadata.bins as usize * self.input_size().pixels();
        let started = Instant::now();
        self.forecast(&vec![0.0; length], horizons_ms)?;
        let elapsed = started.elapsed();
        self.reset_state()?;
        Ok(elapsed)
    }

    /// Runs one window: `voxel` is the `[2, H, W]` grid at the padded input size, `horizons_ms`
    /// the forecast horizons. On success the recurrent state advances by one window; on error
    /// it is left as it was.
    pub fn forecast(
        &mut self,
        voxel: &[f32],
        horizons_ms: &[f32],
    ) -> Result<ForecastOutput, ModelError> {
        let height = usize::from(self.metadata.input_height);
        let width = usize::from(self.metadata.input_width);
        let bins = self.metadata.bins as usize;
        self.check_inputs(voxel, horizons_ms, bins, height, width)?;
        let path = &self.model_path;
        let run_error = |source: ort::Error| ModelError::Run {
            path: path.clone(),
            source,
        };

        let voxel_shape = [1usize, bins, height, width];
        let horizon_count = horizons_ms.len() as i64;
        let (h, w) = (height as i64, width as i64);
        let (flow_height, flow_width) = self.metadata.flow_size();
        let take_forecast = |outputs: &mut ort::session::SessionOutputs<'_>| {
            Ok::<_, ModelError>([
                take_output(outputs, path, OUTPUT_MASK, vec![1, 1, h, w])?,
                take_output(
                    outputs,
                    path,
                    OUTPUT_FUTURE_MASK,
                    vec![1, horizon_count, h, w],
                )?,
                take_output(
                    outputs,
                    path,
                    OUTPUT_FUTURE_FLOW,
                    vec![1, horizon_count, 2, flow_height as i64, flow_width as i64],
                )?,
            ])
        };

        let started = Instant::now();
        let [mask_logits, future_mask_logits, future_flow] = match &mut self.bound_state {
            Some(bound) => {
                // Owned copies: binding a borrowed view would make ONNX Runtime clone it anyway.
                let voxel_tensor =
                    Tensor::from_array((voxel_shape, voxel.to_vec())).map_err(run_error)?;
                let horizons_tensor =
                    Tensor::from_array(([horizons_ms.len()], horizons_ms.to_vec()))
                        .map_err(run_error)?;
                let binding = bound
                    .bind(&voxel_tensor, &horizons_tensor, self.state.tensors())
                    .map_err(run_error)?;
                let mut outputs = self.session.run_binding(binding).map_err(run_error)?;
                let forecast = take_forecast(&mut outputs)?;
                drop(outputs);
                bound.commit();
                self.state.count_window();
                forecast
            }
            None => {
                let voxel_tensor =
                    TensorRef::from_array_view((voxel_shape, voxel)).map_err(run_error)?;
                let horizons_tensor =
                    TensorRef::from_array_view(([horizons_ms.len()], horizons_ms))
                        .map_err(run_error)?;
                let [state_0, state_1, state_2, state_3] = self.state.tensors();
                let inputs = ort::inputs! {
                    INPUT_VOXEL => voxel_tensor,
                    INPUT_HORIZONS => horizons_tensor,
                    INPUT_STATES[0] => state_0,
                    INPUT_STATES[1] => state_1,
                    INPUT_STATES[2] => state_2,
                    INPUT_STATES[3] => state_3,
                };
                let mut outputs = self.session.run(inputs).map_err(run_error)?;
                let forecast = take_forecast(&mut outputs)?;
                let state_shape = |stage: usize| self.state.shape(stage).map(|d| d as i64).to_vec();
                let next_state = [
                    take_output(&mut outputs, path, OUTPUT_STATES[0], state_shape(0))?,
                    take_output(&mut outputs, path, OUTPUT_STATES[1], state_shape(1))?,
                    take_output(&mut outputs, path, OUTPUT_STATES[2], state_shape(2))?,
                    take_output(&mut outputs, path, OUTPUT_STATES[3], state_shape(3))?,
                ];
                drop(outputs);
                self.state.advance(next_state);
                forecast
            }
        };
        let inference_time = started.elapsed();
        Ok(ForecastOutput {
            height,
            width,
            horizons_ms: horizons_ms.to_vec(),
            mask_logits,
            future_mask_logits,
            future_flow,
            flow_height,
            flow_width,
            inference_time,
        })
    }

    fn check_inputs(
        &self,
        voxel: &[f32],
        horizons_ms: &[f32],
        bins: usize,
        height: usize,
        width: usize,
    ) -> Result<(), ModelError> {
        let expected = bins * height * width;
        if voxel.len() != expected {
            return Err(ModelError::VoxelLength {
                path: self.model_path.clone(),
                actual: voxel.len(),
                expected,
                height,
                width,
            });
        }
        if horizons_ms.is_empty() {
            return Err(ModelError::NoHorizons);
        }
        let max = self.metadata.max_horizon_ms;
        if let Some((index, &value)) = horizons_ms
            .iter()
            .enumerate()
            .find(|(_, h)| !(0.0..=max).contains(*h))
        {
            return Err(ModelError::HorizonOutOfRange {
                path: self.model_path.clone(),
                index,
                value,
                max,
            });
        }
        Ok(())
    }
}

fn configure_session(
    builder: SessionBuilder,
    options: &RuntimeOptions,
) -> ort::Result<SessionBuilder> {
    let mut builder = builder
        .with_optimization_level(GraphOptimizationLevel::All)?
        .with_inter_threads(1)?
        .with_intra_op_spinning(options.spin_threads)?
        .with_inter_op_spinning(false)?
        // The memory pattern pre-plans one block for every intermediate tensor of a run; with
        // the committed S model at 352×272 and 8 horizons that block kept evgate-infer at
        // 235 MiB resident against 152 MiB without it, at the same CPU time per call (the
        // arena then reuses freed tensors' memory); `git show dd99da7:BENCHMARKS.md`, "Pipeline".
        .with_memory_pattern(false)?;
    if options.intra_threads > 0 {
        builder = builder.with_intra_threads(options.intra_threads)?;
    }
    Ok(builder)
}

/// Registers the CUDA provider when asked for and commits the session; any CUDA failure
/// (provider missing from the library, no device, missing CUDA libraries) falls back to a CPU
/// session built by `cpu_builder`, logged.
fn commit_with_provider(
    builder: SessionBuilder,
    path: &Path,
    options: &RuntimeOptions,
    cpu_builder: impl Fn() -> ort::Result<SessionBuilder>,
) -> Result<(Session, ActiveProvider), ModelError> {
    let session_error = |source: ort::Error| ModelError::Session {
        path: path.to_path_buf(),
        source,
    };
    if options.provider == Provider::Cpu {
        let mut builder = builder;
        let session = builder.commit_from_file(path).map_err(session_error)?;
        return Ok((session, ActiveProvider::Cpu));
    }
    let cuda = ep::CUDA::default()
        .with_device_id(options.cuda_device)
        .build()
        .error_on_failure();
    let failure = match builder.with_execution_providers([cuda]) {
        Ok(mut cuda_builder) => match cuda_builder.commit_from_file(path) {
            Ok(session) => return Ok((session, ActiveProvider::Cuda)),
            Err(error) => format!("the session did not start on CUDA: {error}"),
        },
        Err(error) => format!("the CUDA provider did not register: {error}"),
    };
    let hint = "the CUDA build of the library comes from \
                `EVGATE_ORT_PACKAGE=onnxruntime-gpu bash scripts/fetch-onnxruntime.sh`";
    if options.provider == Provider::Cuda {
        tracing::warn!(model = %path.display(), %failure, hint, "cuda requested; falling back to cpu");
    } else {
        tracing::info!(model = %path.display(), %failure, "cuda unavailable; using cpu");
    }
    let session = cpu_builder()
        .map_err(|source| ModelError::Configure {
            path: path.to_path_buf(),
            source,
        })?
        .commit_from_file(path)
        .map_err(session_error)?;
    Ok((session, ActiveProvider::Cpu))
}

fn take_output(
    outputs: &mut ort::session::SessionOutputs<'_>,
    path: &Path,
    name: &'static str,
    expected: Vec<i64>,
) -> Result<Tensor<f32>, ModelError> {
    let missing = |reason: String| ModelError::OutputMissing {
        path: path.to_path_buf(),
        name,
        reason,
    };
    let value = outputs
        .remove(name)
        .ok_or_else(|| missing("absent from the run's outputs".to_owned()))?;
    let tensor = value
        .downcast::<TensorValueType<f32>>()
        .map_err(|error| missing(error.to_string()))?;
    let (shape, _) = tensor
        .try_extract_tensor::<f32>()
        .map_err(|error| missing(error.to_string()))?;
    if shape.iter().as_slice() != expected.as_slice() {
        return Err(ModelError::OutputShape {
            path: path.to_path_buf(),
            name,
            found: shape.to_vec(),
            expected,
        });
    }
    Ok(tensor)
}
