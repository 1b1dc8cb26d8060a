//! The tracker state's tests.

use super::*;
use vtol_link::dialect;

fn hb(mavtype: MavType, autopilot: MavAutopilot, armed: bool) -> MavMessage {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        custom_mode: 18,
        mavtype,
        autopilot,
        base_mode,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// The twin's heartbeat: a tailsitter, armed or not.
fn vehicle_beat(armed: bool) -> MavMessage {
    hb(
        MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        MavAutopilot::MAV_AUTOPILOT_GENERIC,
        armed,
    )
}

/// A ground station's heartbeat.
fn gcs_beat() -> MavMessage {
    hb(
        MavType::MAV_TYPE_GCS,
        MavAutopilot::MAV_AUTOPILOT_INVALID,
        false,
    )
}

/// The vehicle (1, 1) and a ground station (255, 190), as senders.
const VEHICLE: (u8, u8) = (1, 1);
const CLIENT: (u8, u8) = (255, 190);

/// A tracker fed frames, by default all at one instant.
struct Fixture {
    s: VehicleState,
    now: Instant,
}

impl Fixture {
    fn new() -> Self {
        Self {
            s: VehicleState::default(),
            now: Instant::now(),
        }
    }

    /// Applies `msg` sent by `from` under `seq` on `link` at `now`.
    fn feed(
        &mut self,
        link: u32,
        side: Side,
        from: (u8, u8),
        seq: u8,
        msg: &MavMessage,
    ) -> Option<MavMessage> {
        let now = self.now;
        self.feed_at(link, side, from, seq, msg, now)
    }

    /// Applies `msg` sent by `from` under `seq` on `link` at `at`.
    fn feed_at(
        &mut self,
        link: u32,
        side: Side,
        (sys, comp): (u8, u8),
        seq: u8,
        msg: &MavMessage,
        at: Instant,
    ) -> Option<MavMessage> {
        let frame = Frame::encode_v2(SystemId(sys), ComponentId(comp), seq, msg);
        self.s.apply(LinkId(link), side, &frame, at)
    }

    fn vehicle(&self, (sys, comp): (u8, u8)) -> &VehicleView {
        &self.s.vehicles[&(SystemId(sys), ComponentId(comp))]
    }

    fn link(&self, link: u32) -> &LinkHealth {
        &self.s.links[&LinkId(link)]
    }
}

#[test]
fn a_boot_clock_going_back_is_a_reboot() {
    let mut f = Fixture::new();
    f.feed(1, Side::Vehicle, VEHICLE, 0, &vehicle_beat(false));
    let attitude = |ms: u32| {
        MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
            time_boot_ms: ms,
            ..Default::default()
        })
    };
    for (seq, ms) in [10_000, 10_050, 10_050, 10_100].into_iter().enumerate() {
        f.feed(1, Side::Vehicle, VEHICLE, seq as u8, &attitude(ms));
    }
    let v = f.vehicle(VEHICLE);
    assert_eq!(
        (v.reboots, v.last_reboot),
        (0, None),
        "equal or rising times"
    );
    f.feed(1, Side::Vehicle, VEHICLE, 9, &attitude(1_520));
    f.feed(1, Side::Vehicle, VEHICLE, 10, &attitude(1_570));
    let v = f.vehicle(VEHICLE);
    assert_eq!(v.reboots, 1);
    let r = v.last_reboot.unwrap();
    assert_eq!((r.before_ms, r.after_ms), (10_100, 1_520));
}

#[test]
fn vehicle_found_by_heartbeat_and_gcs_ignored() {
    let mut f = Fixture::new();
    f.feed(1, Side::Client, CLIENT, 0, &gcs_beat());
    assert!(f.s.vehicles.is_empty());
    f.feed(2, Side::Vehicle, VEHICLE, 0, &vehicle_beat(true));
    let view = f.vehicle(VEHICLE);
    assert!(view.armed);
    assert_eq!(view.mode_name(), "QHOVER");
}

#[test]
fn a_restart_on_a_link_that_stays_up_is_no_loss() {
    // A twin restarted behind a UDP link (which never goes down): its sequence starts at 0
    // again, and a client's first two frames both carry 0. Neither is a wrap of 255 lost.
    let mut f = Fixture::new();
    let v = vehicle_beat(false);
    let other = gcs_beat();
    let frames = [
        (VEHICLE, 0u8),
        (VEHICLE, 1),
        (VEHICLE, 2),
        (VEHICLE, 0),
        (VEHICLE, 1),
    ];
    let client_frames = [(CLIENT, 0u8), (CLIENT, 0), (CLIENT, 1)];
    // The restart comes a second later, and the client's two frames differ: identical
    // frames under one number within moments of each other are one datagram repeated.
    for (k, (from, seq)) in frames.into_iter().chain(client_frames).enumerate() {
        let at = f.now + Duration::from_secs(u64::from(k >= 3));
        let msg = if k == 6 { &other } else { &v };
        f.feed_at(1, Side::Vehicle, from, seq, msg, at);
    }
    assert_eq!(f.link(1).lost, 0);
    assert_eq!(f.link(1).frames, 8);
}

#[test]
fn late_frames_are_no_loss_and_repeated_ones_count_once() {
    let mut f = Fixture::new();
    let v = vehicle_beat(false);
    // 1 overtaken by 2, 2 and 4 repeated, 5 lost.
    for (k, seq) in [0u8, 2, 1, 2, 3, 4, 4, 6].into_iter().enumerate() {
        let applied = f.feed(1, Side::Vehicle, VEHICLE, seq, &v);
        assert_eq!(applied.is_none(), k == 3 || k == 6, "frame {k}");
    }
    let now = f.now;
    let h = f.link(1);
    assert_eq!((h.frames, h.lost), (6, 1));
    assert!((h.window.loss_pct(now) - 100.0 / 7.0).abs() < 1e-9);
    let view = f.vehicle(VEHICLE);
    assert_eq!((view.frames, view.lost), (6, 1));
    assert!((view.window.loss_pct(now) - 100.0 / 7.0).abs() < 1e-9);
}

#[test]
fn sequence_gaps_count_as_loss() {
    let mut f = Fixture::new();
    let v = vehicle_beat(false);
    for seq in [250u8, 251, 253, 254, 255, 0, 3] {
        f.feed(1, Side::Vehicle, VEHICLE, seq, &v);
    }
    let h = f.link(1);
    assert_eq!(h.frames, 7);
    assert_eq!(h.lost, 3);
    assert!((h.window.loss_pct(f.now) - 30.0).abs() < 1e-9);
    // Once the link goes down and comes back (a reconnect keeps its id), the gap is not
    // loss.
    f.s.retain_links(&[]);
    f.s.retain_links(&[LinkId(1)]);
    f.feed(1, Side::Vehicle, VEHICLE, 100, &v);
    assert_eq!(f.link(1).lost, 0);
}

#[test]
fn a_vehicle_whose_link_goes_down_is_lost_at_once_and_back_with_its_next_heartbeat() {
    let mut f = Fixture::new();
    let v = vehicle_beat(false);
    for (link, sys) in [(1, 1), (2, 2)] {
        f.feed(link, Side::Vehicle, (sys, 1), 0, &v);
    }
    f.s.forget_link(LinkId(2));
    // A heartbeat of link 2 still on its way to the tracker is stale: 2 stays lost.
    f.feed(2, Side::Vehicle, (2, 1), 1, &v);
    let now = f.now;
    let lost = |f: &Fixture, sys: u8| f.vehicle((sys, 1)).is_lost(now);
    assert!(!lost(&f, 1));
    assert!(lost(&f, 2));
    assert!(!f.s.vehicle_lost(now));
    f.feed(3, Side::Vehicle, (2, 1), 2, &v);
    assert!(!lost(&f, 2));
}

#[test]
fn vehicles_leaving_and_rejoining_on_new_links_leave_the_state_at_its_steady_size() {
    let mut s = VehicleState::default();
    let now = Instant::now();
    let v = hb(
        MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        MavAutopilot::MAV_AUTOPILOT_GENERIC,
        false,
    );
    let att = MavMessage::ATTITUDE(dialect::ATTITUDE_DATA::default());
    // Five vehicles, each leaving and coming back on a new link (a fleet's vehicle does) many
    // times more often than the state remembers departed links.
    let rounds = 3 * DOWN_MEMORY as u64 / 5;
    let mut next_link = 1;
    let mut sizes = Vec::new();
    for round in 0..rounds {
        let mut live = Vec::new();
        for sys in 1..=5u8 {
            let link = LinkId(next_link);
            next_link += 1;
            let seq = (round % 128) as u8 * 2;
            for (i, m) in [&v, &att].into_iter().enumerate() {
                let f = Frame::encode_v2(SystemId(sys), ComponentId(1), seq + i as u8, m);
                s.apply(link, Side::Vehicle, &f, now);
            }
            live.push(link);
        }
        // Every one of them leaves: the router's links are none.
        s.retain_links(&[]);
        sizes.push((
            s.vehicles.len(),
            s.links.len(),
            s.messages.len(),
            s.last_seq.len(),
            s.down.len().max(s.down_order.len()),
        ));
        // A frame of a departed link still on its way is stale.
        let stale = Frame::encode_v2(SystemId(1), ComponentId(1), 255, &v);
        s.apply(live[0], Side::Vehicle, &stale, now);
        assert!(s.vehicles[&(SystemId(1), ComponentId(1))].is_lost(now));
    }
    // The same five vehicles, however often they came back.
    assert_eq!(s.vehicles.len(), 5);
    assert!(s.vehicles.values().all(|x| x.frames >= rounds));
    let last = *sizes.last().unwrap();
    assert_eq!(last, (5, 0, 10, 0, DOWN_MEMORY));
    assert!(sizes.iter().all(|x| x.4 <= DOWN_MEMORY), "{sizes:?}");
    assert_eq!(s.down.len(), s.down_order.len());
}

/// A HEARTBEAT's payload: custom_mode, type, autopilot (armed, custom mode enabled, ACTIVE).
fn raw_heartbeat(custom_mode: u32, mav_type: u8, autopilot: u8) -> Frame {
    let mut p = [0u8; 9];
    p[..4].copy_from_slice(&custom_mode.to_le_bytes());
    p[4] = mav_type;
    p[5] = autopilot;
    p[6] = 0x81;
    p[7] = 4;
    p[8] = 3;
    Frame::encode_payload_v2(SystemId(1), ComponentId(1), 0, 0, &p).unwrap()
}

#[test]
fn an_arducopter_reads_copter_modes() {
    let mut s = VehicleState::default();
    // ArduCopter, QUADROTOR, custom_mode 5.
    s.apply(
        LinkId(1),
        Side::Vehicle,
        &raw_heartbeat(5, 2, 3),
        Instant::now(),
    );
    let v = &s.vehicles[&(SystemId(1), ComponentId(1))];
    assert_eq!((v.autopilot, v.mav_type), (3, 2));
    assert_eq!(v.mode_name(), "LOITER");
    assert_eq!(v.kind(), "ArduCopter");
    s.apply(
        LinkId(1),
        Side::Vehicle,
        &raw_heartbeat(4, 2, 3),
        Instant::now(),
    );
    assert_eq!(
        s.vehicles[&(SystemId(1), ComponentId(1))].mode_name(),
        "GUIDED"
    );
    // PX4: main mode 3 (POSCTL).
    s.apply(
        LinkId(1),
        Side::Vehicle,
        &raw_heartbeat(196_609, 2, 12),
        Instant::now(),
    );
    assert_eq!(
        s.vehicles[&(SystemId(1), ComponentId(1))].mode_name(),
        "POSCTL"
    );
}

/// A vehicle whose MAV_TYPE the dialect does not define (60) is tracked, not dropped: its
/// type is kept as the number and its mode falls back to `MODE(n)`.
#[test]
fn a_type_the_dialect_lacks_is_still_a_vehicle() {
    let mut s = VehicleState::default();
    let got = s.apply(
        LinkId(1),
        Side::Vehicle,
        &raw_heartbeat(7, 60, 3),
        Instant::now(),
    );
    assert!(matches!(got, Some(MavMessage::HEARTBEAT(_))));
    let v = &s.vehicles[&(SystemId(1), ComponentId(1))];
    assert_eq!((v.autopilot, v.mav_type), (3, 60));
    assert!(v.armed);
    assert_eq!(v.mode_name(), "MODE(7)");
    assert_eq!(v.kind(), "ArduPilot type 60");
}
