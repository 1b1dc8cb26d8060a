//! The signing state file: key and last timestamp, kept across restarts.

use std::path::{Path, PathBuf};

use super::{KeyError, MAX_TIMESTAMP, STATE_FILE_FORMAT, SigningKey};

/// What a signing party persists: its key and its last timestamp.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SigningState {
    /// The key.
    pub key: SigningKey,
    /// The last timestamp used or accepted.
    pub timestamp: u64,
}

/// Why a key or state file cannot be read or written. Never quotes key bytes.
#[derive(Debug, thiserror::Error)]
pub enum SigningFileError {
    /// The file cannot be read.
    #[error("cannot read signing file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file cannot be written.
    #[error("cannot write signing file {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file holds a bad key.
    #[error("bad signing key in {}: {source}", path.display())]
    Key {
        /// The file.
        path: PathBuf,
        /// What is wrong with the key.
        source: KeyError,
    },
    /// The state file is not `key = "<64 hex>"` and `timestamp = N`.
    #[error("bad signing state file {}{}: {message}", path.display(), line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Format {
        /// The file.
        path: PathBuf,
        /// 1-based line, when known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
}

pub(super) fn read_text(path: &Path) -> Result<String, SigningFileError> {
    std::fs::read_to_string(path).map_err(|source| SigningFileError::Read {
        path: path.to_owned(),
        source,
    })
}

impl SigningState {
    /// The state file's text (TOML).
    #[must_use]
    pub fn to_text(&self) -> String {
        format!(
            "# MAVLink 2 signing key and last timestamp (10 us units since 2015-01-01 UTC).\n\
             # Secret: keep this file private.\n\
             key = \"{}\"\n\
             timestamp = {}\n",
            self.key.to_hex(),
            self.timestamp
        )
    }

    /// Parses a state file's text; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<SigningState, SigningFileError> {
        let format = |line: Option<usize>, message: String| SigningFileError::Format {
            path: path.to_owned(),
            line,
            message,
        };
        let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
        // Only the parser's message and position: its full report quotes the line, which may
        // hold the key.
        // Not even the message when it quotes a value (`invalid type: integer `…``): that value
        // may be the key, written without its quotes.
        let table: toml::Table = toml::from_str(text).map_err(|e| {
            let message = if e.message().contains('`') {
                format!("not valid TOML ({STATE_FILE_FORMAT})")
            } else {
                e.message().trim_end().replace('\n', "; ")
            };
            format(e.span().map(|s| line_of(s.start)), message)
        })?;
        let line_of_key = |name: &str| {
            text.lines()
                .position(|l| l.trim_start().starts_with(name))
                .map(|i| i + 1)
        };
        if let Some(unknown) = table
            .keys()
            .find(|k| k.as_str() != "key" && k.as_str() != "timestamp")
        {
            // The name is not quoted: a key glued to its name by a missing `=` would be.
            return Err(format(
                line_of_key(unknown),
                "unknown field (expected `key` and `timestamp`)".to_owned(),
            ));
        }
        let key = match table.get("key") {
            None => return Err(format(None, "missing `key`".to_owned())),
            Some(toml::Value::String(s)) => {
                SigningKey::from_hex(s).map_err(|source| SigningFileError::Key {
                    path: path.to_owned(),
                    source,
                })?
            }
            Some(_) => {
                return Err(format(
                    line_of_key("key"),
                    "`key` must be a quoted string of 64 hex characters".to_owned(),
                ));
            }
        };
        let timestamp = match table.get("timestamp") {
            None => return Err(format(None, "missing `timestamp`".to_owned())),
            Some(toml::Value::Integer(t)) => u64::try_from(*t)
                .ok()
                .filter(|&t| t <= MAX_TIMESTAMP)
                .ok_or_else(|| {
                    format(
                        line_of_key("timestamp"),
                        format!("`timestamp` {t} is outside 0..={MAX_TIMESTAMP}"),
                    )
                })?,
            Some(_) => {
                return Err(format(
                    line_of_key("timestamp"),
                    "`timestamp` must be a whole number".to_owned(),
                ));
            }
        };
        Ok(SigningState { key, timestamp })
    }

    /// Reads a state file.
    pub fn load(path: &Path) -> Result<SigningState, SigningFileError> {
        SigningState::parse(&read_text(path)?, path)
    }

    /// Reads a state file if it exists (`Ok(None)` if it does not).
    pub fn load_if_exists(path: &Path) -> Result<Option<SigningState>, SigningFileError> {
        match std::fs::read_to_string(path) {
            Ok(text) => SigningState::parse(&text, path).map(Some),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(SigningFileError::Read {
                path: path.to_owned(),
                source,
            }),
        }
    }

    /// Writes the state file (owner-only permissions on Unix) through a temporary file beside
    /// it, renamed into place, so a crash leaves the old or the new state, never half of one.
    pub fn save(&self, path: &Path) -> Result<(), SigningFileError> {
        use std::io::Write;
        let write_err = |source| SigningFileError::Write {
            path: path.to_owned(),
            source,
        };
        let mut tmp_name = path.as_os_str().to_owned();
        tmp_name.push(".tmp");
        let tmp = PathBuf::from(tmp_name);
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create(true).truncate(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.mode(0o600);
        }
        let mut file = options.open(&tmp).map_err(write_err)?;
        file.write_all(self.to_text().as_bytes())
            .and_then(|()| file.sync_all())
            .map_err(write_err)?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(write_err)
    }
}
