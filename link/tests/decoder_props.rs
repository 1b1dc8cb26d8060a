//! Property tests of the frame codec: typed round-trips, garbage tolerance, split invariance.

use proptest::prelude::*;
use vtol_link::dialect::MavMessage;
use vtol_link::frame::{Frame, crc_extra, known_message_ids};
use vtol_link::{FrameDecoder, MavlinkVersion};

use mavlink::Message;

/// Bytes biased to small values, so that enum fields often hold defined values and the typed
/// decoder accepts a good share of random payloads.
fn payload_byte() -> impl Strategy<Value = u8> {
    prop_oneof![any::<u8>(), 0u8..4]
}

/// A valid frame of a known id with a random (possibly truncated) payload; v1 or v2.
fn valid_frame() -> impl Strategy<Value = Frame> {
    let ids = known_message_ids();
    (
        proptest::sample::select(ids),
        proptest::collection::vec(any::<u8>(), 1..255),
        any::<(u8, u8, u8)>(),
        any::<bool>(),
    )
        .prop_map(|(id, payload, (sys, comp, seq), v1)| {
            let extra = crc_extra(id).unwrap();
            if v1 && id < 256 {
                // v1 framing by hand: FE len seq sys comp id payload crc.
                let mut b = vec![0xFE, payload.len() as u8, seq, sys, comp, id as u8];
                b.extend_from_slice(&payload);
                let crc = vtol_link::frame::frame_crc(&b[1..], extra);
                b.extend_from_slice(&crc.to_le_bytes());
                Frame::from_bytes(b.into()).unwrap()
            } else {
                Frame::encode_raw_v2(
                    vtol_link::SystemId(sys),
                    vtol_link::ComponentId(comp),
                    seq,
                    id,
                    &payload,
                    extra,
                )
                .unwrap()
            }
        })
}

fn decode_stream(chunks: &[&[u8]]) -> Vec<Frame> {
    let mut d = FrameDecoder::new();
    let mut out = Vec::new();
    for c in chunks {
        d.push(c);
        out.extend(d.frames());
    }
    out.extend(d.finish());
    out
}

fn is_subsequence(needles: &[Frame], hay: &[Frame]) -> bool {
    let mut it = hay.iter();
    needles
        .iter()
        .all(|n| it.any(|h| h.as_bytes() == n.as_bytes()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Typed message -> v2 frame -> decoder -> typed message gives the same wire payload.
    #[test]
    fn typed_round_trip(
        id in proptest::sample::select(known_message_ids()),
        payload in proptest::collection::vec(payload_byte(), 255),
        sys in any::<u8>(), comp in any::<u8>(), seq in any::<u8>(),
    ) {
        let Ok(msg) = MavMessage::parse(MavlinkVersion::V2, id, &payload) else {
            return Ok(()); // an enum value the dialect rejects: not a message
        };
        let frame = Frame::encode_v2(vtol_link::SystemId(sys), vtol_link::ComponentId(comp), seq, &msg);
        let mut d = FrameDecoder::new();
        d.push(frame.as_bytes());
        let got: Vec<_> = d.frames().collect();
        prop_assert_eq!(got.len(), 1);
        let f = &got[0];
        prop_assert_eq!(f.as_bytes(), frame.as_bytes());
        prop_assert!(f.is_verified());
        prop_assert_eq!((f.system_id(), f.component_id(), f.seq(), f.message_id()),
                        (sys, comp, seq, id));
        let back = f.decode().unwrap();
        // Compare re-encoded payloads (NaN floats make PartialEq unreliable).
        let (mut a, mut b) = ([0u8; 255], [0u8; 255]);
        let (la, lb) = (msg.ser(MavlinkVersion::V2, &mut a), back.ser(MavlinkVersion::V2, &mut b));
        prop_assert_eq!(&a[..la], &b[..lb]);
        prop_assert_eq!(f.target(), msg.target_system_id()
            .filter(|&s| s != 0)
            .map(|s| (s, msg.target_component_id().unwrap_or(0))));
        if id < 256 {
            let v1 = Frame::encode_v1(vtol_link::SystemId(sys), vtol_link::ComponentId(comp), seq, &msg).unwrap();
            let mut d = FrameDecoder::new();
            d.push(v1.as_bytes());
            let got: Vec<_> = d.frames().collect();
            prop_assert_eq!(got.len(), 1);
            prop_assert!(got[0].decode().is_ok());
        }
    }

    /// A whole datagram decoded in place ([`FrameDecoder::push_final_with`]) gives exactly
    /// what pushing it and finishing gives: the same frames, verdicts and counters, with or
    /// without a partial frame buffered before it.
    #[test]
    fn datagram_path_matches_the_stream_path(
        items in proptest::collection::vec(
            (proptest::collection::vec(any::<u8>(), 0..48), valid_frame()), 0..8),
        tail in proptest::collection::vec(any::<u8>(), 0..48),
        head in proptest::collection::vec(any::<u8>(), 0..24),
    ) {
        let mut dgram = Vec::new();
        for (garbage, f) in &items {
            dgram.extend_from_slice(garbage);
            dgram.extend_from_slice(f.as_bytes());
        }
        dgram.extend_from_slice(&tail);
        for buffered in [&[][..], &head[..]] {
            let (mut a, mut b) = (FrameDecoder::new(), FrameDecoder::new());
            a.push(buffered);
            b.push(buffered);
            let mut via_stream: Vec<Frame> = a.frames().collect();
            a.push(&dgram);
            a.finish_with(|f| via_stream.push(f));
            let mut in_place: Vec<Frame> = b.frames().collect();
            b.push_final_with(&dgram, |f| in_place.push(f));
            prop_assert_eq!(a.stats(), b.stats());
            prop_assert_eq!(via_stream.len(), in_place.len());
            for (x, y) in via_stream.iter().zip(&in_place) {
                prop_assert_eq!(x.as_bytes(), y.as_bytes());
                prop_assert_eq!(x.is_verified(), y.is_verified());
            }
            prop_assert_eq!(a.buffered_len(), 0);
            prop_assert_eq!(b.buffered_len(), 0);
        }
    }

    /// Random garbage between valid frames: every valid frame comes out, in order, and every
    /// verified frame that comes out has a correct CRC.
    #[test]
    fn garbage_never_loses_frames(
        items in proptest::collection::vec(
            (proptest::collection::vec(any::<u8>(), 0..48), valid_frame()), 1..12),
        tail in proptest::collection::vec(any::<u8>(), 0..48),
    ) {
        let mut stream = Vec::new();
        let mut frames = Vec::new();
        for (garbage, f) in &items {
            stream.extend_from_slice(garbage);
            stream.extend_from_slice(f.as_bytes());
            frames.push(f.clone());
        }
        stream.extend_from_slice(&tail);
        let out = decode_stream(&[&stream]);
        // The one legitimate way to lose a frame: garbage that passes the 16-bit CRC by chance
        // (p = 2^-16 per candidate, inherent to MAVLink) and swallows it. Then the output holds
        // a verified frame that was never sent.
        let collision = out
            .iter()
            .any(|o| o.is_verified() && !frames.iter().any(|f| f.as_bytes() == o.as_bytes()));
        prop_assert!(collision || is_subsequence(&frames, &out),
            "lost a frame: in {:?}, out {:?}", frames, out);
        for f in out.iter().filter(|f| f.is_verified()) {
            prop_assert!(Frame::from_bytes(f.bytes().clone()).is_ok());
        }
    }

    /// Splitting the byte stream anywhere gives the same verified frames (and, for a stream
    /// of frames without garbage, exactly the same frames).
    #[test]
    fn splitting_is_invisible(
        items in proptest::collection::vec(
            (proptest::collection::vec(any::<u8>(), 0..32), valid_frame()), 1..10),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..8),
        with_garbage in any::<bool>(),
    ) {
        let mut stream = Vec::new();
        for (garbage, f) in &items {
            if with_garbage {
                stream.extend_from_slice(garbage);
            }
            stream.extend_from_slice(f.as_bytes());
        }
        let mut points: Vec<usize> = cuts.iter().map(|i| i.index(stream.len() + 1)).collect();
        points.sort_unstable();
        points.dedup();
        let mut chunks = Vec::new();
        let mut last = 0;
        for p in points {
            chunks.push(&stream[last..p]);
            last = p;
        }
        chunks.push(&stream[last..]);
        let whole = decode_stream(&[&stream]);
        let split = decode_stream(&chunks);
        let verified = |v: &[Frame]| v.iter().filter(|f| f.is_verified()).cloned().collect::<Vec<_>>();
        prop_assert_eq!(verified(&whole), verified(&split));
        if !with_garbage {
            let frames: Vec<Frame> = items.iter().map(|(_, f)| f.clone()).collect();
            prop_assert_eq!(&whole, &frames);
            prop_assert_eq!(&split, &frames);
        }
    }
}

/// Frames of ids the dialect lacks pass through a clean stream, split anywhere.
#[test]
fn unknown_ids_survive_clean_streams() {
    let u = Frame::encode_raw_v2(
        vtol_link::SystemId(3),
        vtol_link::ComponentId(4),
        5,
        0x00_BEEF,
        &[9, 8, 7, 0xFD, 0xFE, 1],
        0x42,
    )
    .unwrap();
    assert!(!u.is_verified());
    let hb = Frame::encode_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        0,
        &MavMessage::default_message_from_id(0).unwrap(),
    );
    let mut stream = Vec::new();
    for _ in 0..3 {
        stream.extend_from_slice(u.as_bytes());
        stream.extend_from_slice(hb.as_bytes());
    }
    for cut in 0..=stream.len() {
        let out = decode_stream(&[&stream[..cut], &stream[cut..]]);
        assert_eq!(out.len(), 6, "cut at {cut}");
        assert_eq!(out.iter().filter(|f| !f.is_verified()).count(), 3);
    }
}
