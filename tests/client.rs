//! The ground station's client against the real twin over real TCP sockets: parameter pull,
//! verified writes, the transactional push (ordering, refusal, rollback), commands with the
//! vehicle's reasons, all again at 30 % frame loss each way, and the daemon's operator
//! heartbeat.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use firmware_sim::shell::clock::ClockMode;
use firmware_sim::shell::serve::{Impairment, ServeConfig, Twin};
use tokio_util::sync::CancellationToken;
use vtol_gcs::client::{ClientConfig, ClientError, ClientHandle};
use vtol_gcs::params::plan::{ParamOutcome, PushResult};
use vtol_gcs::params::{MavParamType, Param, ParamSet};

struct Rig {
    cancel: CancellationToken,
    client: ClientHandle,
}

impl Drop for Rig {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

async fn rig(loss: f64, seed: u64, speed: f64) -> Rig {
    let cancel = CancellationToken::new();
    let config = ServeConfig {
        listen: vec!["tcpin:127.0.0.1:0".parse().expect("url")],
        clock: ClockMode::Scaled { speed },
        impairment: Impairment {
            loss,
            latency: Duration::ZERO,
            seed,
            radio_baud: None,
        },
        ..ServeConfig::default()
    };
    let twin = Twin::start(config, cancel.clone())
        .await
        .expect("twin starts");
    let port = twin.bound()[0].local_addr.expect("bound").port();
    tokio::spawn(twin.join());
    let url = format!("tcp:127.0.0.1:{port}").parse().expect("url");
    let client = ClientHandle::connect(&url, ClientConfig::default(), cancel.clone())
        .await
        .expect("client opens its link");
    client
        .wait_target(Duration::from_secs(20))
        .await
        .expect("vehicle heartbeat");
    Rig { cancel, client }
}

fn defaults() -> BTreeMap<&'static str, f32> {
    firmware_sim::nav::params::TABLE
        .iter()
        .map(|d| (d.name, d.ty.cast(d.default) as f32))
        .collect()
}

fn wanted(items: &[(&str, f32)]) -> ParamSet {
    items
        .iter()
        .map(|(n, v)| {
            (
                (*n).to_owned(),
                Param {
                    value: *v,
                    ty: MavParamType::MAV_PARAM_TYPE_REAL32,
                },
            )
        })
        .collect()
}

const LOW_LATERAL: [(&str, f32); 4] = [
    ("LAT_SAT_A", 0.4),
    ("LAT_SAT_B", 0.2),
    ("LAT_SAT_C", 0.1),
    ("LAT_SAT_D", 0.05),
];

/// Every check of the push, on one twin: same set → 0 changed; a one-order set applied and
/// verified; a set breaking the conditions next to a valid change leaves the vehicle as it was.
async fn push_scenarios(r: &Rig) {
    let c = &r.client;
    let table = c.params_pull(None).await.expect("pull");
    assert_eq!(table.len(), firmware_sim::nav::params::TABLE.len());
    for (name, v) in defaults() {
        assert_eq!(table[name].value.to_bits(), v.to_bits(), "{name}");
    }

    let same = c
        .params_push(&table, None)
        .await
        .expect("push of the pulled table");
    assert_eq!(same.result, PushResult::Applied);
    assert_eq!(same.changed, 0);
    assert!(same.outcomes.is_empty(), "{same:?}");

    let low = c
        .params_push(&wanted(&LOW_LATERAL), None)
        .await
        .expect("push");
    assert_eq!(low.result, PushResult::Applied, "{low:?}");
    assert_eq!(low.changed, 4);
    let after = c.params_pull(None).await.expect("pull");
    for (n, v) in LOW_LATERAL {
        assert_eq!(after[n].value, v, "{n} on the vehicle");
        assert!(matches!(low.outcomes[n], ParamOutcome::Written { new, .. } if new == v));
    }

    let bad = c
        .params_push(&wanted(&[("ALT_KP", 6.0), ("LAT_SAT_B", 2.0)]), None)
        .await
        .expect("push runs");
    let PushResult::RolledBack { cause } = &bad.result else {
        panic!("expected a rollback: {bad:?}");
    };
    assert!(cause.contains("LAT_SAT_B"), "{cause}");
    assert!(
        matches!(&bad.outcomes["LAT_SAT_B"], ParamOutcome::Refused { reason, .. } if reason.contains("LAT_SAT_B")),
        "{bad:?}"
    );
    assert_eq!(bad.changed, 0);
    let unchanged = c.params_pull(None).await.expect("pull");
    assert_eq!(
        unchanged, after,
        "a refused push leaves the vehicle exactly as it was"
    );

    // Back to the defaults, which again needs the reverse order.
    let back = wanted(&[
        ("LAT_SAT_A", 1.2),
        ("LAT_SAT_B", 0.6),
        ("LAT_SAT_C", 0.22),
        ("LAT_SAT_D", 0.18),
    ]);
    let restored = c.params_push(&back, None).await.expect("push");
    assert_eq!(restored.result, PushResult::Applied, "{restored:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pull_push_and_rollback_lossless() {
    let r = rig(0.0, 1, 1.0).await;
    push_scenarios(&r).await;
    // One verified write, and a refusal with the vehicle's reason.
    assert_eq!(r.client.param_set("HOVER_ALT", 1.5).await, Ok(1.5));
    match r.client.param_set("LAT_SAT_D", 5.0).await {
        Err(ClientError::Refused { reason }) => assert!(reason.contains("LAT_SAT_D"), "{reason}"),
        other => panic!("expected a refusal, got {other:?}"),
    }
    // A name the vehicle does not have is an input error (exit 2 on the command line).
    match r.client.param_get("NO_SUCH_PARAM").await {
        Err(ClientError::Usage(reason)) => {
            assert!(reason.contains("NO_SUCH_PARAM"), "{reason}")
        }
        other => panic!("expected an input error, got {other:?}"),
    }
    // An integer parameter confirms with the vehicle's rounding.
    assert_eq!(r.client.param_set("SIM_PUSH_MS", 250.4).await, Ok(250.0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn thirty_percent_loss_each_way() {
    let r = rig(0.3, 7, 1.0).await;
    let start = Instant::now();
    push_scenarios(&r).await;
    eprintln!("push scenarios at 30 % loss: {:?}", start.elapsed());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn commands_carry_the_vehicle_reason() {
    // At 1 % of real time the twin's 1 s gyro calibration lasts 100 s: arming is refused.
    let r = rig(0.0, 1, 0.01).await;
    match r.client.arm(false).await {
        Err(ClientError::Refused { reason }) => {
            assert!(
                reason.contains("PreArm") && reason.contains("calibration"),
                "{reason}"
            );
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    match r.client.set_mode("NOT_A_MODE").await {
        Err(ClientError::Usage(_)) => {}
        other => panic!("expected a usage error, got {other:?}"),
    }
    r.client.set_mode("QHOVER").await.expect("mode accepted");
    // Forced past the checks.
    r.client.arm(true).await.expect("force arm");
    r.client.disarm(true).await.expect("force disarm");
}

/// A rollback the vehicle refuses: the client is told a stale value (LAT_SAT_D 0.3, which the
/// twin would never accept beside c = 0.22), so restoring it fails and the report says what the
/// vehicle now holds, read back from it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rollback_the_vehicle_refuses_is_reported_with_what_it_holds() {
    let r = rig(0.0, 1, 1.0).await;
    let c = &r.client;
    let mut stale = c.params_pull(None).await.expect("pull");
    stale.get_mut("LAT_SAT_D").expect("in the table").value = 0.3;
    let want = wanted(&[("LAT_SAT_D", 0.15), ("LAT_SAT_B", 2.0)]);
    let report = c
        .push_onto(&stale, &want, &vtol_gcs::params::TwinRules, None)
        .await
        .expect("push runs");
    assert!(
        matches!(report.result, PushResult::RollbackIncomplete { .. }),
        "{report:?}"
    );
    match &report.outcomes["LAT_SAT_D"] {
        ParamOutcome::RollbackFailed { old, holds, .. } => {
            assert_eq!(*old, 0.3);
            assert_eq!(*holds, Some(0.15), "what the vehicle holds, read back");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(c.param_get("LAT_SAT_D").await.expect("read").value, 0.15);
}

/// Frames from (255, 190) seen on a raw TCP client of the daemon within `window`.
async fn own_heartbeats(sock: &mut tokio::net::TcpStream, window: Duration) -> usize {
    use tokio::io::AsyncReadExt;
    let mut dec = vtol_link::FrameDecoder::new();
    let mut buf = [0u8; 8192];
    let end = tokio::time::Instant::now() + window;
    let mut n = 0;
    while let Ok(Ok(len)) = tokio::time::timeout_at(end, sock.read(&mut buf)).await {
        assert!(len > 0, "daemon closed the connection");
        dec.push(&buf[..len]);
        n += dec
            .frames()
            .filter(|f| (f.system_id(), f.component_id()) == (255, 190) && f.message_id() == 0)
            .count();
        if n > 0 {
            break;
        }
    }
    n
}

/// The daemon's own client sends its heartbeat only while an operator guard lives.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_heartbeat_flows_only_while_an_operator_is_present() {
    let cancel = CancellationToken::new();
    let config = vtol_gcs::config::Config {
        serve: vec!["tcpin:127.0.0.1:0".parse().expect("url")],
        log_dir: None,
        ..vtol_gcs::config::Config::default()
    };
    let mut tasks = tokio::task::JoinSet::new();
    let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks)
        .await
        .expect("daemon starts");
    let addr = running.serving[0].1.expect("bound");
    let mut sock = tokio::net::TcpStream::connect(addr).await.expect("connect");
    // No operator: a window longer than the 1 Hz period holds no heartbeat of the daemon's.
    assert_eq!(
        own_heartbeats(&mut sock, Duration::from_millis(2500)).await,
        0
    );
    let guard = running.client.operator_present();
    assert!(
        own_heartbeats(&mut sock, Duration::from_secs(5)).await > 0,
        "no heartbeat while an operator is present"
    );
    drop(guard);
    // Allow the one heartbeat that may already be on its way, then none.
    let _ = own_heartbeats(&mut sock, Duration::from_millis(300)).await;
    assert_eq!(
        own_heartbeats(&mut sock, Duration::from_millis(2500)).await,
        0
    );
    // The daemon's client finds the embedded twin and reads a parameter through the router.
    let p = running.client.param_get("HOVER_ALT").await.expect("read");
    assert_eq!(p.value, 1.0);
    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}
