//! Core types of evgate: no I/O, no async, no allocation on the hot paths beyond what the caller
//! hands in.

pub mod event;
pub mod geometry;

pub use event::{Event, Polarity};
pub use geometry::SensorSize;
