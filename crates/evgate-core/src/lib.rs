//! Core types of evgate: no I/O, no async, no allocation on the hot paths beyond what the caller
//! hands in.

pub mod event;
pub mod gate;
pub mod geometry;
pub mod mask;
pub mod voxel;
pub mod warp;
pub mod window;

pub use event::{is_event_time, Event, Polarity, MAX_EVENT_TIME_US};
pub use gate::{keep_bitmap, partition, ForecastView, GateCounts, GateError, GateMode};
pub use geometry::SensorSize;
pub use mask::{words_for, BitMask, MaskError, MaskView};
pub use voxel::{NonZeroStats, SplatCounts, VoxelError, VoxelGrid, PADDING_MULTIPLE};
pub use warp::{warp_backward, WarpError};
pub use window::{
    events_in, windows_by_count, TimeSpan, TimeWindow, WindowError, WindowsByDuration,
};
