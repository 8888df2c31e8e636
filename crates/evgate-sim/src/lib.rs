//! evgate-sim: a synthetic event camera with ground truth.
//!
//! A pinhole camera with smooth 6-DoF ego-motion looks at a static world of textured planes at
//! several depths and at independently moving textured objects. The static world is ray-cast
//! as often as its own image motion requires (and interpolated in between), the objects as
//! often as theirs, and an ESIM-style pixel model (per-pixel thresholds,
//! interpolated timestamps, refractory period, shot and leak noise, hot pixels) turns log
//! intensity changes into events labelled with the surface that caused them. Ground truth
//! (instance masks, depth, forward flow over any horizon) can be queried at any time.
//!
//! ```no_run
//! use evgate_sim::{Preset, Simulator};
//! let mut sim = Simulator::from_preset(Preset::Boxes, 1);
//! let mut events = Vec::new();
//! sim.advance(50_000, &mut events); // events in (0, 50 ms]
//! let mask = sim.mask_at(50_000);
//! let flow = sim.flow(50_000, 20_000);
//! ```

pub mod atlas;
pub mod camera;
pub mod config;
pub mod domain;
pub mod esim;
pub mod event_model;
pub mod event_sort;
mod index_lanes;
pub mod linalg;
pub mod motion;
pub mod noise;
pub mod photo;
pub mod preset;
pub mod readout_delay;
pub mod render;
pub mod scene;
pub mod sequence;
pub mod silhouette;
pub mod simulator;
pub mod suite;
pub mod texture;
mod variation;
pub mod world;

pub use camera::Intrinsics;
pub use config::{Layout, ObjectVariation, SceneParams, SimConfig};
pub use domain::{randomised_config, Domain};
pub use esim::LabelledEvent;
pub use event_model::EventModel;
pub use preset::{Preset, UnknownPreset};
pub use render::Frame;
pub use sequence::{simulate_sequence, SequenceOptions};
pub use simulator::{SimStats, Simulator, SimulatorError, Surfaces};
pub use suite::{suite_plan, Split, SuiteEntry, SuiteScale, SUITE_VERSION};
