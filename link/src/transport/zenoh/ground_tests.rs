//! The ground end's bookkeeping on a real (unconnected) Zenoh session: departures, late
//! samples and returns, and that a fleet whose vehicles come and go keeps a bounded state.

use super::*;
use crate::transport::{ZenohMode, ZenohOptions};
use crate::{ComponentId, SystemId, dialect};
use zenoh::sample::SampleBuilder;

async fn ground() -> Ground {
    let opts = ZenohOptions {
        mode: ZenohMode::Peer,
        listen: vec!["tcp/127.0.0.1:0".to_string()],
        ..ZenohOptions::default()
    };
    let session = super::super::session(&opts).await.expect("a Zenoh session");
    Ground {
        fleet: "t".to_string(),
        session,
        opts: LinkOptions::default(),
        cancel: CancellationToken::new(),
        runtime: tokio::runtime::Handle::current(),
        links: HashMap::new(),
        gone: HashMap::new(),
        late: 0,
        declared: HashMap::new(),
        wake: Arc::new(tokio::sync::Notify::new()),
    }
}

fn token(v: &str, kind: SampleKind) -> Sample {
    let key = KeyExpr::try_from(liveliness_key("t", v)).unwrap();
    match kind {
        SampleKind::Put => SampleBuilder::put(key, Vec::<u8>::new()).into(),
        SampleKind::Delete => SampleBuilder::delete(key).into(),
    }
}

fn data(v: &str, sys: u8, seq: u8) -> Sample {
    let msg = dialect::MavMessage::ATTITUDE(dialect::ATTITUDE_DATA::default());
    let f = Frame::encode_v2(SystemId(sys), ComponentId(1), seq, &msg);
    let key = KeyExpr::try_from(from_vehicle_key("t", v)).unwrap();
    SampleBuilder::put(key, f.as_bytes().to_vec()).into()
}

/// Counts of (Up, Down) events.
fn ups_downs(events: &[LinkEvent]) -> (usize, usize) {
    let up = events
        .iter()
        .filter(|e| matches!(e, LinkEvent::Up { .. }))
        .count();
    let down = events
        .iter()
        .filter(|e| matches!(e, LinkEvent::Down { .. }))
        .count();
    (up, down)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn vehicles_leaving_and_rejoining_leave_the_ground_at_its_steady_size() {
    let mut g = ground().await;
    let names: Vec<String> = (1..=8).map(|i| format!("v{i}")).collect();
    let (mut events, mut frames) = (Vec::new(), Vec::new());
    let mut sizes = Vec::new();
    for round in 0..50u8 {
        for (i, v) in names.iter().enumerate() {
            g.liveliness(&token(v, SampleKind::Put), &mut events);
            g.data(&data(v, i as u8 + 1, round), &mut events, &mut frames);
            g.liveliness(&token(v, SampleKind::Delete), &mut events);
        }
        assert_eq!(g.links.len(), names.len());
        g.expire(Instant::now() + LEAVE_GRACE, &mut events);
        sizes.push((g.links.len(), g.gone.len()));
    }
    // Every frame delivered, every link that came up went down, nothing dropped as late.
    assert_eq!(frames.len(), 50 * names.len());
    assert_eq!(ups_downs(&events), (50 * names.len(), 50 * names.len()));
    assert_eq!(g.late, 0);
    assert!(sizes.iter().all(|s| *s == (0, names.len())), "{sizes:?}");
    // Each vehicle's data key declared once, not once per link (Zenoh's key ids would run out).
    assert_eq!(g.declared.len(), names.len());
    // A departure is remembered for a while only.
    g.expire(Instant::now() + LEAVE_GRACE + GONE_MEMORY, &mut events);
    assert!(g.gone.is_empty());
    assert_eq!(g.next_expiry(), None);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_after_the_grace_bring_the_vehicle_back_and_are_delivered() {
    let mut g = ground().await;
    let (mut events, mut frames) = (Vec::new(), Vec::new());
    g.liveliness(&token("v1", SampleKind::Put), &mut events);
    g.liveliness(&token("v1", SampleKind::Delete), &mut events);
    g.expire(Instant::now() + LEAVE_GRACE, &mut events);
    assert_eq!(ups_downs(&events), (1, 1));

    // Its last samples, later than the grace: a link again, for a grace, and the frames on it.
    g.data(&data("v1", 1, 7), &mut events, &mut frames);
    g.data(&data("v1", 1, 8), &mut events, &mut frames);
    assert_eq!(ups_downs(&events), (2, 1));
    assert_eq!(frames.len(), 2);
    assert_eq!(g.late, 1);
    let Some(LinkEvent::Up { id, .. }) = events.get(2) else {
        panic!("{events:?}")
    };
    assert!(frames.iter().all(|(l, _)| l == id));
    let due = g.next_expiry().expect("a grace");
    assert!(due > Instant::now() && due <= Instant::now() + LEAVE_GRACE);
    g.expire(due, &mut events);
    assert_eq!(ups_downs(&events), (2, 2));
    assert!(g.links.is_empty());

    // Back ahead of its new token: its first samples bring it up, the token keeps it up.
    g.data(&data("v1", 1, 9), &mut events, &mut frames);
    g.liveliness(&token("v1", SampleKind::Put), &mut events);
    assert_eq!(ups_downs(&events), (3, 2));
    assert_eq!(frames.len(), 3);
    assert_eq!(g.next_expiry(), None);
    g.expire(Instant::now() + LEAVE_GRACE * 4, &mut events);
    assert_eq!(ups_downs(&events), (3, 2));
    assert_eq!(g.links.len(), 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_in_the_grace_extend_it() {
    let mut g = ground().await;
    let (mut events, mut frames) = (Vec::new(), Vec::new());
    g.liveliness(&token("v1", SampleKind::Put), &mut events);
    g.liveliness(&token("v1", SampleKind::Delete), &mut events);
    let first = g.next_expiry().expect("a grace");
    g.data(&data("v1", 1, 1), &mut events, &mut frames);
    let extended = g.next_expiry().expect("a grace");
    assert!(extended >= first);
    g.expire(first, &mut events);
    // Still up at the first deadline only if the sample came later than the token's removal.
    let (_, down) = ups_downs(&events);
    assert_eq!(down, usize::from(extended == first));
    g.expire(extended, &mut events);
    assert_eq!(ups_downs(&events), (1, 1));
    assert_eq!(frames.len(), 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_more_keys_are_declared_than_the_session_can_number() {
    let mut g = ground().await;
    let (mut events, mut frames) = (Vec::new(), Vec::new());
    for i in 0..MAX_DECLARED_KEYS + 8 {
        let v = format!("v{i}");
        g.data(&data(&v, 1, 0), &mut events, &mut frames);
        g.liveliness(&token(&v, SampleKind::Delete), &mut events);
        g.expire(Instant::now() + LEAVE_GRACE, &mut events);
    }
    assert_eq!(g.declared.len(), MAX_DECLARED_KEYS);
    // The vehicles past the bound are served all the same.
    assert_eq!(frames.len(), MAX_DECLARED_KEYS + 8);
    assert_eq!(
        ups_downs(&events),
        (MAX_DECLARED_KEYS + 8, MAX_DECLARED_KEYS + 8)
    );
}
