//! The text files both programs keep, parameter files (ArduPilot's `.parm`, the ground
//! stations' formats) and missions: read whole, written so that a crash cannot tear them, and
//! refused with the file, and the line, of the first thing wrong.

use std::io::Write;
use std::path::{Path, PathBuf};

/// A text file that cannot be read, written or used.
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

impl TextFileError {
    /// Line `line` (1-based) of `path` cannot be used, for `reason`.
    #[must_use]
    pub fn line(path: &Path, line: usize, reason: String) -> Self {
        Self::Line {
            path: path.to_owned(),
            line,
            reason,
        }
    }

    /// Reading or writing `path` failed with `source`.
    #[must_use]
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_owned(),
            source,
        }
    }
}

/// Reads `path` as UTF-8 text.
///
/// # Errors
/// [`TextFileError::Io`].
pub fn read_text(path: &Path) -> Result<String, TextFileError> {
    std::fs::read_to_string(path).map_err(|source| TextFileError::io(path, source))
}

/// [`write`] of `text`.
///
/// # Errors
/// [`TextFileError::Io`], of the step that failed.
pub fn write_text(path: &Path, text: &str) -> Result<(), TextFileError> {
    write(path, text.as_bytes()).map_err(|source| TextFileError::io(path, source))
}

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

/// The temporary file [`write`] goes through: `.NAME.tmp` in the same directory.
fn temporary_beside(path: &Path) -> PathBuf {
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

    #[test]
    fn a_write_replaces_the_whole_file_and_leaves_nothing_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mission.waypoints");
        write_text(&path, "a much longer first version\n").unwrap();
        write_text(&path, "short\n").unwrap();
        assert_eq!(read_text(&path).unwrap(), "short\n");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let missing = dir.path().join("missing");
        let e = read_text(&missing).unwrap_err();
        assert!(matches!(e, TextFileError::Io { .. }));
        assert!(e.to_string().starts_with(&missing.display().to_string()));
        let e = TextFileError::line(&path, 3, "bad".into());
        assert_eq!(e.to_string(), format!("{}:3: bad", path.display()));
    }
}
