//! Message rates and requests for messages. GET_MESSAGE_INTERVAL as a state machine: the
//! request sent again until the vehicle's MESSAGE_INTERVAL for that message arrives, or given
//! up (a vehicle that does not answer it leaves the interval unknown). REQUEST_MESSAGE and
//! SET_MESSAGE_INTERVAL as commands, and [`ask_on_connect`]: what the operator's view needs
//! that ArduPilot does not send unasked — HOME_POSITION (the home distance), and
//! EXTENDED_SYS_STATE (the VTOL state and a transition's progress) when it is not streamed.

use std::time::{Duration, Instant};

use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::{self as apm, MavCmd, MavMessage};
use vtol_link::{ComponentId, SystemId};

use super::machine::{Inbound, Machine, Retry, Step};
use super::{ClientError, ClientHandle};
use crate::tracker::VehicleState;

/// HOME_POSITION's message id.
pub const HOME_POSITION: u32 = vtol_link::protocol::id::HOME_POSITION;
/// EXTENDED_SYS_STATE's message id.
pub const EXTENDED_SYS_STATE: u32 = vtol_link::protocol::id::EXTENDED_SYS_STATE;
/// How long after first contact EXTENDED_SYS_STATE may take to come unasked (ArduPilot
/// streams it at 1 Hz or more when its stream rates include it).
pub const STREAM_WAIT: Duration = Duration::from_secs(3);
/// The interval asked for EXTENDED_SYS_STATE when it does not come: 2 Hz.
pub const EXTENDED_SYS_STATE_INTERVAL_US: f32 = 500_000.0;

impl ClientHandle {
    /// Asks the vehicle to send message `msgid` once (MAV_CMD_REQUEST_MESSAGE); the message
    /// comes as any other.
    ///
    /// # Errors
    /// [`ClientError::Refused`] (not supported, or nothing to send yet such as a home not
    /// set), or a link error.
    pub async fn request_message(&self, msgid: u32) -> Result<(), ClientError> {
        self.command_ok(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [msgid as f32, 0., 0., 0., 0., 0., 0.],
        )
        .await
    }

    /// Asks the vehicle to stream message `msgid` every `interval_us` µs
    /// (MAV_CMD_SET_MESSAGE_INTERVAL; −1 stops it, 0 restores its default).
    ///
    /// # Errors
    /// As [`ClientHandle::request_message`].
    pub async fn set_message_interval(
        &self,
        msgid: u32,
        interval_us: f32,
    ) -> Result<(), ClientError> {
        self.command_ok(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [msgid as f32, interval_us, 0., 0., 0., 0., 0.],
        )
        .await
    }
}

/// The heartbeats a client hears from now on (made before a command, read after it).
#[derive(Debug)]
pub struct Heartbeats(tokio::sync::broadcast::Receiver<std::sync::Arc<Inbound>>);

impl ClientHandle {
    /// Starts listening to heartbeats.
    #[must_use]
    pub fn heartbeats(&self) -> Heartbeats {
        Heartbeats(self.inbound.subscribe())
    }
}

impl Heartbeats {
    /// The last heartbeat of `target` heard since [`ClientHandle::heartbeats`], else the next
    /// one within `timeout`; `None` when none comes.
    pub async fn latest(
        &mut self,
        target: (SystemId, ComponentId),
        timeout: Duration,
    ) -> Option<apm::HEARTBEAT_DATA> {
        use tokio::sync::broadcast::error::{RecvError, TryRecvError};
        let mine = |m: &Inbound| match &m.msg {
            MavMessage::HEARTBEAT(h) if (m.sys, m.comp) == target => Some(h.clone()),
            _ => None,
        };
        let mut last = None;
        loop {
            match self.0.try_recv() {
                Ok(m) => last = mine(&m).or(last),
                Err(TryRecvError::Lagged(_)) => {}
                Err(TryRecvError::Empty | TryRecvError::Closed) => break,
            }
        }
        if last.is_some() {
            return last;
        }
        tokio::time::timeout(timeout, async {
            loop {
                match self.0.recv().await {
                    Ok(m) => {
                        if let Some(h) = mine(&m) {
                            return Some(h);
                        }
                    }
                    Err(RecvError::Lagged(_)) => {}
                    Err(RecvError::Closed) => return None,
                }
            }
        })
        .await
        .ok()
        .flatten()
    }
}

/// What the tracker knows of the client's vehicle: its key, reboots, armed, and whether
/// HOME_POSITION and EXTENDED_SYS_STATE were heard from it.
fn vehicle_now(
    s: &VehicleState,
    client: &ClientHandle,
) -> Option<((SystemId, ComponentId), u32, bool, bool)> {
    let key = client
        .target()
        .or_else(|| s.vehicles.keys().next().copied())?;
    let v = s.vehicles.get(&key)?;
    let heard = |id| s.messages.contains_key(&(key.0, key.1, id));
    Some((key, v.reboots, v.armed, heard(HOME_POSITION)))
}

/// Whether EXTENDED_SYS_STATE came from `key` after `since` (not a copy from before a reboot).
fn heard_ext(s: &VehicleState, key: (SystemId, ComponentId), since: Instant) -> bool {
    s.messages
        .get(&(key.0, key.1, EXTENDED_SYS_STATE))
        .is_some_and(|m| m.last_at > since)
}

/// While an operator is present, asks the client's vehicle, at first contact and after each
/// reboot, for HOME_POSITION (again at each arming while none came: ArduPilot sets home when it arms) and, when
/// EXTENDED_SYS_STATE has not come within [`STREAM_WAIT`], for that message at 2 Hz. Every
/// answer is logged; a refusal changes nothing else. Runs until `cancel` fires or the tracker
/// stops.
pub async fn ask_on_connect(
    mut state: watch::Receiver<std::sync::Arc<VehicleState>>,
    client: ClientHandle,
    cancel: CancellationToken,
) {
    // (vehicle, reboots) already asked for; whether it was armed at the last look.
    let mut asked: Option<((SystemId, ComponentId), u32)> = None;
    let mut was_armed = false;
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            r = state.changed() => if r.is_err() { return },
        }
        let Some((key, reboots, armed, has_home)) =
            vehicle_now(&state.borrow_and_update(), &client)
        else {
            continue;
        };
        // Only for an operator's view (the terminal UI holds the guard): a headless daemon
        // routes, and sends the vehicle nothing its clients did not ask for. An operator who
        // comes later is served at the next state change, as at first contact.
        if !client.has_operator() {
            asked = None;
            continue;
        }
        let armed_now = armed && !was_armed;
        was_armed = armed;
        let first = asked != Some((key, reboots));
        // Home is set when the vehicle arms: ask again then if none came yet.
        let home_again = armed_now && !has_home;
        if !first && !home_again {
            continue;
        }
        asked = Some((key, reboots));
        let since = crate::tracker::now();
        let home = tokio::select! {
            () = cancel.cancelled() => return,
            r = client.request_message(HOME_POSITION) => r,
        };
        match home {
            Ok(()) => tracing::debug!("HOME_POSITION asked of {}:{}", key.0, key.1),
            Err(e) => tracing::info!("HOME_POSITION not sent by {}:{}: {e}", key.0, key.1),
        }
        if !first {
            continue;
        }
        let streamed = tokio::time::timeout(STREAM_WAIT, async {
            loop {
                if heard_ext(&state.borrow_and_update(), key, since) {
                    return true;
                }
                if state.changed().await.is_err() {
                    return false;
                }
            }
        });
        let streamed = tokio::select! {
            () = cancel.cancelled() => return,
            r = streamed => r.unwrap_or(false),
        };
        if streamed {
            continue;
        }
        let r = tokio::select! {
            () = cancel.cancelled() => return,
            r = client.set_message_interval(EXTENDED_SYS_STATE, EXTENDED_SYS_STATE_INTERVAL_US) => r,
        };
        match r {
            Ok(()) => tracing::info!(
                "EXTENDED_SYS_STATE not streamed by {}:{}: asked for it at 2 Hz",
                key.0,
                key.1
            ),
            Err(e) => tracing::info!(
                "EXTENDED_SYS_STATE not streamed by {}:{}, and not sent when asked: {e}",
                key.0,
                key.1
            ),
        }
    }
}

/// Sends before the interval is called unknown…
pub const INTERVAL_TRIES: u8 = 6;
/// …and at least this long: a full radio's queue holds the answer back for a while.
pub const INTERVAL_GIVE_UP: Duration = Duration::from_secs(2);

/// One message's interval, asked of `target`: `Some(µs)` as the vehicle reports it (0: not
/// sent or unknown, −1: disabled), `None` without an answer.
#[derive(Debug)]
pub struct IntervalMachine {
    target: (SystemId, ComponentId),
    msgid: u32,
    retry: Retry,
    done: Option<Option<i32>>,
}

impl IntervalMachine {
    /// Asks `target` for the interval of `msgid`, asking again every `rto` (then backing off).
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), msgid: u32, rto: Duration) -> Self {
        Self {
            target,
            msgid,
            retry: Retry::new(rto, INTERVAL_TRIES, INTERVAL_GIVE_UP),
            done: None,
        }
    }

    // GET_MESSAGE_INTERVAL is deprecated for REQUEST_MESSAGE(MESSAGE_INTERVAL, id), which
    // neither ArduPilot nor the twin answers with the interval; both answer this.
    #[allow(deprecated)]
    fn request(&mut self, now: Instant) -> MavMessage {
        let send = self.retry.send(now);
        vtol_link::frame::command_long(
            self.target,
            MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL,
            [self.msgid as f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            send - 1,
        )
    }
}

impl Machine for IntervalMachine {
    type Output = Option<i32>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.request(now)]
    }

    fn on_message(&mut self, _now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if let MavMessage::MESSAGE_INTERVAL(i) = &m.msg
            && (m.sys, m.comp) == self.target
            && u32::from(i.message_id) == self.msgid
        {
            self.done.get_or_insert(Some(i.interval_us));
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        match self.retry.step(now) {
            Step::Wait => Vec::new(),
            Step::GiveUp => {
                self.done = Some(None);
                Vec::new()
            }
            Step::Send => vec![self.request(now)],
        }
    }

    fn deadline(&self) -> Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

    fn interval(msgid: u16, us: i32) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::MESSAGE_INTERVAL(apm::MESSAGE_INTERVAL_DATA {
                interval_us: us,
                message_id: msgid,
            }),
        }
    }

    #[test]
    fn the_answer_for_that_message_ends_it_and_silence_gives_up() {
        let t0 = Instant::now();
        let mut m = IntervalMachine::new(V, 251, Duration::from_millis(20));
        assert_eq!(m.start(t0).len(), 1);
        m.on_message(t0, &interval(30, 20_000));
        assert!(m.result().is_none(), "another message's interval");
        assert_eq!(m.on_time(m.deadline()).len(), 1, "asked again");
        m.on_message(t0, &interval(251, 100_000));
        assert_eq!(m.result(), Some(Some(100_000)));

        let mut m = IntervalMachine::new(V, 251, Duration::from_millis(20));
        let mut sends = m.start(t0).len();
        while m.done.is_none() {
            sends += m.on_time(m.deadline()).len();
        }
        assert!(sends >= usize::from(INTERVAL_TRIES), "{sends}");
        assert!(m.deadline().duration_since(t0) >= INTERVAL_GIVE_UP);
        assert_eq!(m.result(), Some(None));
    }
}
