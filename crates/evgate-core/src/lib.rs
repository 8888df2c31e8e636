//! Core types of evgate: no I/O, no async, no allocation on the hot paths beyond what the caller
//! hands in.

pub mod bitset;
pub mod dilation;
pub mod event;
pub mod gate;
pub mod geometry;
pub mod judge;
pub mod mask;
pub mod voxel;
pub mod window;

pub use bitset::words_for;
pub use dilation::{dilate_logits, dilate_mask, DilationScratch};
pub use event::{is_event_time, Event, Polarity, MAX_EVENT_TIME_US};
pub use gate::{ForecastView, GateCounts, GateError, GateMode};
pub use geometry::SensorSize;
pub use judge::{EventSink, Forecast, Judge, NoForecast, Policy, Verdict};
pub use mask::{BitMask, MaskError, MaskView};
pub use voxel::{NonZeroStats, SplatCounts, VoxelError, VoxelGrid, PADDING_MULTIPLE};
pub use window::{events_in, TimeSpan, WindowError};
