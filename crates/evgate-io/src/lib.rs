//! Event file decoders and encoders, and the labelled-sequence `.npz` format shared by the
//! simulator, training and evaluation.
//!
//! Reading: [`open`] detects the format (magic bytes, `%` header, extension) and returns a
//! streaming [`EventReader`]; memory stays bounded whatever the file size. What a decoder
//! drops, skips or finds out of order is counted in its [`DecodeReport`] (policy in
//! [`report`]). Writing: [`create`] picks an [`EventWriter`] by extension.

pub mod aedat4;
pub mod aedat4_stream_writer;
pub mod csv;
pub mod csv_writer;
pub mod dat;
#[cfg(feature = "dsec")]
pub mod dsec;
pub mod error;
pub mod evimo;
pub mod evimo2_events;
pub mod evimo_recording;
pub mod evt2;
pub mod evt3;
pub mod evt3_writer;
pub mod flatbuffer;
pub mod format;
pub mod header;
pub mod native;
pub mod native_writer;
pub mod network;
pub mod npy;
pub mod npz;
pub mod pickle;
pub mod pyvalue;
pub mod reader;
pub mod records;
pub mod report;
pub mod sequence;
pub mod source;
pub mod stream_decoder;
pub mod time_high;
pub mod writer;

pub use error::DecodeError;
pub use evimo_recording::{
    EvimoError, EvimoLayout, EvimoRecording, GtFrame, GtFrameInfo, GtFrames,
};
pub use evt3::Evt3TimeLow;
pub use format::{detect, Format};
pub use reader::{open, open_with, open_with_time_low_rule, read_all, EventReader, OpenOptions};
pub use report::DecodeReport;
pub use sequence::{LabelledSequence, SequenceError};
pub use writer::{create, create_as, EncodeError, EventWriter};
