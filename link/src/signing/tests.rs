//! Signing and verifying, against pymavlink's and the C library's bytes.

use super::*;
use crate::dialect::{self as apm, MavMessage};
use bytes::Bytes;
use proptest::prelude::*;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::frame::{Frame, HEADER_LEN_V2, SIGNATURE_LEN, crc_extra, frame_crc};

fn at(seconds_since_2015: f64) -> SystemTime {
    UNIX_EPOCH + Duration::from_secs_f64(SIGNING_EPOCH_UNIX_S as f64 + seconds_since_2015)
}

/// 2026-11-23, as a fixed "now".
const T0: f64 = 375_000_000.0;

fn command_long(sysid: u8, compid: u8, seq: u8) -> Frame {
    let msg = MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
        param1: 1.0,
        command: apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 1,
        ..Default::default()
    });
    Frame::encode_v2(
        crate::SystemId(sysid),
        crate::ComponentId(compid),
        seq,
        &msg,
    )
}

fn key() -> SigningKey {
    SigningKey::from_passphrase("correct horse")
}

#[test]
fn timestamp_epoch_and_units() {
    assert_eq!(timestamp_at(at(0.0)), 0);
    assert_eq!(timestamp_at(UNIX_EPOCH), 0);
    assert_eq!(timestamp_at(at(1.0)), TIMESTAMP_UNITS_PER_S);
    assert_eq!(timestamp_at(at(0.00001)), 1);
    assert_eq!(
        timestamp_at(UNIX_EPOCH + Duration::from_secs(u64::from(u32::MAX) * 4)),
        MAX_TIMESTAMP
    );
}

#[test]
fn key_debug_display_and_errors_hide_bytes() {
    let k = SigningKey::from_bytes([0xab; 32]);
    for text in [format!("{k:?}"), format!("{k}")] {
        assert!(!text.to_lowercase().contains("ab"), "{text}");
    }
    assert_eq!(SigningKey::from_hex(&k.to_hex()).unwrap(), k);
    assert_eq!(
        SigningKey::from_hex(&format!("  {}\n", k.to_hex().to_uppercase())).unwrap(),
        k
    );
    assert_eq!(
        SigningKey::from_hex("abcd"),
        Err(KeyError::WrongLength { chars: 4 })
    );
    let mut bad = k.to_hex();
    bad.replace_range(10..11, "g");
    let err = SigningKey::from_hex(&bad).unwrap_err();
    assert_eq!(err, KeyError::NotHex { position: 11 });
    assert!(!err.to_string().contains("abab"));
    // Multi-byte characters count as characters, not bytes, and do not panic.
    assert!(matches!(
        SigningKey::from_hex(&"é".repeat(64)),
        Err(KeyError::NotHex { position: 1 })
    ));
    assert!(SigningKey::from_bytes([0; 32]).is_zero());
    assert!(!k.is_zero());
}

#[test]
fn passphrase_key_is_sha256_of_the_text() {
    // SHA-256("abc"), FIPS 180-2 appendix B.1.
    assert_eq!(
        SigningKey::from_passphrase("abc").to_hex(),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
}

#[test]
fn signed_frame_layout() {
    let f = command_long(255, 190, 3);
    let signed = sign_frame(&key(), &f, 7, 0x0102_0304_0506).unwrap();
    assert_eq!(signed.len(), f.len() + SIGNATURE_LEN);
    assert!(signed.is_signed());
    assert_eq!(signed.payload(), f.payload());
    // The CRC covers the header with the signed flag, so it changed; the frame re-parses.
    assert_ne!(signed.crc(), f.crc());
    let reparsed = Frame::from_bytes(signed.bytes().clone()).unwrap();
    assert!(reparsed.is_verified());
    let sig = signed.signature().unwrap();
    assert_eq!(&sig[..7], &[7, 6, 5, 4, 3, 2, 1]);
    let fields = SignatureFields::of(&signed).unwrap();
    assert_eq!((fields.link_id, fields.timestamp), (7, 0x0102_0304_0506));
    assert!(signature_matches(&key(), &signed));
    assert!(!signature_matches(
        &SigningKey::from_passphrase("x"),
        &signed
    ));
    // Re-signing a signed frame replaces the trailer only.
    let again = sign_frame(&key(), &signed, 8, 99).unwrap();
    assert_eq!(again.len(), signed.len());
    assert_eq!(again.crc(), signed.crc());
    assert!(signature_matches(&key(), &again));
    assert_eq!(
        sign_frame(&key(), &f, 0, MAX_TIMESTAMP + 1),
        Err(SignError::TimestampExhausted)
    );
}

#[test]
fn v1_cannot_be_signed_and_counts_as_unsigned() {
    let hb = crate::gcs_heartbeat();
    let v1 = Frame::encode_v1(crate::SystemId(255), crate::ComponentId(190), 0, &hb).unwrap();
    let mut s = Signing::new(key(), 0, 0);
    assert_eq!(s.sign(&v1, at(T0)), Err(SignError::NotV2));
    assert_eq!(
        s.verify(&v1, at(T0)),
        Err(Refusal::Unsigned { message_id: 0 })
    );
}

#[test]
fn unknown_ids_are_signed_with_the_recovered_crc_extra() {
    let f = Frame::encode_raw_v2(
        crate::SystemId(1),
        crate::ComponentId(1),
        0,
        60_000,
        &[1, 2, 3],
        77,
    )
    .unwrap();
    assert!(!f.is_verified());
    let signed = sign_frame(&key(), &f, 0, 5).unwrap();
    let expected = frame_crc(&signed.as_bytes()[1..HEADER_LEN_V2 + 3], 77);
    assert_eq!(signed.crc(), expected);
    // A CRC no CRC_EXTRA explains (the last step is one-to-one, so most do not).
    let mut b = f.as_bytes().to_vec();
    let crcs: std::collections::HashSet<u16> = (0..=255u8)
        .map(|x| frame_crc(&b[1..HEADER_LEN_V2 + 3], x))
        .collect();
    assert_eq!(crcs.len(), 256, "CRC_EXTRA recovery must be unambiguous");
    let free = (0..=u16::MAX).find(|c| !crcs.contains(c)).unwrap();
    let n = b.len();
    b[n - 2..].copy_from_slice(&free.to_le_bytes());
    let broken = Frame::from_bytes(Bytes::from(b)).unwrap();
    assert_eq!(
        sign_frame(&key(), &broken, 0, 5),
        Err(SignError::UnknownCrcExtra(60_000))
    );
}

#[test]
fn timestamps_never_go_back_and_follow_the_wall_clock() {
    let mut c = TimestampSource::new(0);
    let a = c.next(at(T0)).unwrap();
    assert_eq!(a, timestamp_at(at(T0)));
    // Same instant, or the wall clock stepping back: still +1.
    assert_eq!(c.next(at(T0)).unwrap(), a + 1);
    assert_eq!(c.next(at(T0 - 3600.0)).unwrap(), a + 2);
    // Ten minutes later: the wall clock again.
    assert_eq!(
        c.next(at(T0 + 600.0)).unwrap(),
        timestamp_at(at(T0 + 600.0))
    );
    // A peer's higher timestamp raises ours.
    let high = timestamp_at(at(T0 + 1000.0));
    c.observe(high);
    assert_eq!(c.next(at(T0 + 601.0)).unwrap(), high + 1);
    // A persisted timestamp ahead of the clock is honoured.
    let mut p = TimestampSource::new(high);
    assert_eq!(p.next(at(T0)).unwrap(), high + 1);
    let mut end = TimestampSource::new(MAX_TIMESTAMP);
    assert_eq!(end.next(at(T0)), Err(SignError::TimestampExhausted));
}

#[test]
fn replay_and_streams() {
    let mut gcs = Signing::new(key(), 1, 0);
    let mut vehicle = Signing::new(key(), 0, 0);
    let now = at(T0);
    let f1 = gcs.sign(&command_long(255, 190, 0), now).unwrap();
    let f2 = gcs.sign(&command_long(255, 190, 1), now).unwrap();
    assert!(matches!(
        vehicle.verify(&f1, now),
        Ok(Accepted::Signed { link_id: 1, .. })
    ));
    assert!(matches!(
        vehicle.verify(&f1, now),
        Err(Refusal::Replayed {
            link_id: 1,
            system_id: 255,
            component_id: 190,
            ..
        })
    ));
    assert!(vehicle.verify(&f2, now).is_ok());
    // f1 after f2: older than the stream's last.
    assert!(matches!(
        vehicle.verify(&f1, now),
        Err(Refusal::Replayed { .. })
    ));
    // The same timestamp on another (link, sys, comp) is another stream.
    let other_comp = sign_frame(
        &key(),
        &command_long(255, 191, 0),
        1,
        SignatureFields::of(&f1).unwrap().timestamp,
    )
    .unwrap();
    assert!(vehicle.verify(&other_comp, now).is_ok());
    let other_link = sign_frame(
        &key(),
        &command_long(255, 190, 0),
        2,
        SignatureFields::of(&f1).unwrap().timestamp,
    )
    .unwrap();
    assert!(vehicle.verify(&other_link, now).is_ok());
    // Accepting raised the vehicle's own timestamp above what it saw.
    let seen = SignatureFields::of(&f2).unwrap().timestamp;
    let reply = vehicle.sign(&command_long(1, 1, 0), now).unwrap();
    assert!(SignatureFields::of(&reply).unwrap().timestamp > seen);
}

#[test]
fn new_stream_older_than_a_minute_is_refused() {
    let mut vehicle = Signing::new(key(), 0, 0);
    let now = at(T0);
    let ours = timestamp_at(now);
    let old = sign_frame(
        &key(),
        &command_long(255, 190, 0),
        0,
        ours - NEW_STREAM_WINDOW - 1,
    )
    .unwrap();
    assert_eq!(
        vehicle.verify(&old, now),
        Err(Refusal::TooOld {
            timestamp: ours - NEW_STREAM_WINDOW - 1,
            ours
        })
    );
    let edge = sign_frame(
        &key(),
        &command_long(255, 190, 0),
        0,
        ours - NEW_STREAM_WINDOW,
    )
    .unwrap();
    assert!(vehicle.verify(&edge, now).is_ok());
}

#[test]
fn unsigned_allow_list() {
    let mut vehicle = Signing::new(key(), 0, 0);
    let now = at(T0);
    let radio = Frame::encode_v2(
        crate::SystemId(51),
        crate::ComponentId(68),
        0,
        &MavMessage::RADIO_STATUS(apm::RADIO_STATUS_DATA::default()),
    );
    assert_eq!(vehicle.verify(&radio, now), Ok(Accepted::UnsignedAllowed));
    assert_eq!(
        vehicle.verify(&command_long(255, 190, 0), now),
        Err(Refusal::Unsigned { message_id: 76 })
    );
    let mut strict = Signing::new(key(), 0, 0).with_allow_unsigned(&[]);
    assert!(strict.verify(&radio, now).is_err());
}

#[test]
fn idle_and_outage_cause_no_refusal() {
    // The sender signs at T0, then stays silent for 10 minutes, then sends across a 90 s
    // outage; the receiver forgets its streams in between (a restart). Every frame passes.
    let mut gcs = Signing::new(key(), 1, 0);
    let mut vehicle = Signing::new(key(), 0, 0);
    let mut t = T0;
    for step in [0.0, 600.0, 90.0, 0.001] {
        t += step;
        let f = gcs.sign(&command_long(255, 190, 0), at(t)).unwrap();
        assert!(vehicle.verify(&f, at(t)).is_ok(), "after {step} s");
        let mut restarted = Signing::new(key(), 0, vehicle.state(at(t)).timestamp);
        let g = gcs.sign(&command_long(255, 190, 1), at(t)).unwrap();
        assert!(
            restarted.verify(&g, at(t)).is_ok(),
            "restarted, after {step} s"
        );
        let reply = vehicle.sign(&command_long(1, 1, 0), at(t)).unwrap();
        assert!(gcs.verify(&reply, at(t)).is_ok());
    }
    // What a +1-per-frame counter (pymavlink's) would send after the 10-minute idle is
    // refused by a receiver that does not know the stream yet: why the source follows
    // the wall clock.
    let counter = timestamp_at(at(T0)) + 2;
    let stale = sign_frame(&key(), &command_long(255, 190, 0), 9, counter).unwrap();
    assert!(matches!(
        Signing::new(key(), 0, 0).verify(&stale, at(T0 + 600.0)),
        Err(Refusal::TooOld { .. })
    ));
}

#[test]
fn refused_frames_change_nothing() {
    let mut vehicle = Signing::new(key(), 0, 0);
    let now = at(T0);
    let far = timestamp_at(at(T0 + 10_000.0));
    let wrong = sign_frame(
        &SigningKey::from_passphrase("wrong"),
        &command_long(255, 190, 0),
        0,
        far,
    )
    .unwrap();
    assert_eq!(vehicle.verify(&wrong, now), Err(Refusal::BadSignature));
    assert_eq!(vehicle.clock().last(), 0);
    // The same stream signed right, with a lower timestamp, is still a new stream.
    let right = sign_frame(&key(), &command_long(255, 190, 0), 0, timestamp_at(now)).unwrap();
    assert!(vehicle.verify(&right, now).is_ok());
}

#[test]
fn state_file_round_trip_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("signing.toml");
    assert!(SigningState::load_if_exists(&path).unwrap().is_none());
    let state = SigningState {
        key: key(),
        timestamp: 123_456_789,
    };
    state.save(&path).unwrap();
    assert_eq!(SigningState::load(&path).unwrap(), state);
    assert_eq!(
        SigningState::load_if_exists(&path).unwrap(),
        Some(state.clone())
    );
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    let hex = key().to_hex();
    let cases: [(String, &str); 8] = [
        (String::new(), "missing `key`"),
        (format!("key = \"{hex}\"\n"), "missing `timestamp`"),
        (format!("key = \"{hex}\"\ntimestamp = -1\n"), "line 2"),
        (
            format!("key = \"{hex}\"\ntimestamp = 1.5\n"),
            "whole number",
        ),
        (
            format!("key = \"{hex}\"\ntimestamp = 1\nextra = 2\n"),
            "line 3: unknown field",
        ),
        (
            format!("key = \"{}\"\ntimestamp = 1\n", &hex[..60]),
            "got 60",
        ),
        (format!("key = {hex}\ntimestamp = 1\n"), "line 1"),
        ("key = [1, 2]\ntimestamp = 1\n".to_owned(), "quoted string"),
    ];
    for (text, want) in cases {
        let err = SigningState::parse(&text, &path).unwrap_err().to_string();
        assert!(err.contains(want), "{text:?}: {err}");
        assert!(err.contains("signing.toml"), "{err}");
        assert!(!err.contains(&hex[..16]), "key bytes in error: {err}");
    }
    let missing = dir.path().join("nope");
    assert!(matches!(
        SigningState::load(&missing),
        Err(SigningFileError::Read { .. })
    ));
    // Key files.
    let key_file = dir.path().join("key");
    std::fs::write(&key_file, format!("{hex}\n")).unwrap();
    assert_eq!(SigningKey::from_key_file(&key_file).unwrap(), key());
    std::fs::write(&key_file, "not a key").unwrap();
    let err = SigningKey::from_key_file(&key_file)
        .unwrap_err()
        .to_string();
    assert!(err.contains("64 hex characters, got 9"), "{err}");
    assert!(!err.contains("not a key"), "{err}");
    // Saving where no file can be written is an error, not a panic.
    assert!(matches!(
        state.save(&dir.path().join("no/such/dir/state")),
        Err(SigningFileError::Write { .. })
    ));
}

fn any_frame() -> impl Strategy<Value = Frame> {
    let ids = crate::frame::known_message_ids();
    (
        proptest::sample::select(ids),
        any::<u8>(),
        any::<u8>(),
        any::<u8>(),
        proptest::collection::vec(any::<u8>(), 1..=255),
    )
        .prop_map(|(id, sys, comp, seq, payload)| {
            Frame::encode_raw_v2(
                crate::SystemId(sys),
                crate::ComponentId(comp),
                seq,
                id,
                &payload,
                crc_extra(id).unwrap_or_default(),
            )
            .unwrap_or_else(|e| unreachable!("{e}"))
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn sign_then_verify_round_trip(
        frame in any_frame(),
        link in any::<u8>(),
        secs in 0.0f64..2.0e9,
        pass in "[ -~]{0,40}",
    ) {
        let k = SigningKey::from_passphrase(&pass);
        let mut tx = Signing::new(k.clone(), link, 0);
        let mut rx = Signing::new(k, 0, 0);
        let signed = tx.sign(&frame, at(secs)).unwrap();
        let parsed = Frame::from_bytes(signed.bytes().clone()).unwrap();
        prop_assert_eq!(parsed.payload(), frame.payload());
        prop_assert!(rx.verify(&parsed, at(secs)).is_ok());
        let replayed = matches!(rx.verify(&parsed, at(secs)), Err(Refusal::Replayed { .. }));
        prop_assert!(replayed);
    }

    #[test]
    fn any_flipped_byte_fails(
        frame in any_frame(),
        index in any::<proptest::sample::Index>(),
        bit in 0u8..8,
    ) {
        let now = at(T0);
        let signed = Signing::new(key(), 3, 0).sign(&frame, now).unwrap();
        let mut b = signed.as_bytes().to_vec();
        let i = index.index(b.len());
        b[i] ^= 1 << bit;
        // Either the framing refuses it, or the signature check does.
        if let Ok(f) = Frame::from_bytes(Bytes::from(b)) {
            let verdict = Signing::new(key(), 0, 0).verify(&f, now);
            prop_assert!(verdict.is_err(), "byte {} bit {} accepted", i, bit);
        }
    }
}
