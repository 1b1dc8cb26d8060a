//! The twin's MAVLink 2 signing: `vtol_link::signing` (the daemon's own implementation) applied
//! to the frames the serve loop receives and sends, SETUP_SIGNING, and the persisted state.
//!
//! Contract:
//! - **Key at start**: `--signing-passphrase` / `--signing-key-file` if given (the operator's
//!   explicit word wins); otherwise the key saved beside `--param-file` ([`signing_file_beside`])
//!   by an earlier keyed run or an accepted SETUP_SIGNING; otherwise none. An all-zero key is no
//!   key. The saved timestamp is continued in every case, so timestamps never go back.
//! - **Keyed**: every outgoing frame is signed; an incoming frame passes only if
//!   [`Signing::verify`] accepts it (rightly signed and fresh, or unsigned RADIO_STATUS). A
//!   refused frame changes nothing and gets no answer. **Unkeyed**: everything passes unsigned.
//! - **SETUP_SIGNING** (id 256) is handled here and never reaches the vehicle, the tlog or a log
//!   line. It is accepted when addressed to us (target system 0 or ours, component 0 or 1) and
//!   it came either **signed with the current key** (verified, fresh) or on a **local link**. A
//!   local link is a serial device the twin opened (`--listen serial:…`): the USB-cable
//!   analogue, where ArduPilot also takes SETUP_SIGNING, since whoever holds the cable holds
//!   the vehicle. TCP, UDP and streams attached in process are never local. Anything else is
//!   refused and changes nothing. Accepted, it sets the key (an all-zero key switches signing
//!   off, as ArduPilot does) and the timestamp to the larger of the message's
//!   `initial_timestamp` and ours, forgets the streams of the old key, and saves both at once.
//! - **Persistence**: key and timestamp are saved beside `--param-file` at start (when keyed; an
//!   unwritable place is an error at start), every [`SAVE_EVERY`], at an accepted SETUP_SIGNING
//!   and at exit. A twin switched off by SETUP_SIGNING saves the all-zero key, so it restarts
//!   unkeyed.
//!
//! No key byte is ever printed or logged: `SigningKey` hides them, and the frames and errors
//! logged here name only link ids and reasons.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use mavlink::dialects::ardupilotmega as apm;
use tokio::time::Instant;
use vtol_link::signing::{
    KEY_LEN, Refusal, SignError, Signing, SigningFileError, SigningKey, SigningState,
};
use vtol_link::{Accepted, Frame};

/// How often a keyed twin saves its signing timestamp (the spec asks for at least once a
/// minute), besides at start, at SETUP_SIGNING and at shutdown.
pub const SAVE_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

/// Where a twin keeps its signing key and last timestamp: beside the parameter file, with the
/// extension `signing` (`params.parm` → `params.signing`).
#[must_use]
pub fn signing_file_beside(param_file: &Path) -> PathBuf {
    let p = param_file.with_extension("signing");
    if p == param_file {
        let mut s = param_file.as_os_str().to_owned();
        s.push(".state.signing");
        PathBuf::from(s)
    } else {
        p
    }
}

/// What to do with a received frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Admit {
    /// Hand it to the vehicle.
    Pass,
    /// Drop it: refused by the signing rules. Nothing changed.
    Refused(Refusal),
    /// A SETUP_SIGNING, handled here (whatever the outcome): drop it, log nothing of it.
    SetupSigning(SetupOutcome),
}

/// What became of a SETUP_SIGNING.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SetupOutcome {
    /// A new key is in use.
    Keyed,
    /// An all-zero key: signing is off.
    Disabled,
    /// Neither signed with the current key nor on a local link: nothing changed.
    Refused,
    /// Addressed to another system or component: nothing changed.
    NotForUs,
}

/// The twin's signing state: the shared [`Signing`] when keyed, the timestamp kept while
/// unkeyed, where it is saved, what was refused.
#[derive(Debug)]
pub struct TwinSigning {
    active: Option<Signing>,
    /// The last timestamp while unkeyed (a later key continues above it).
    idle_timestamp: u64,
    file: Option<PathBuf>,
    saved_at: Instant,
    refused: u64,
}

impl TwinSigning {
    /// The signing a twin starts with (see the module docs for where the key comes from).
    /// A keyed twin saves its state at once, so an unwritable place is an error at start.
    ///
    /// # Errors
    /// A broken state file, or one that cannot be written.
    pub fn start(key: Option<SigningKey>, file: Option<PathBuf>) -> Result<Self, SigningFileError> {
        let saved = match &file {
            Some(f) => SigningState::load_if_exists(f)?,
            None => None,
        };
        let timestamp = saved.as_ref().map_or(0, |s| s.timestamp);
        let key = key
            .or_else(|| saved.map(|s| s.key))
            .filter(|k| !k.is_zero());
        let keyed = key.is_some();
        let mut s = Self {
            active: key.map(|k| Signing::new(k, 0, timestamp)),
            idle_timestamp: timestamp,
            file,
            saved_at: Instant::now(),
            refused: 0,
        };
        if keyed {
            s.save()?;
        }
        Ok(s)
    }

    /// True while a key is in use.
    #[must_use]
    pub fn is_keyed(&self) -> bool {
        self.active.is_some()
    }

    /// Frames refused so far (SETUP_SIGNING refusals included).
    #[must_use]
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// Decides about a frame received on a link (`local`: a serial device, see the module
    /// docs) of a vehicle with system id `sysid`.
    pub fn admit(
        &mut self,
        frame: &Frame,
        local: bool,
        sysid: vtol_link::SystemId,
        now: SystemTime,
    ) -> Admit {
        let verdict = self.active.as_mut().map(|s| s.verify(frame, now));
        if frame.message_id() == vtol_link::protocol::id::SETUP_SIGNING && frame.is_verified() {
            let signed = matches!(verdict, Some(Ok(Accepted::Signed { .. })));
            let outcome = self.setup_signing(frame, signed || local, sysid, now);
            if outcome == SetupOutcome::Refused {
                self.refused += 1;
            }
            return Admit::SetupSigning(outcome);
        }
        match verdict {
            None | Some(Ok(_)) => Admit::Pass,
            Some(Err(refusal)) => {
                self.refused += 1;
                Admit::Refused(refusal)
            }
        }
    }

    fn setup_signing(
        &mut self,
        frame: &Frame,
        allowed: bool,
        sysid: vtol_link::SystemId,
        now: SystemTime,
    ) -> SetupOutcome {
        let Ok(apm::MavMessage::SETUP_SIGNING(setup)) = frame.decode() else {
            return SetupOutcome::Refused;
        };
        let for_us = (setup.target_system == 0 || setup.target_system == sysid.0)
            && (setup.target_component == 0 || setup.target_component == crate::endpoint::COMPID.0);
        if !for_us {
            return SetupOutcome::NotForUs;
        }
        if !allowed {
            return SetupOutcome::Refused;
        }
        let key: [u8; KEY_LEN] = setup.secret_key;
        let timestamp = self.timestamp(now).max(setup.initial_timestamp);
        let key = SigningKey::from_bytes(key);
        let outcome = if key.is_zero() {
            self.active = None;
            SetupOutcome::Disabled
        } else {
            self.active = Some(Signing::new(key, 0, timestamp));
            SetupOutcome::Keyed
        };
        self.idle_timestamp = timestamp;
        if let Err(e) = self.save() {
            tracing::warn!("{e}");
        }
        outcome
    }

    /// Our current timestamp, keyed or not.
    fn timestamp(&self, now: SystemTime) -> u64 {
        match &self.active {
            Some(s) => s.clock().current(now),
            None => self.idle_timestamp,
        }
    }

    /// The frame to send: signed when keyed, as it is otherwise.
    ///
    /// # Errors
    /// See [`SignError`] (a MAVLink 1 frame, an exhausted timestamp).
    pub fn outgoing(&mut self, frame: Frame, now: SystemTime) -> Result<Frame, SignError> {
        match &mut self.active {
            None => Ok(frame),
            Some(s) => s.sign(&frame, now),
        }
    }

    /// Saves key and timestamp beside the parameter file, if there is one (the all-zero key
    /// when unkeyed).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn save(&mut self) -> Result<(), SigningFileError> {
        self.saved_at = Instant::now();
        let Some(f) = &self.file else {
            return Ok(());
        };
        let state = match &self.active {
            Some(s) => s.state(SystemTime::now()),
            None => SigningState {
                key: SigningKey::from_bytes([0; KEY_LEN]),
                timestamp: self.idle_timestamp,
            },
        };
        state.save(f)
    }

    /// Saves a keyed twin's timestamp when [`SAVE_EVERY`] has passed.
    pub fn save_if_due(&mut self) {
        if self.is_keyed()
            && self.saved_at.elapsed() >= SAVE_EVERY
            && let Err(e) = self.save()
        {
            tracing::warn!("{e}");
        }
    }

    /// At shutdown: saves a keyed twin's state.
    pub fn finish(&mut self) {
        if self.is_keyed() {
            tracing::info!(refused = self.refused, "signing: frames refused");
            if let Err(e) = self.save() {
                tracing::warn!("{e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use vtol_link::signing::SignatureFields;

    use super::*;

    const SYSID: u8 = 1;

    /// The wall clock: what the twin saves with, so the timestamps compared here agree.
    fn now() -> SystemTime {
        SystemTime::now()
    }

    fn key(text: &str) -> SigningKey {
        SigningKey::from_passphrase(text)
    }

    fn setup(new: &SigningKey, initial_timestamp: u64, target: (u8, u8)) -> Frame {
        let msg = apm::MavMessage::SETUP_SIGNING(apm::SETUP_SIGNING_DATA {
            initial_timestamp,
            target_system: target.0,
            target_component: target.1,
            secret_key: *new.as_bytes(),
        });
        Frame::encode_v2(
            vtol_link::SystemId(255),
            vtol_link::ComponentId(190),
            0,
            &msg,
        )
    }

    fn param_read() -> Frame {
        let msg = apm::MavMessage::PARAM_REQUEST_LIST(apm::PARAM_REQUEST_LIST_DATA {
            target_system: SYSID,
            target_component: 1,
        });
        Frame::encode_v2(
            vtol_link::SystemId(255),
            vtol_link::ComponentId(190),
            0,
            &msg,
        )
    }

    /// A GCS signing with `k` on link id 1.
    fn gcs(k: &SigningKey) -> Signing {
        Signing::new(k.clone(), 1, 0)
    }

    fn admit(s: &mut TwinSigning, f: &Frame, local: bool) -> Admit {
        s.admit(f, local, vtol_link::SystemId(SYSID), now())
    }

    #[test]
    fn unkeyed_twin_takes_setup_signing_only_on_a_local_link() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.signing");
        let mut s = TwinSigning::start(None, Some(file.clone())).unwrap();
        assert!(!s.is_keyed());
        assert!(!file.exists(), "an unkeyed twin writes nothing at start");
        assert_eq!(admit(&mut s, &param_read(), false), Admit::Pass);
        // Unsigned, over the network: refused, nothing changes.
        let new = key("new");
        let f = setup(&new, 0, (SYSID, 1));
        assert_eq!(
            admit(&mut s, &f, false),
            Admit::SetupSigning(SetupOutcome::Refused)
        );
        assert!(!s.is_keyed() && !file.exists());
        assert_eq!(admit(&mut s, &param_read(), false), Admit::Pass);
        // On the cable: keyed and saved.
        assert_eq!(
            admit(&mut s, &f, true),
            Admit::SetupSigning(SetupOutcome::Keyed)
        );
        assert!(s.is_keyed());
        assert_eq!(SigningState::load(&file).unwrap().key, new);
        assert!(matches!(
            admit(&mut s, &param_read(), false),
            Admit::Refused(Refusal::Unsigned { message_id: 21 })
        ));
        let signed = gcs(&new).sign(&param_read(), now()).unwrap();
        assert_eq!(admit(&mut s, &signed, false), Admit::Pass);
        // What goes out is signed with the new key.
        let out = s.outgoing(param_read(), now()).unwrap();
        assert!(vtol_link::signing::signature_matches(&new, &out));
        assert_eq!(s.refused(), 2);
    }

    #[test]
    fn keyed_twin_is_rekeyed_only_by_a_frame_signed_with_its_key() {
        let old = key("old");
        let new = key("new");
        let mut s = TwinSigning::start(Some(old.clone()), None).unwrap();
        let mut gcs_old = gcs(&old);
        // Unsigned, and signed with another key: refused, the old key still works.
        for f in [
            setup(&new, 0, (SYSID, 1)),
            gcs(&new).sign(&setup(&new, 0, (SYSID, 1)), now()).unwrap(),
        ] {
            assert_eq!(
                admit(&mut s, &f, false),
                Admit::SetupSigning(SetupOutcome::Refused)
            );
        }
        let f = gcs_old.sign(&param_read(), now()).unwrap();
        assert_eq!(admit(&mut s, &f, false), Admit::Pass);
        // Addressed elsewhere: ignored even when rightly signed.
        let elsewhere = gcs_old.sign(&setup(&new, 0, (7, 1)), now()).unwrap();
        assert_eq!(
            admit(&mut s, &elsewhere, false),
            Admit::SetupSigning(SetupOutcome::NotForUs)
        );
        // Signed with the current key, broadcast target: re-keyed.
        let rekey = gcs_old.sign(&setup(&new, 0, (0, 0)), now()).unwrap();
        assert_eq!(
            admit(&mut s, &rekey, false),
            Admit::SetupSigning(SetupOutcome::Keyed)
        );
        // Replayed: refused (the old key is gone, and so is its stream).
        assert_eq!(
            admit(&mut s, &rekey, false),
            Admit::SetupSigning(SetupOutcome::Refused)
        );
        let f = gcs_old.sign(&param_read(), now()).unwrap();
        assert_eq!(
            admit(&mut s, &f, false),
            Admit::Refused(Refusal::BadSignature)
        );
        let f = gcs(&new).sign(&param_read(), now()).unwrap();
        assert_eq!(admit(&mut s, &f, false), Admit::Pass);
    }

    #[test]
    fn zero_key_switches_signing_off_and_it_stays_off_after_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.signing");
        let k = key("k");
        let mut s = TwinSigning::start(Some(k.clone()), Some(file.clone())).unwrap();
        let before = SigningState::load(&file).unwrap();
        assert_eq!(before.key, k);
        let zero = SigningKey::from_bytes([0; KEY_LEN]);
        let off = gcs(&k).sign(&setup(&zero, 0, (SYSID, 1)), now()).unwrap();
        assert_eq!(
            admit(&mut s, &off, false),
            Admit::SetupSigning(SetupOutcome::Disabled)
        );
        assert!(!s.is_keyed());
        assert_eq!(admit(&mut s, &param_read(), false), Admit::Pass);
        let out = s.outgoing(param_read(), now()).unwrap();
        assert!(!out.is_signed());
        let saved = SigningState::load(&file).unwrap();
        assert!(saved.key.is_zero());
        assert!(saved.timestamp >= before.timestamp, "the timestamp kept");
        let restarted = TwinSigning::start(None, Some(file.clone())).unwrap();
        assert!(!restarted.is_keyed());
        // A key on the command line wins over the saved state.
        assert!(TwinSigning::start(Some(k), Some(file)).unwrap().is_keyed());
    }

    #[test]
    fn saved_key_is_used_at_restart_and_timestamps_never_go_back() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.signing");
        let mut s = TwinSigning::start(None, Some(file.clone())).unwrap();
        let new = key("new");
        // An initial timestamp an hour ahead of the clock is honoured.
        let ahead = vtol_link::signing::timestamp_at(now() + Duration::from_secs(3600));
        let f = setup(&new, ahead, (SYSID, 0));
        assert_eq!(
            admit(&mut s, &f, true),
            Admit::SetupSigning(SetupOutcome::Keyed)
        );
        let out = s.outgoing(param_read(), now()).unwrap();
        assert!(SignatureFields::of(&out).unwrap().timestamp > ahead);
        s.finish();
        let mut again = TwinSigning::start(None, Some(file)).unwrap();
        assert!(again.is_keyed());
        let out2 = again.outgoing(param_read(), now()).unwrap();
        assert!(vtol_link::signing::signature_matches(&new, &out2));
        assert!(
            SignatureFields::of(&out2).unwrap().timestamp
                > SignatureFields::of(&out).unwrap().timestamp
        );
    }
}
