//! Event file decoders and encoders, and the labelled-sequence `.npz` format shared by the
//! simulator, training and evaluation.

pub mod npy;
pub mod npz;
pub mod sequence;

pub use sequence::{LabelledSequence, SequenceError};
