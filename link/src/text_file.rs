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

/// Writes `bytes` to `path` without harm to what is there:
///
/// - `-` is standard output;
/// - a regular file (or a new one) is written atomically: a temporary file in the same
///   directory, flushed to disk, then renamed over `path`, so a crash leaves either the old file
///   or the new one;
/// - a device, a FIFO or a socket, and the target of a symbolic link, are written in place
///   (opened, truncated where that means anything, written): never replaced by a file, and a
///   link stays a link.
///
/// # Errors
/// The I/O error of the step that failed.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if path.as_os_str() == "-" {
        let mut out = std::io::stdout().lock();
        out.write_all(bytes)?;
        return out.flush();
    }
    if in_place(path)? {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(path)?;
        f.write_all(bytes)?;
        return f.flush();
    }
    let tmp = temporary_beside(path);
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, path)
}

/// Whether `path` is written where it is instead of replaced: a symbolic link (its target is
/// written), or anything that is neither a regular file nor a directory (a device, a FIFO).
/// A directory is refused; a missing path is a new regular file.
fn in_place(path: &Path) -> std::io::Result<bool> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(e),
    };
    if meta.file_type().is_symlink() {
        return match std::fs::metadata(path) {
            Ok(target) if target.is_dir() => Err(is_a_directory()),
            Ok(_) => Ok(true),
            // A dangling link: its target is created through it.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(true),
            Err(e) => Err(e),
        };
    }
    if meta.is_dir() {
        return Err(is_a_directory());
    }
    Ok(!meta.is_file())
}

fn is_a_directory() -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory")
}

/// A file written as [`write`] writes one, but streamed: `-` is standard output; a device, a
/// FIFO or a symbolic link's target is written in place; a regular file goes into a
/// temporary file beside it, renamed over it by [`Output::finish`] (dropped unfinished, the
/// temporary file is removed and the old file stays).
#[derive(Debug)]
pub struct Output {
    sink: Sink,
}

#[derive(Debug)]
enum Sink {
    /// Renamed over `to` by `finish`.
    Atomic {
        file: std::fs::File,
        tmp: PathBuf,
        to: PathBuf,
    },
    /// Written where it is.
    InPlace(std::fs::File),
    /// Standard output.
    Stdout(std::io::Stdout),
    /// Spooled in an unnamed temporary file (a writer that seeks), copied out by `finish`.
    Spool { file: std::fs::File, to: Box<Sink> },
    /// Finished.
    Done,
}

impl Output {
    /// Opens `path` for a writer that only appends.
    ///
    /// # Errors
    /// The I/O error of opening it (a directory is refused).
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let sink = if path.as_os_str() == "-" {
            Sink::Stdout(std::io::stdout())
        } else if in_place(path)? {
            Sink::InPlace(
                std::fs::OpenOptions::new()
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(path)?,
            )
        } else {
            let tmp = temporary_beside(path);
            Sink::Atomic {
                file: std::fs::File::create(&tmp)?,
                tmp,
                to: path.to_owned(),
            }
        };
        Ok(Self { sink })
    }

    /// Opens `path` for a writer that seeks back (MCAP's): what cannot seek (standard
    /// output, a FIFO, a device) is spooled in a temporary file first.
    ///
    /// # Errors
    /// As [`Output::create`].
    pub fn create_seekable(path: &Path) -> std::io::Result<Self> {
        let out = Self::create(path)?;
        if matches!(out.sink, Sink::Atomic { .. }) {
            return Ok(out);
        }
        let tmp = std::env::temp_dir().join(format!(
            ".vtol-spool-{}-{}",
            std::process::id(),
            SPOOLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        ));
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        // Unnamed from the start: nothing is left behind, whatever happens.
        std::fs::remove_file(&tmp)?;
        let mut out = out;
        let to = Box::new(std::mem::replace(&mut out.sink, Sink::Done));
        out.sink = Sink::Spool { file, to };
        Ok(out)
    }

    /// Completes the file: flushes it, and renames a regular file's temporary file over it or
    /// copies a spool out.
    ///
    /// # Errors
    /// The I/O error of the step that failed.
    pub fn finish(mut self) -> std::io::Result<()> {
        match std::mem::replace(&mut self.sink, Sink::Done) {
            Sink::Atomic { mut file, tmp, to } => {
                let done = file
                    .flush()
                    .and_then(|()| file.sync_all())
                    .and_then(|()| std::fs::rename(&tmp, &to));
                if done.is_err() {
                    let _ = std::fs::remove_file(&tmp);
                }
                done
            }
            Sink::InPlace(mut f) => f.flush(),
            Sink::Stdout(mut s) => s.flush(),
            Sink::Spool { mut file, to, .. } => {
                use std::io::Seek;
                file.rewind()?;
                let mut out = Output { sink: *to };
                std::io::copy(&mut file, &mut out)?;
                out.finish()
            }
            Sink::Done => Ok(()),
        }
    }

    fn writer(&mut self) -> std::io::Result<&mut dyn Write> {
        Ok(match &mut self.sink {
            Sink::Atomic { file, .. } | Sink::InPlace(file) | Sink::Spool { file, .. } => file,
            Sink::Stdout(s) => s,
            Sink::Done => {
                return Err(std::io::Error::other("written after finish"));
            }
        })
    }
}

static SPOOLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer()?.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer()?.flush()
    }
}

impl std::io::Seek for Output {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        match &mut self.sink {
            Sink::Atomic { file, .. } | Sink::Spool { file, .. } => file.seek(pos),
            _ => Err(std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "this output cannot seek",
            )),
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        if let Sink::Atomic { tmp, .. } = &self.sink {
            let _ = std::fs::remove_file(tmp);
        }
    }
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
    if path.as_os_str() == "-" {
        return Ok(());
    }
    if in_place(path)? {
        use std::os::unix::fs::FileTypeExt;
        // Written where it is. Opening a FIFO would wait for its reader: its being there is
        // what the write needs.
        if std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo()) {
            return Ok(());
        }
        return match std::fs::OpenOptions::new().write(true).open(path) {
            Ok(_) => Ok(()),
            // A dangling link: its target is created by the write.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(e),
        };
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

    /// A symbolic link stays a link: its target is written.
    #[test]
    fn a_link_is_written_through_not_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("real.parm");
        std::fs::write(&target, b"old and longer\n").unwrap();
        let link = dir.path().join("link.parm");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_text(&link, "new\n").unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(read_text(&target).unwrap(), "new\n");
        // A link to a directory is refused.
        let to_dir = dir.path().join("to_dir");
        std::os::unix::fs::symlink(dir.path(), &to_dir).unwrap();
        assert!(write_text(&to_dir, "x").is_err());
        assert!(
            std::fs::symlink_metadata(&to_dir)
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }

    /// A FIFO is written into, with its reader getting the text, and stays a FIFO.
    #[test]
    fn a_fifo_is_written_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        make_fifo(&fifo);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
        };
        write_text(&fifo, "through the pipe\n").unwrap();
        assert_eq!(reader.join().unwrap(), "through the pipe\n");
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::symlink_metadata(&fifo)
                .unwrap()
                .file_type()
                .is_fifo()
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    /// A character device (made here with /dev/null's numbers) is written in place, never
    /// replaced by a regular file. Needs root to make the node.
    #[test]
    fn a_device_is_written_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let dev = dir.path().join("null");
        let made = std::process::Command::new("mknod")
            .arg(&dev)
            .args(["c", "1", "3"])
            .status();
        if !made.is_ok_and(|s| s.success()) {
            eprintln!("skipped: cannot make a device node here (not root)");
            return;
        }
        write_text(&dev, "into the device\n").unwrap();
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::symlink_metadata(&dev)
                .unwrap()
                .file_type()
                .is_char_device()
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        check_writable(&dev).unwrap();
    }

    fn make_fifo(path: &Path) {
        let made = std::process::Command::new("mkfifo").arg(path).status();
        assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", path.display());
    }

    /// A streamed output replaces a regular file only when finished; one dropped unfinished
    /// leaves the old file and nothing beside it. A seeking writer into a FIFO is spooled.
    #[test]
    fn a_streamed_output_is_atomic_and_spools_for_a_fifo() {
        use std::io::{Seek, SeekFrom};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        std::fs::write(&path, b"old").unwrap();
        let mut o = Output::create(&path).unwrap();
        o.write_all(b"half").unwrap();
        drop(o);
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let mut o = Output::create_seekable(&path).unwrap();
        o.write_all(b"xxxx tail").unwrap();
        o.seek(SeekFrom::Start(0)).unwrap();
        o.write_all(b"head").unwrap();
        o.finish().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"head tail");

        let fifo = dir.path().join("pipe");
        make_fifo(&fifo);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        let mut o = Output::create_seekable(&fifo).unwrap();
        o.write_all(b"1234 rest").unwrap();
        o.seek(SeekFrom::Start(0)).unwrap();
        o.write_all(b"abcd").unwrap();
        o.finish().unwrap();
        assert_eq!(reader.join().unwrap(), b"abcd rest");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
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
