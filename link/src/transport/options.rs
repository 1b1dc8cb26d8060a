//! Tuning for links, the Zenoh options among them.

use super::EgressFilter;
use std::fmt;
use std::time::Duration;

/// Tuning for links. `Default` gives the values documented on each field.
#[derive(Debug, Clone)]
pub struct LinkOptions {
    /// Egress queue length per link, in frames (default 1024).
    pub queue_len: usize,
    /// A UDP peer that sends nothing for this long goes down (default 10 s).
    pub udp_peer_timeout: Duration,
    /// A `udpin` endpoint whose peers are vehicles (default false): a new peer address that
    /// sends as a system id another peer of the endpoint sent as is that vehicle come back
    /// (a restarted process, a radio bridge, a new NAT mapping): the old peer's link goes
    /// down and the new address is followed at once, as mavlink-router's UDP server follows
    /// its last sender. Off for clients, where scripts share system id 255.
    pub udp_follow_system: bool,
    /// First reconnect delay for TCP clients and serial ports (default 100 ms).
    pub reconnect_min: Duration,
    /// Cap of the doubling reconnect delay (default 2 s).
    pub reconnect_max: Duration,
    /// Open a serial endpoint whose device does not exist yet and wait for it to appear
    /// (default false: a missing device at start is an error, most likely a typo).
    pub wait_for_device: bool,
    /// Which frames the links take (default: all). For an in-process consumer that reads only
    /// a few message types: the others are never copied to it.
    pub accept: Option<EgressFilter>,
    /// The Zenoh session and this end's role, for `zenoh:` URLs.
    pub zenoh: ZenohOptions,
}

/// How a `zenoh:` endpoint joins the Zenoh network, and which end of the fleet it is.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct ZenohOptions {
    /// Peer (default), client of a router, or a router itself.
    pub mode: ZenohMode,
    /// Endpoints to connect to, e.g. `tcp/127.0.0.1:7447`.
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Which end of the fleet a `zenoh:` URL opens here.
    pub role: ZenohRole,
}

/// Zenoh's session modes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ZenohMode {
    /// Talks to peers directly, and to routers.
    #[default]
    Peer,
    /// Talks through one router.
    Client,
    /// Routes for clients and peers (what `zenohd` does).
    Router,
}

impl std::str::FromStr for ZenohMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "peer" => Ok(ZenohMode::Peer),
            "client" => Ok(ZenohMode::Client),
            "router" => Ok(ZenohMode::Router),
            other => Err(format!(
                "unknown Zenoh mode '{other}'; expected peer, client or router"
            )),
        }
    }
}

impl fmt::Display for ZenohMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        })
    }
}

/// Which end of a fleet a `zenoh:` URL opens.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ZenohRole {
    /// The ground end (a daemon's vehicle side): each vehicle of the fleet is a link, its
    /// frames read from `from_vehicle`, its egress published on `to_vehicle`.
    #[default]
    Ground,
    /// The vehicle's end (a daemon's serve side): one link whose egress, what the vehicle
    /// sends, is published on `from_vehicle`, and whose ingress is `to_vehicle`.
    Vehicle,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            queue_len: 1024,
            udp_peer_timeout: Duration::from_secs(10),
            udp_follow_system: false,
            reconnect_min: Duration::from_millis(100),
            reconnect_max: Duration::from_secs(2),
            wait_for_device: false,
            accept: None,
            zenoh: ZenohOptions::default(),
        }
    }
}
