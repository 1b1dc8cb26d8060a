//! Flight logs a user can look at: `log stats`, `log export` (CSV, MCAP), `log plot` (PNG
//! figures in the paper's layout) and replay of a tlog as the daemon's vehicle.
//!
//! Every part reads tlogs through the one streaming reader of [`crate::tlog`], so garbage
//! between records and a torn last record are handled (and reported) the same way everywhere.
//! Nothing here prints: the binary renders the reports and owns the progress bar, which it
//! feeds through the `progress` callbacks (bytes consumed so far).

pub mod export;
pub mod plot;
pub mod replay;
pub mod stats;

use std::path::{Path, PathBuf};

use crate::tlog::TlogReader;

/// Why a log command failed.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The input could not be opened or read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// An output could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// File.
        path: PathBuf,
        /// Cause.
        message: String,
    },
    /// A simulate CSV without the columns a figure needs, or with a value that is not a number.
    #[error("{path}: {message}")]
    Csv {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The request cannot be honoured with this input (e.g. control inputs from a tlog).
    #[error("{0}")]
    Unsupported(String),
}

/// Opens a tlog for streaming and returns it with the file's size (for progress).
///
/// # Errors
/// [`LogError::Read`].
pub fn open_tlog(path: &Path) -> Result<(TlogReader, u64), LogError> {
    let read_err = |source| LogError::Read {
        path: path.to_owned(),
        source,
    };
    let size = std::fs::metadata(path).map_err(read_err)?.len();
    let reader = TlogReader::open(path).map_err(read_err)?;
    Ok((reader, size))
}

/// How the log at `path` tells a record's direction, from its first records (see
/// [`crate::tlog::Directions`]).
///
/// # Errors
/// [`LogError::Read`].
pub fn directions(path: &Path) -> Result<crate::tlog::Directions, LogError> {
    let reader = TlogReader::open(path).map_err(|source| LogError::Read {
        path: path.to_owned(),
        source,
    })?;
    Ok(crate::tlog::Directions::detect(reader))
}

/// Ends a scan: a read error in the middle of the file is an error (the report would be
/// silently short), a torn tail or garbage is not.
///
/// # Errors
/// [`LogError::Read`] if the reader stopped on an I/O error.
pub fn finish_read(reader: &mut TlogReader, path: &Path) -> Result<(), LogError> {
    match reader.io_error.take() {
        Some(source) => Err(LogError::Read {
            path: path.to_owned(),
            source,
        }),
        None => Ok(()),
    }
}
