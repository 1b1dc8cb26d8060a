//! The signing key: parsed, shown without its bytes.

use std::fmt;
use std::path::Path;

use super::{KEY_LEN, SigningFileError, read_text};
use sha2::{Digest, Sha256};

/// A 32-byte MAVLink 2 signing key. Its bytes never appear in `Debug` or `Display`.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; KEY_LEN]);

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SigningKey(<secret>)")
    }
}

impl fmt::Display for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("<secret signing key>")
    }
}

/// Why text is not a signing key. The text itself is never quoted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// Not 64 characters (after trimming white space).
    #[error("a signing key is 64 hex characters, got {chars}")]
    WrongLength {
        /// Characters found.
        chars: usize,
    },
    /// A character that is not a hex digit.
    #[error("a signing key is 64 hex characters: character {position} is not a hex digit")]
    NotHex {
        /// 1-based position of the first bad character.
        position: usize,
    },
}

impl SigningKey {
    /// The key from its 32 bytes.
    #[must_use]
    pub fn from_bytes(bytes: [u8; KEY_LEN]) -> SigningKey {
        SigningKey(bytes)
    }

    /// The key MAVProxy's `signing setup PASSPHRASE` uses: SHA-256 of the passphrase's UTF-8
    /// bytes.
    #[must_use]
    pub fn from_passphrase(passphrase: &str) -> SigningKey {
        SigningKey(Sha256::digest(passphrase.as_bytes()).into())
    }

    /// The key from 64 hex characters (either case; white space around them is ignored).
    pub fn from_hex(text: &str) -> Result<SigningKey, KeyError> {
        let text = text.trim();
        let chars = text.chars().count();
        if chars != 2 * KEY_LEN {
            return Err(KeyError::WrongLength { chars });
        }
        if let Some(pos) = text.chars().position(|c| !c.is_ascii_hexdigit()) {
            return Err(KeyError::NotHex { position: pos + 1 });
        }
        let mut bytes = [0u8; KEY_LEN];
        hex::decode_to_slice(text, &mut bytes).map_err(|_| KeyError::WrongLength { chars })?;
        Ok(SigningKey(bytes))
    }

    /// Reads a key file: 64 hex characters (a trailing newline is fine).
    pub fn from_key_file(path: &Path) -> Result<SigningKey, SigningFileError> {
        let text = read_text(path)?;
        SigningKey::from_hex(&text).map_err(|source| SigningFileError::Key {
            path: path.to_owned(),
            source,
        })
    }

    /// The key as 64 lowercase hex characters, for writing a key or state file. Never log it.
    #[must_use]
    pub fn to_hex(&self) -> String {
        hex::encode(self.0)
    }

    /// The raw key bytes (for SETUP_SIGNING). Never log them.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8; KEY_LEN] {
        &self.0
    }

    /// True for the all-zero key, which SETUP_SIGNING uses to switch signing off.
    #[must_use]
    pub fn is_zero(&self) -> bool {
        self.0.iter().all(|&b| b == 0)
    }
}
