//! Cost of MAVLink 2 signing per frame: signing an unsigned COMMAND_LONG (33-byte payload, CRC
//! recomputed), signing a 255-byte payload, and verifying a fresh signed COMMAND_LONG (signature,
//! stream lookup, timestamp update). One thread; criterion's time per frame is CPU time per
//! frame on a quiet machine.
//!
//! Run: `cargo bench -p vtol-link --bench signing`

use std::hint::black_box;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::frame::Frame;
use vtol_link::protocol::id::COMMAND_LONG as MSG_ID_COMMAND_LONG;
use vtol_link::signing::{Signing, SigningKey};

fn command_long() -> Frame {
    Frame::encode_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(190),
        0,
        &MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
            param1: 1.0,
            command: apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }),
    )
}

fn signing(c: &mut Criterion) {
    let key = SigningKey::from_passphrase("bench");
    let mut tx = Signing::new(key.clone(), 1, 0);
    let small = command_long();
    c.bench_function("sign COMMAND_LONG (45-byte frame)", |b| {
        b.iter(|| tx.sign_now(black_box(&small)).unwrap());
    });
    // The largest frame: a 255-byte payload of an id the dialect knows (COMMAND_LONG's CRC_EXTRA).
    let big = Frame::encode_raw_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(190),
        0,
        MSG_ID_COMMAND_LONG,
        &[0x5a; 255],
        152,
    )
    .unwrap();
    c.bench_function("sign 255-byte payload (267-byte frame)", |b| {
        b.iter(|| tx.sign_now(black_box(&big)).unwrap());
    });
    let mut rx = Signing::new(key, 0, 0);
    c.bench_function("verify signed COMMAND_LONG", |b| {
        b.iter_batched(
            || tx.sign_now(&small).unwrap(),
            |f| rx.verify_now(&f).unwrap(),
            BatchSize::SmallInput,
        );
    });
}

criterion_group!(benches, signing);
criterion_main!(benches);
