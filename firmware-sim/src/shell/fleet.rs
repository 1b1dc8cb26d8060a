//! A fleet of twins in one process: `firmware-sim serve --count N`.
//!
//! # Contract
//!
//! - N twins run side by side, each its own [`Twin`] (its own vehicle loop, state, parameters,
//!   mission, clock and signing state), with system ids `first..first+N-1` (`first` is
//!   `--sysid`, default 1).
//! - They share **one set of endpoints** (the `--listen` URLs): a ground station connected to
//!   the fleet's URL hears every twin's frames on that one link, as it would hear several
//!   vehicles behind one radio. A frame that targets a system id goes only to the twin with
//!   that id (a frame targeting an id no twin has is dropped); a frame without a target, or
//!   with target system 0 (broadcast), reaches every twin. Each twin's endpoint still applies
//!   its own target rules.
//! - Files are named per twin beside the ones given: with `--param-file DIR/NAME.EXT`, twin
//!   `S` keeps its parameters in `DIR/NAME-sysS.EXT`, and so its mission in
//!   `DIR/NAME-sysS.waypoints` and its signing state in `DIR/NAME-sysS.signing`; `--tlog`
//!   is split the same way ([`member_file`]). With `--count 1` nothing is renamed.
//! - Twin `S` draws its noise from seed `--seed + (S - first)`, so the vehicles differ.
//! - With more than one twin, `--control` (and so `--lockstep`) is refused: the harness channel
//!   speaks for one vehicle.
//!
//! The fan-out is a task of its own between the transports and the twins' event queues: the
//! twins and the endpoint state machine are unchanged.

use std::path::{Path, PathBuf};

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use vtol_link::{EndpointHandle, LinkEvent};

use crate::shell::serve::{Bound, Listeners, ServeConfig, ServeError, Twin, open_listeners};

/// Capacity of the transports → fan-out queue.
const FAN_OUT_QUEUE: usize = 4096;

/// Why a fleet could not start.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// One twin (or a shared endpoint) could not start.
    #[error(transparent)]
    Serve(#[from] ServeError),
    /// Zero twins asked for.
    #[error("--count must be at least 1")]
    Empty,
    /// The system ids would pass 255.
    #[error("--count {count} from system id {first} passes 255")]
    SysidRange {
        /// The first system id.
        first: u8,
        /// How many twins.
        count: u16,
    },
    /// `--control` with more than one twin.
    #[error("--control (and --lockstep) take one twin; drop --count or set it to 1")]
    Control,
}

/// The file twin `sysid` uses in place of `path`: `DIR/NAME.EXT` → `DIR/NAME-sysS.EXT`
/// (`DIR/NAME` → `DIR/NAME-sysS` without an extension).
#[must_use]
pub fn member_file(path: &Path, sysid: u8) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(ext) => format!("{stem}-sys{sysid}.{}", ext.to_string_lossy()),
        None => format!("{stem}-sys{sysid}"),
    };
    path.with_file_name(name)
}

/// A running fleet.
#[derive(Debug)]
pub struct Fleet {
    twins: Vec<Twin>,
    bound: Vec<Bound>,
    endpoints: Vec<EndpointHandle>,
    fan_out: Option<JoinHandle<()>>,
}

impl Fleet {
    /// Starts `count` twins from `config` (each with its parameter file loaded) and opens the
    /// shared endpoints. With `count == 1` this is exactly [`Twin::start`] (files not renamed).
    ///
    /// # Errors
    /// [`FleetError`]; a failure cancels `cancel`, stopping what had started.
    pub async fn start(
        config: ServeConfig,
        count: u16,
        cancel: CancellationToken,
    ) -> Result<Self, FleetError> {
        let first = config.endpoint.sysid.unwrap_or(1);
        if count == 0 {
            return Err(FleetError::Empty);
        }
        if u16::from(first) + count - 1 > 255 {
            return Err(FleetError::SysidRange { first, count });
        }
        if count == 1 {
            let mut config = config;
            config.load_param_file()?;
            let twin = Twin::start(config, cancel).await?;
            let bound = twin.bound().to_vec();
            return Ok(Self {
                twins: vec![twin],
                bound,
                endpoints: Vec::new(),
                fan_out: None,
            });
        }
        if config.control.is_some() {
            return Err(FleetError::Control);
        }
        match Self::start_many(config, first, count, cancel.clone()).await {
            Ok(f) => Ok(f),
            Err(e) => {
                cancel.cancel();
                Err(e)
            }
        }
    }

    async fn start_many(
        config: ServeConfig,
        first: u8,
        count: u16,
        cancel: CancellationToken,
    ) -> Result<Self, FleetError> {
        // The shared endpoints first, so each twin knows which of their links are local.
        let (events, rx) = mpsc::channel(FAN_OUT_QUEUE);
        let Listeners {
            bound,
            endpoints,
            local_links,
        } = open_listeners(&config.listen, &events, &config.link_options, &cancel)
            .await
            .map_err(ServeError::from)?;
        let mut twins = Vec::with_capacity(usize::from(count));
        let mut queues = Vec::with_capacity(usize::from(count));
        for i in 0..count {
            // In range: checked by the caller.
            let sysid = u8::try_from(u16::from(first) + i).unwrap_or(u8::MAX);
            let mut c = config.clone();
            c.listen = Vec::new();
            c.endpoint.sysid = Some(sysid);
            c.endpoint.vehicle.seed = config.endpoint.vehicle.seed.wrapping_add(u64::from(i));
            c.impairment.seed = config.impairment.seed.wrapping_add(u64::from(i));
            c.endpoint.param_file = config
                .endpoint
                .param_file
                .as_deref()
                .map(|p| member_file(p, sysid));
            c.tlog = config.tlog.as_deref().map(|p| member_file(p, sysid));
            c.load_param_file()?;
            let twin = Twin::start_member(c, cancel.clone(), local_links.clone()).await?;
            queues.push((sysid, twin.events()));
            twins.push(twin);
        }
        drop(events);
        let fan_out = tokio::spawn(fan_out(rx, queues, cancel));
        Ok(Self {
            twins,
            bound,
            endpoints,
            fan_out: Some(fan_out),
        })
    }

    /// The opened endpoints, in `listen` order (shared by every twin).
    #[must_use]
    pub fn bound(&self) -> &[Bound] {
        &self.bound
    }

    /// The twins, in system id order.
    #[must_use]
    pub fn twins(&self) -> &[Twin] {
        &self.twins
    }

    /// The control listener's URL (a fleet of one only).
    #[must_use]
    pub fn control_url(&self) -> Option<String> {
        match self.twins.as_slice() {
            [t] => t.control_url(),
            _ => None,
        }
    }

    /// Waits for every twin, the fan-out and the shared endpoints to stop (after `cancel`).
    pub async fn join(self) {
        for e in self.endpoints {
            e.join().await;
        }
        if let Some(f) = self.fan_out {
            let _ = f.await;
        }
        for t in self.twins {
            t.join().await;
        }
    }
}

/// Hands every transport event to the twins: link ups and downs to all, frames by target.
async fn fan_out(
    mut rx: mpsc::Receiver<LinkEvent>,
    twins: Vec<(u8, mpsc::Sender<LinkEvent>)>,
    cancel: CancellationToken,
) {
    loop {
        let ev = tokio::select! {
            () = cancel.cancelled() => return,
            ev = rx.recv() => match ev {
                Some(ev) => ev,
                None => return,
            },
        };
        match ev {
            LinkEvent::Up { id, peer, tx } => {
                for (_, q) in &twins {
                    let ev = LinkEvent::Up {
                        id,
                        peer: peer.clone(),
                        tx: tx.clone(),
                    };
                    let _ = q.send(ev).await;
                }
            }
            LinkEvent::Frame { id, frame } => match frame.target() {
                Some((sys, _)) if sys != 0 => {
                    if let Some((_, q)) = twins.iter().find(|(s, _)| *s == sys) {
                        let _ = q.send(LinkEvent::Frame { id, frame }).await;
                    }
                }
                _ => {
                    for (_, q) in &twins {
                        let ev = LinkEvent::Frame {
                            id,
                            frame: frame.clone(),
                        };
                        let _ = q.send(ev).await;
                    }
                }
            },
            LinkEvent::Down { id, reason } => {
                for (_, q) in &twins {
                    let ev = LinkEvent::Down {
                        id,
                        reason: reason.clone(),
                    };
                    let _ = q.send(ev).await;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn member_files_keep_directory_and_extension() {
        assert_eq!(
            member_file(Path::new("/tmp/a/fleet.parm"), 3),
            PathBuf::from("/tmp/a/fleet-sys3.parm")
        );
        assert_eq!(
            member_file(Path::new("fleet"), 12),
            PathBuf::from("fleet-sys12")
        );
        assert_eq!(
            crate::nav::mission::file_beside(&member_file(Path::new("d/p.parm"), 2)),
            PathBuf::from("d/p-sys2.waypoints")
        );
    }
}
