//! The error every decoder returns: it always names the file and, where there is one, the byte
//! offset of the problem.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    #[error("{path}: cannot open: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: read error at byte offset {offset}: {source}")]
    Io {
        path: PathBuf,
        offset: u64,
        source: std::io::Error,
    },
    #[error(
        "{path}: truncated at byte offset {offset}: {what} needs {needed} bytes, only {found} left"
    )]
    Truncated {
        path: PathBuf,
        offset: u64,
        what: &'static str,
        needed: usize,
        found: usize,
    },
    #[error("{path}: bad header at byte offset {offset}: {problem}")]
    BadHeader {
        path: PathBuf,
        offset: u64,
        problem: String,
    },
    #[error("{path}: malformed data at byte offset {offset}: {problem}")]
    Malformed {
        path: PathBuf,
        offset: u64,
        problem: String,
    },
    #[error("{path}: {problem}")]
    Unrecognised { path: PathBuf, problem: String },
    /// A problem in one dataset of an HDF5 file (DSEC).
    #[error("{path}: dataset `{dataset}`: {problem}")]
    Dataset {
        path: PathBuf,
        dataset: String,
        problem: String,
    },
}
