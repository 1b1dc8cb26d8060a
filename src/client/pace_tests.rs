//! The pacer's rules with instants of the test's own, then the client's session over an
//! in-memory link holding its frames back while a radio reports its buffer full.

use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::{ComponentId, Frame, LinkEvent, LinkOptions, LinkSender, SystemId};

use super::*;
use crate::client::test_frames::radio_status;
use crate::client::{ClientConfig, ClientHandle};

const MS: Duration = Duration::from_millis(1);

#[test]
fn frames_go_at_once_without_a_radio_or_with_room_in_its_buffer() {
    let t0 = Instant::now();
    let mut p = Pacer::default();
    assert_eq!(p.next_send(t0), None);
    p.sent(t0);
    assert_eq!(p.next_send(t0), None);
    p.on_radio_status(TXBUF_SLOW, t0);
    assert_eq!(p.next_send(t0), None);
    p.on_radio_status(100, t0);
    assert_eq!(p.next_send(t0 + MS), None);
}

#[test]
fn a_buffer_more_than_half_full_spaces_the_frames() {
    let t0 = Instant::now();
    let mut p = Pacer::default();
    p.on_radio_status(TXBUF_SLOW - 1, t0);
    assert_eq!(p.next_send(t0), None, "nothing sent yet");
    p.sent(t0);
    assert_eq!(p.next_send(t0 + MS), Some(t0 + SLOW_GAP));
    assert_eq!(p.next_send(t0 + SLOW_GAP), None);
    // A report that the buffer drained ends the spacing.
    p.on_radio_status(90, t0 + 10 * MS);
    assert_eq!(p.next_send(t0 + 10 * MS), None);
}

#[test]
fn a_nearly_full_buffer_pauses_until_it_drains_or_the_pause_is_long() {
    let t0 = Instant::now();
    let mut p = Pacer::default();
    p.sent(t0);
    p.on_radio_status(TXBUF_PAUSE - 1, t0);
    assert_eq!(p.next_send(t0 + MS), Some(t0 + PAUSE_MAX));
    // Still nearly full a second later: the pause counts from its start.
    p.on_radio_status(5, t0 + Duration::from_secs(1));
    assert_eq!(
        p.next_send(t0 + Duration::from_secs(1)),
        Some(t0 + PAUSE_MAX)
    );
    // Past the longest pause, frames go one every gap, whatever the radio says.
    p.on_radio_status(5, t0 + PAUSE_MAX);
    assert_eq!(p.next_send(t0 + PAUSE_MAX), None);
    p.sent(t0 + PAUSE_MAX);
    assert_eq!(
        p.next_send(t0 + PAUSE_MAX + MS),
        Some(t0 + PAUSE_MAX + SLOW_GAP)
    );
    // Room again: the next pause starts afresh.
    let t1 = t0 + Duration::from_secs(5);
    p.on_radio_status(60, t1);
    assert_eq!(p.next_send(t1), None);
    p.on_radio_status(10, t1 + MS);
    assert_eq!(p.next_send(t1 + MS), Some(t1 + MS + PAUSE_MAX));
}

#[test]
fn a_radio_that_stops_reporting_holds_nothing_back() {
    let t0 = Instant::now();
    let mut p = Pacer::default();
    p.on_radio_status(40, t0);
    p.sent(t0);
    assert!(p.next_send(t0 + MS).is_some());
    assert_eq!(p.next_send(t0 + REPORT_FRESH), None);
}

/// The client's frames as the vehicle end receives them, each with when.
type Arrivals = mpsc::UnboundedReceiver<(Frame, tokio::time::Instant)>;

/// A vehicle end of an in-memory link to a client: what it receives from the client, and its
/// sender.
async fn vehicle_and_client(cancel: &CancellationToken) -> (Arrivals, LinkSender, ClientHandle) {
    let (client_end, vehicle_end) = tokio::io::duplex(1 << 16);
    let client = ClientHandle::over_stream(client_end, ClientConfig::default(), cancel.clone());
    let (tx, mut rx) = mpsc::channel(64);
    let (_, task) = vtol_link::spawn_stream_link(
        vehicle_end,
        "vehicle",
        tx,
        LinkOptions::default(),
        cancel.clone(),
    );
    drop(task);
    let sender = loop {
        if let Some(LinkEvent::Up { tx, .. }) = rx.recv().await {
            break tx;
        }
    };
    let (arrived, arrivals) = mpsc::unbounded_channel();
    tokio::spawn(async move {
        while let Some(ev) = rx.recv().await {
            if let LinkEvent::Frame { frame, .. } = ev
                && frame.system_id() == 255
            {
                let _ = arrived.send((frame, tokio::time::Instant::now()));
            }
        }
    });
    (arrivals, sender, client)
}

fn statustext(seq: u8) -> MavMessage {
    let mut text = [0u8; 50];
    text[0] = b'0' + seq;
    MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
        severity: apm::MavSeverity::MAV_SEVERITY_INFO,
        text: text.into(),
        ..Default::default()
    })
}

/// The next frame the vehicle end received from the client (system 255), and when.
async fn next_from_client(rx: &mut Arrivals) -> (Frame, tokio::time::Instant) {
    rx.recv().await.expect("link open")
}

/// Sends `frame` from the vehicle end and waits until the client's session has read it: a
/// vehicle heartbeat behind it makes the session find its vehicle.
async fn tell(tx: &LinkSender, client: &ClientHandle, frame: Frame) {
    tx.send(frame).await.expect("sent");
    let vehicle = MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: apm::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: apm::MavModeFlag::empty(),
        system_status: apm::MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    tx.send(Frame::encode_v2(SystemId(1), ComponentId(1), 0, &vehicle))
        .await
        .expect("sent");
    client
        .wait_target(Duration::from_secs(5))
        .await
        .expect("vehicle found");
}

#[tokio::test(start_paused = true)]
async fn the_client_holds_its_frames_while_the_radio_says_its_buffer_is_full() {
    let cancel = CancellationToken::new();
    let (mut rx, tx, client) = vehicle_and_client(&cancel).await;
    tell(&tx, &client, radio_status(10, 0)).await;
    let t0 = tokio::time::Instant::now();
    client.send(statustext(1)).await.expect("queued");
    // Held for the longest pause: the radio never says it drained.
    let (f, at) = next_from_client(&mut rx).await;
    assert_eq!(f.message_id(), 253);
    assert!(at - t0 >= PAUSE_MAX, "{:?}", at - t0);
    // A buffer more than half full: the frames go a gap apart, in order.
    tx.send(radio_status(40, 1)).await.expect("sent");
    // The clock is paused: a sleep ends only once every task is idle, the report read.
    tokio::time::sleep(SLOW_GAP).await;
    for n in 2..5 {
        client.send(statustext(n)).await.expect("queued");
    }
    let mut times = Vec::new();
    for n in 2..5 {
        let (f, at) = next_from_client(&mut rx).await;
        let Ok(MavMessage::STATUSTEXT(t)) = f.decode() else {
            panic!("{f:?}")
        };
        assert_eq!(t.text[0], b'0' + n);
        times.push(at);
    }
    assert!(
        times.windows(2).all(|w| w[1] - w[0] >= SLOW_GAP),
        "{times:?}"
    );
    // Room again: at once.
    tx.send(radio_status(95, 2)).await.expect("sent");
    tokio::time::sleep(MS).await;
    let t1 = tokio::time::Instant::now();
    client.send(statustext(5)).await.expect("queued");
    let (_, at) = next_from_client(&mut rx).await;
    assert!(at - t1 < SLOW_GAP, "{:?}", at - t1);
    cancel.cancel();
}

#[tokio::test(start_paused = true)]
async fn a_paused_client_sends_as_soon_as_the_radio_says_its_buffer_drained() {
    let cancel = CancellationToken::new();
    let (mut rx, tx, client) = vehicle_and_client(&cancel).await;
    tell(&tx, &client, radio_status(5, 0)).await;
    let t0 = tokio::time::Instant::now();
    client.send(statustext(1)).await.expect("queued");
    tokio::time::sleep(Duration::from_millis(500)).await;
    tx.send(radio_status(70, 1)).await.expect("sent");
    let (_, at) = next_from_client(&mut rx).await;
    let held = at - t0;
    assert!(
        held >= Duration::from_millis(500) && held < PAUSE_MAX,
        "{held:?}"
    );
    cancel.cancel();
}

#[tokio::test(start_paused = true)]
async fn a_request_held_back_by_the_radio_is_not_sent_again_meanwhile_nor_given_up() {
    let cancel = CancellationToken::new();
    let (mut rx, tx, client) = vehicle_and_client(&cancel).await;
    tell(&tx, &client, radio_status(5, 0)).await;
    let t0 = tokio::time::Instant::now();
    let asking = client.clone();
    let command = tokio::spawn(async move {
        asking
            .command_long(
                apm::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                [30.0, 100_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .await
    });
    // The radio stays nearly full: the command goes when the longest pause ends, once.
    let (f, at) = next_from_client(&mut rx).await;
    assert_eq!(f.message_id(), 76, "{f:?}");
    assert!(at - t0 >= PAUSE_MAX, "{:?}", at - t0);
    let Ok(MavMessage::COMMAND_LONG(c)) = f.decode() else {
        panic!("{f:?}")
    };
    assert_eq!(
        c.confirmation, 0,
        "the first copy, not a retry queued behind it"
    );
    // Answered: the request succeeds, although it waited longer than its retries would.
    let ack = MavMessage::COMMAND_ACK(apm::COMMAND_ACK_DATA {
        command: c.command,
        result: apm::MavResult::MAV_RESULT_ACCEPTED,
        target_system: 255,
        target_component: 190,
        ..Default::default()
    });
    tx.send(Frame::encode_v2(SystemId(1), ComponentId(1), 1, &ack))
        .await
        .expect("sent");
    let outcome = command.await.expect("joined").expect("answered");
    assert!(outcome.accepted(), "{outcome:?}");
    // Nothing else was queued behind it.
    tokio::time::sleep(PAUSE_MAX).await;
    assert!(rx.try_recv().is_err());
    cancel.cancel();
}
