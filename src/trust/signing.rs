//! The daemon's MAVLink 2 signing, as the router applies it (the rules themselves are
//! `vtol_link::signing`'s, shared with the twin).
//!
//! Contract:
//! - One [`Signing`] (one key, one timestamp source) for everything the daemon signs: its own
//!   traffic and the frames of `sign` clients. Each link signs as its own signing link id
//!   ([`signing_link_id`], 1–255; 0 is left to clients that sign for themselves, pymavlink's and
//!   MAVProxy's default), so each is its own stream at the vehicle, and one timestamp source
//!   means no two frames share a timestamp.
//! - Frames from the vehicle are verified: unsigned (RADIO_STATUS excepted), wrongly signed and
//!   replayed or stale frames are dropped before anything else sees them, and counted by kind
//!   in [`SigningCounters`]. A replayed log as the vehicle is not verified.
//! - The time comes from a [`WallClock`] (the system clock in the daemon), so a test can move
//!   it by minutes without waiting.
//! - The timestamp is persisted in a state file (key and last timestamp, owner-only, written
//!   atomically by `SigningState::save`) at start, every [`SAVE_EVERY`] and at shutdown, so a
//!   restart never signs below a timestamp already used, even when the vehicle's clock ran ahead.
//! - No key bytes in any log line or error: `SigningKey` prints none, refusals carry ids and
//!   timestamps only.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

use vtol_link::signing::{Accepted, Refusal, SignError, Signing, SigningState};
use vtol_link::{Frame, LinkId, SigningFileError, SigningKey};

/// How often the running daemon saves its signing timestamp (the spec asks for at least once a
/// minute), besides at start and at shutdown.
pub const SAVE_EVERY: Duration = Duration::from_secs(30);

/// Where the time comes from: the system clock, or a test's.
pub type WallClock = Arc<dyn Fn() -> SystemTime + Send + Sync>;

/// The system clock.
#[must_use]
pub fn system_clock() -> WallClock {
    Arc::new(SystemTime::now)
}

/// The signing link id a link's frames are signed with: 1–255 from the link's id.
#[must_use]
pub fn signing_link_id(link: LinkId) -> u8 {
    // 1 + (id mod 255) is at most 255.
    u8::try_from(1 + link.0 % 255).unwrap_or(u8::MAX)
}

/// Router-wide signing counters (shown on the status line and in the terminal UI).
#[derive(Debug, Default)]
pub struct SigningCounters {
    /// Vehicle frames accepted with a right signature.
    pub verified: AtomicU64,
    /// Vehicle frames dropped: unsigned and not on the allow-list (MAVLink 1 included).
    pub refused_unsigned: AtomicU64,
    /// Vehicle frames dropped: wrong signature (another key, or changed on the way).
    pub refused_bad_signature: AtomicU64,
    /// Vehicle frames dropped: replayed, stale on a new stream, or too many streams.
    pub refused_replayed: AtomicU64,
    /// Frames the daemon signed (its own traffic and `sign` clients').
    pub signed: AtomicU64,
}

/// A copy of [`SigningCounters`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SigningSnapshot {
    /// See [`SigningCounters::verified`].
    pub verified: u64,
    /// See [`SigningCounters::refused_unsigned`].
    pub refused_unsigned: u64,
    /// See [`SigningCounters::refused_bad_signature`].
    pub refused_bad_signature: u64,
    /// See [`SigningCounters::refused_replayed`].
    pub refused_replayed: u64,
    /// See [`SigningCounters::signed`].
    pub signed: u64,
}

impl SigningSnapshot {
    /// Every vehicle frame refused.
    #[must_use]
    pub fn refused(&self) -> u64 {
        self.refused_unsigned + self.refused_bad_signature + self.refused_replayed
    }
}

impl SigningCounters {
    /// Reads every counter.
    #[must_use]
    pub fn snapshot(&self) -> SigningSnapshot {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        SigningSnapshot {
            verified: g(&self.verified),
            refused_unsigned: g(&self.refused_unsigned),
            refused_bad_signature: g(&self.refused_bad_signature),
            refused_replayed: g(&self.refused_replayed),
            signed: g(&self.signed),
        }
    }
}

/// The daemon's signing state, owned by the router.
pub struct DaemonSigning {
    signing: Signing,
    clock: WallClock,
    file: Option<PathBuf>,
    verify_vehicle: bool,
    counters: Arc<SigningCounters>,
}

impl std::fmt::Debug for DaemonSigning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DaemonSigning")
            .field("file", &self.file)
            .field("verify_vehicle", &self.verify_vehicle)
            .finish_non_exhaustive()
    }
}

impl DaemonSigning {
    /// Signing with `key`, continuing above the timestamp saved in `file` (when it exists;
    /// whatever key it held), and saved there at once, so an unwritable place or a broken file
    /// is an error at start. `verify_vehicle` false leaves vehicle frames unchecked (a replayed
    /// log).
    ///
    /// # Errors
    /// A state file that cannot be read, parsed or written.
    pub fn start(
        key: SigningKey,
        file: Option<PathBuf>,
        verify_vehicle: bool,
        clock: WallClock,
    ) -> Result<Self, SigningFileError> {
        let saved = match &file {
            Some(f) => SigningState::load_if_exists(f)?.map_or(0, |s| s.timestamp),
            None => 0,
        };
        let s = DaemonSigning {
            signing: Signing::new(key, 0, saved),
            clock,
            file,
            verify_vehicle,
            counters: Arc::default(),
        };
        s.save()?;
        Ok(s)
    }

    /// The counters, shared.
    #[must_use]
    pub fn counters(&self) -> &Arc<SigningCounters> {
        &self.counters
    }

    /// The state file, if any.
    #[must_use]
    pub fn file(&self) -> Option<&Path> {
        self.file.as_deref()
    }

    /// What to persist now.
    #[must_use]
    pub fn state(&self) -> SigningState {
        self.signing.state((self.clock)())
    }

    /// Writes the state file (if any).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn save(&self) -> Result<(), SigningFileError> {
        match &self.file {
            Some(f) => self.state().save(f),
            None => Ok(()),
        }
    }

    /// Checks a frame from the vehicle; counts a refusal by kind.
    ///
    /// # Errors
    /// The refusal (the frame must be dropped).
    pub fn verify_vehicle(&mut self, frame: &Frame) -> Result<(), Refusal> {
        if !self.verify_vehicle {
            return Ok(());
        }
        let c = &self.counters;
        match self.signing.verify(frame, (self.clock)()) {
            Ok(Accepted::Signed { .. }) => {
                c.verified.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Ok(Accepted::UnsignedAllowed) => Ok(()),
            Err(r) => {
                let counter = match r {
                    Refusal::Unsigned { .. } => &c.refused_unsigned,
                    Refusal::BadSignature => &c.refused_bad_signature,
                    Refusal::Replayed { .. } | Refusal::TooOld { .. } | Refusal::TooManyStreams => {
                        &c.refused_replayed
                    }
                };
                counter.fetch_add(1, Ordering::Relaxed);
                Err(r)
            }
        }
    }

    /// Signs one of our own frames as signing link 0 (a client on its own link).
    ///
    /// # Errors
    /// MAVLink 1 (cannot be signed), or the timestamp exhausted.
    pub fn sign_own(&mut self, frame: &Frame) -> Result<Frame, SignError> {
        let signed = self.signing.sign(frame, (self.clock)())?;
        self.counters.signed.fetch_add(1, Ordering::Relaxed);
        Ok(signed)
    }

    /// Signs a frame that came in on `link` with the daemon's key, as that link's stream.
    ///
    /// # Errors
    /// MAVLink 1 (cannot be signed), or the timestamp exhausted.
    pub fn sign(&mut self, frame: &Frame, link: LinkId) -> Result<Frame, SignError> {
        let signed = self
            .signing
            .sign_as(frame, signing_link_id(link), (self.clock)())?;
        self.counters.signed.fetch_add(1, Ordering::Relaxed);
        Ok(signed)
    }
}

/// The default state file: `$XDG_STATE_HOME/vtol-gcs/signing.toml`, else
/// `$HOME/.local/state/vtol-gcs/signing.toml`; `None` when neither is set.
#[must_use]
pub fn default_state_file() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_STATE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".local").join("state"))
        })?;
    Some(base.join("vtol-gcs").join("signing.toml"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signing_link_ids_stay_clear_of_zero() {
        for id in [0, 1, 254, 255, 256, 510, u32::MAX] {
            assert_ne!(signing_link_id(LinkId(id)), 0, "{id}");
        }
        assert_eq!(signing_link_id(LinkId(1)), 2);
        assert_eq!(signing_link_id(LinkId(254)), 255);
        assert_eq!(signing_link_id(LinkId(255)), 1);
    }

    #[test]
    fn state_is_saved_at_start_and_continued() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("signing.toml");
        let key = SigningKey::from_passphrase("daemon");
        let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(1_800_000_000);
        let fixed: WallClock = Arc::new(move || t0);
        let mut s =
            DaemonSigning::start(key.clone(), Some(file.clone()), true, fixed.clone()).unwrap();
        let hb = Frame::encode_v2(
            vtol_link::SystemId(255),
            vtol_link::ComponentId(190),
            0,
            &vtol_link::gcs_heartbeat(),
        );
        let a = s.sign(&hb, LinkId(7)).unwrap();
        let b = s.sign(&hb, LinkId(7)).unwrap();
        s.save().unwrap();
        let ts = |f: &Frame| {
            vtol_link::signing::SignatureFields::of(f)
                .unwrap()
                .timestamp
        };
        assert_eq!(ts(&b), ts(&a) + 1);
        // A restart at the same instant (or with the clock set back) signs above both.
        let mut again = DaemonSigning::start(key, Some(file), true, fixed).unwrap();
        let c = again.sign(&hb, LinkId(7)).unwrap();
        assert!(ts(&c) > ts(&b));
        // An unwritable place is an error at start.
        assert!(
            DaemonSigning::start(
                SigningKey::from_passphrase("x"),
                Some(dir.path().join("no/such/dir/f")),
                true,
                system_clock()
            )
            .is_err()
        );
    }
}
