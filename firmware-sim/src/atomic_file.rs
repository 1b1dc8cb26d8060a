//! Whole-file writes that a crash cannot tear: the twin's parameter and mission files.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed to disk,
/// then renamed over `path`, so a crash leaves either the old file or the new one.
///
/// # Errors
/// The I/O error of the step that failed.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temporary_beside(path);
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, path)
}

/// A text file of the twin's (parameters, mission) that cannot be read, written or parsed.
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line cannot be used.
    #[error("{path}:{line}: {reason}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// Reads `path` as UTF-8 text.
///
/// # Errors
/// [`TextFileError::Io`].
pub fn read_text(path: &Path) -> Result<String, TextFileError> {
    std::fs::read_to_string(path).map_err(|source| TextFileError::Io {
        path: path.to_owned(),
        source,
    })
}

/// [`write`] of `text`.
///
/// # Errors
/// [`TextFileError::Io`], of the step that failed.
pub fn write_text(path: &Path, text: &str) -> Result<(), TextFileError> {
    write(path, text.as_bytes()).map_err(|source| TextFileError::Io {
        path: path.to_owned(),
        source,
    })
}

/// The temporary file [`write`] goes through: `.NAME.tmp` in the same directory.
fn temporary_beside(path: &Path) -> std::path::PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{}.tmp", name.unwrap_or_default()))
}

/// Checks that [`write`] can later replace `path`: creates and removes its temporary file (the
/// directory takes new files) and refuses a directory in its place. This is what a write
/// needs, whatever the permission bits say, so it holds for root too.
///
/// # Errors
/// The I/O error that a later write would meet.
pub fn check_writable(path: &Path) -> std::io::Result<()> {
    if path.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::IsADirectory,
            "is a directory",
        ));
    }
    let tmp = temporary_beside(path);
    std::fs::File::create(&tmp)?;
    std::fs::remove_file(&tmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_place_that_cannot_take_files_is_refused_even_for_root() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").unwrap();
        // Under a regular file: ENOTDIR whoever runs it.
        assert!(check_writable(&file.join("params.parm")).is_err());
        assert!(
            check_writable(dir.path()).is_err(),
            "a directory in its place"
        );
        let ok = dir.path().join("params.parm");
        check_writable(&ok).unwrap();
        assert!(!ok.exists() && std::fs::read_dir(dir.path()).unwrap().count() == 1);
    }
}
