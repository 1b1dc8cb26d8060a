//! Link addresses in pymavlink's words (DESIGN.md §4, PROTOCOL.md C.1).
//!
//! `udpin:HOST:PORT` (alias `udp:`), `udpout:HOST:PORT`, `tcpin:HOST:PORT`,
//! `tcp:HOST:PORT` (alias `tcpout:`), `serial:DEVICE[:BAUD]`, and pymavlink's bare device form
//! `/dev/ttyX[,BAUD]`. Hosts are names or IPs (IPv6 in brackets); names resolve when the link
//! starts. Port 0 asks for an ephemeral port (tests).

use std::fmt;
use std::str::FromStr;

/// Default serial speed (ArduPilot's SERIAL0 default).
pub const DEFAULT_BAUD: u32 = 115_200;

/// Where and how to open a link.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum LinkUrl {
    /// Bind a UDP socket and listen; every peer heard recently is its own link.
    UdpIn {
        /// Local address to bind (name or IP).
        host: String,
        /// Local port (0 = ephemeral).
        port: u16,
    },
    /// Send UDP to a fixed destination from an ephemeral port; replies come back there.
    UdpOut {
        /// Destination host.
        host: String,
        /// Destination port.
        port: u16,
    },
    /// TCP listener; every accepted client is its own link.
    TcpIn {
        /// Local address to bind.
        host: String,
        /// Local port (0 = ephemeral).
        port: u16,
    },
    /// TCP client that reconnects with back-off.
    Tcp {
        /// Server host.
        host: String,
        /// Server port.
        port: u16,
    },
    /// Serial device, 8N1, no flow control.
    Serial {
        /// Device path (`/dev/ttyUSB0`, `COM3`).
        device: String,
        /// Line speed in baud.
        baud: u32,
    },
    /// A fleet over Zenoh: `zenoh:FLEET/VEHICLE` is one vehicle, `zenoh:FLEET/*` every vehicle
    /// of the fleet (each its own link). Frames travel on `vtol/FLEET/VEHICLE/from_vehicle` and
    /// `vtol/FLEET/VEHICLE/to_vehicle`; a liveliness token on `vtol/FLEET/VEHICLE` says the
    /// vehicle's daemon is up.
    Zenoh {
        /// The fleet's name (one key chunk).
        fleet: String,
        /// One vehicle's name, or `None` for every vehicle (`*`).
        vehicle: Option<String>,
    },
}

/// Why a link URL did not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UrlError {
    /// No `scheme:` prefix and not a device path.
    #[error(
        "link URL '{0}' has no scheme; expected udpin:HOST:PORT, udpout:HOST:PORT, tcpin:HOST:PORT, tcp:HOST:PORT, serial:DEVICE[:BAUD] or zenoh:FLEET/VEHICLE"
    )]
    MissingScheme(String),
    /// A scheme this crate does not know.
    #[error(
        "unknown link scheme '{scheme}' in '{url}'; expected udpin, udp, udpout, tcpin, tcp, tcpout, serial or zenoh"
    )]
    UnknownScheme {
        /// The scheme given.
        scheme: String,
        /// The whole URL.
        url: String,
    },
    /// `HOST:PORT` missing or malformed.
    #[error("link URL '{url}': {reason}")]
    BadAddress {
        /// The whole URL.
        url: String,
        /// What is wrong.
        reason: String,
    },
    /// A serial URL without a device or with a bad baud rate.
    #[error("link URL '{url}': {reason}")]
    BadSerial {
        /// The whole URL.
        url: String,
        /// What is wrong.
        reason: String,
    },
    /// A Zenoh URL that is not `zenoh:FLEET/VEHICLE` or `zenoh:FLEET/*`.
    #[error("link URL '{url}': {reason}")]
    BadZenoh {
        /// The whole URL.
        url: String,
        /// What is wrong.
        reason: String,
    },
}

/// Checks one name of a Zenoh URL: a non-empty key chunk of letters, digits, `-`, `_` and `.`
/// (no `/`, no wildcard, nothing Zenoh reserves).
fn check_zenoh_name(url: &str, what: &str, name: &str) -> Result<(), UrlError> {
    let bad = |reason: String| UrlError::BadZenoh {
        url: url.to_string(),
        reason,
    };
    if name.is_empty() {
        return Err(bad(format!(
            "the {what} name is empty; expected zenoh:FLEET/VEHICLE or zenoh:FLEET/*"
        )));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(bad(format!(
            "the {what} name '{name}' has '{c}'; names are letters, digits, '-', '_' and '.'"
        )));
    }
    Ok(())
}

fn parse_zenoh(url: &str, rest: &str) -> Result<LinkUrl, UrlError> {
    let (fleet, vehicle) = rest.split_once('/').ok_or_else(|| UrlError::BadZenoh {
        url: url.to_string(),
        reason: "expected zenoh:FLEET/VEHICLE or zenoh:FLEET/*".into(),
    })?;
    check_zenoh_name(url, "fleet", fleet)?;
    let vehicle = if vehicle == "*" {
        None
    } else {
        check_zenoh_name(url, "vehicle", vehicle)?;
        Some(vehicle.to_string())
    };
    Ok(LinkUrl::Zenoh {
        fleet: fleet.to_string(),
        vehicle,
    })
}

fn parse_host_port(url: &str, rest: &str) -> Result<(String, u16), UrlError> {
    let bad = |reason: String| UrlError::BadAddress {
        url: url.to_string(),
        reason,
    };
    let (host, port) = if let Some(after) = rest.strip_prefix('[') {
        let (host, tail) = after
            .split_once(']')
            .ok_or_else(|| bad("unclosed '[' in IPv6 address".into()))?;
        let port = tail
            .strip_prefix(':')
            .ok_or_else(|| bad("expected HOST:PORT, the port is missing".into()))?;
        (host, port)
    } else {
        let (host, port) = rest
            .rsplit_once(':')
            .ok_or_else(|| bad("expected HOST:PORT, the port is missing".into()))?;
        if host.contains(':') {
            return Err(bad(format!(
                "IPv6 address '{host}' must be written in brackets, e.g. [::1]:{port}"
            )));
        }
        (host, port)
    };
    if host.is_empty() {
        return Err(bad(
            "expected HOST:PORT, the host is empty (use 127.0.0.1 or 0.0.0.0)".into(),
        ));
    }
    if host.contains(['[', ']']) {
        return Err(bad(format!(
            "host '{host}' has a stray bracket: only an IPv6 address is written in brackets, \
             e.g. [::1]:{port}"
        )));
    }
    let port = port
        .parse::<u16>()
        .map_err(|_| bad(format!("port '{port}' is not a number from 0 to 65535")))?;
    Ok((host.to_string(), port))
}

fn parse_serial(url: &str, rest: &str, sep: char) -> Result<LinkUrl, UrlError> {
    let bad = |reason: String| UrlError::BadSerial {
        url: url.to_string(),
        reason,
    };
    let (device, baud) = match rest.rsplit_once(sep) {
        Some((dev, b)) if !b.is_empty() && b.bytes().all(|c| c.is_ascii_digit()) => {
            let baud = b
                .parse::<u32>()
                .map_err(|_| bad(format!("baud rate '{b}' is too large")))?;
            (dev, baud)
        }
        Some((_, b))
            if !b.is_empty() && b.bytes().all(|c| c.is_ascii_alphanumeric()) && sep == ',' =>
        {
            return Err(bad(format!("baud rate '{b}' is not a number")));
        }
        _ => (rest, DEFAULT_BAUD),
    };
    if device.is_empty() {
        return Err(bad("the serial device is missing".into()));
    }
    if baud == 0 {
        return Err(bad("baud rate must be positive".into()));
    }
    Ok(LinkUrl::Serial {
        device: device.to_string(),
        baud,
    })
}

impl FromStr for LinkUrl {
    type Err = UrlError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        // pymavlink accepts a bare device path, with ",BAUD".
        if s.starts_with('/') {
            return parse_serial(s, s, ',');
        }
        let (scheme, rest) = s
            .split_once(':')
            .ok_or_else(|| UrlError::MissingScheme(s.to_string()))?;
        let hp = || parse_host_port(s, rest);
        Ok(match scheme.to_ascii_lowercase().as_str() {
            "udpin" | "udp" => {
                let (host, port) = hp()?;
                LinkUrl::UdpIn { host, port }
            }
            "udpout" => {
                let (host, port) = hp()?;
                LinkUrl::UdpOut { host, port }
            }
            "tcpin" => {
                let (host, port) = hp()?;
                LinkUrl::TcpIn { host, port }
            }
            "tcp" | "tcpout" => {
                let (host, port) = hp()?;
                LinkUrl::Tcp { host, port }
            }
            "serial" => parse_serial(s, rest, ':')?,
            "zenoh" => parse_zenoh(s, rest)?,
            _ if rest.bytes().all(|c| c.is_ascii_digit()) && !rest.is_empty() => {
                // "127.0.0.1:14550": pymavlink would take it as udpin; be explicit instead.
                return Err(UrlError::MissingScheme(s.to_string()));
            }
            other => {
                return Err(UrlError::UnknownScheme {
                    scheme: other.to_string(),
                    url: s.to_string(),
                });
            }
        })
    }
}

struct HostPort<'a>(&'a str, u16);

impl fmt::Display for HostPort<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.contains(':') {
            write!(f, "[{}]:{}", self.0, self.1)
        } else {
            write!(f, "{}:{}", self.0, self.1)
        }
    }
}

impl fmt::Display for LinkUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkUrl::UdpIn { host, port } => write!(f, "udpin:{}", HostPort(host, *port)),
            LinkUrl::UdpOut { host, port } => write!(f, "udpout:{}", HostPort(host, *port)),
            LinkUrl::TcpIn { host, port } => write!(f, "tcpin:{}", HostPort(host, *port)),
            LinkUrl::Tcp { host, port } => write!(f, "tcp:{}", HostPort(host, *port)),
            LinkUrl::Serial { device, baud } => write!(f, "serial:{device}:{baud}"),
            LinkUrl::Zenoh { fleet, vehicle } => {
                write!(f, "zenoh:{fleet}/{}", vehicle.as_deref().unwrap_or("*"))
            }
        }
    }
}

impl LinkUrl {
    /// Host and port of the network variants.
    pub fn host_port(&self) -> Option<(&str, u16)> {
        match self {
            LinkUrl::UdpIn { host, port }
            | LinkUrl::UdpOut { host, port }
            | LinkUrl::TcpIn { host, port }
            | LinkUrl::Tcp { host, port } => Some((host, *port)),
            LinkUrl::Serial { .. } | LinkUrl::Zenoh { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> LinkUrl {
        s.parse().unwrap_or_else(|e| panic!("{s}: {e}"))
    }

    #[test]
    fn zenoh_urls_name_a_fleet_and_one_vehicle_or_all() {
        assert_eq!(
            p("zenoh:test/v1"),
            LinkUrl::Zenoh {
                fleet: "test".into(),
                vehicle: Some("v1".into())
            }
        );
        assert_eq!(
            p("zenoh:survey-2.a/*"),
            LinkUrl::Zenoh {
                fleet: "survey-2.a".into(),
                vehicle: None
            }
        );
        for s in ["zenoh:test/v1", "zenoh:test/*"] {
            assert_eq!(p(s).to_string(), s);
        }
        for bad in [
            "zenoh:test",
            "zenoh:/v1",
            "zenoh:test/",
            "zenoh:*/v1",
            "zenoh:test/v1/x",
            "zenoh:te st/v1",
            "zenoh:test/v*",
            "zenoh:test/$*",
        ] {
            let e = bad.parse::<LinkUrl>().unwrap_err();
            assert!(matches!(e, UrlError::BadZenoh { .. }), "{bad}: {e}");
        }
    }

    #[test]
    fn parses_every_word() {
        let h = |s: &str| s.to_string();
        assert_eq!(
            p("udpin:0.0.0.0:14550"),
            LinkUrl::UdpIn {
                host: h("0.0.0.0"),
                port: 14550
            }
        );
        assert_eq!(
            p("udp:127.0.0.1:0"),
            LinkUrl::UdpIn {
                host: h("127.0.0.1"),
                port: 0
            }
        );
        assert_eq!(
            p("udpout:localhost:14550"),
            LinkUrl::UdpOut {
                host: h("localhost"),
                port: 14550
            }
        );
        assert_eq!(
            p("tcpin:127.0.0.1:5760"),
            LinkUrl::TcpIn {
                host: h("127.0.0.1"),
                port: 5760
            }
        );
        assert_eq!(
            p("tcp:127.0.0.1:5760"),
            LinkUrl::Tcp {
                host: h("127.0.0.1"),
                port: 5760
            }
        );
        assert_eq!(
            p("tcpout:[::1]:5760"),
            LinkUrl::Tcp {
                host: h("::1"),
                port: 5760
            }
        );
        assert_eq!(
            p("serial:/dev/ttyUSB0:57600"),
            LinkUrl::Serial {
                device: h("/dev/ttyUSB0"),
                baud: 57600
            }
        );
        assert_eq!(
            p("serial:/dev/pts/3"),
            LinkUrl::Serial {
                device: h("/dev/pts/3"),
                baud: DEFAULT_BAUD
            }
        );
        assert_eq!(
            p("/dev/ttyACM0,921600"),
            LinkUrl::Serial {
                device: h("/dev/ttyACM0"),
                baud: 921600
            }
        );
        assert_eq!(
            p("serial:COM3"),
            LinkUrl::Serial {
                device: h("COM3"),
                baud: DEFAULT_BAUD
            }
        );
    }

    #[test]
    fn display_round_trips() {
        for s in [
            "udpin:0.0.0.0:14550",
            "udpout:localhost:14550",
            "tcpin:127.0.0.1:5760",
            "tcp:[::1]:5760",
            "serial:/dev/ttyUSB0:57600",
        ] {
            assert_eq!(p(s).to_string(), s);
            assert_eq!(p(&p(s).to_string()), p(s));
        }
        assert_eq!(p("udp:1.2.3.4:5").to_string(), "udpin:1.2.3.4:5");
        assert_eq!(p("tcpout:h:5").to_string(), "tcp:h:5");
    }

    #[test]
    fn clear_errors() {
        let e = |s: &str| s.parse::<LinkUrl>().unwrap_err().to_string();
        assert!(e("14550").contains("no scheme"), "{}", e("14550"));
        assert!(e("127.0.0.1:14550").contains("no scheme"));
        assert!(e("http:foo:1").contains("unknown link scheme 'http'"));
        assert!(e("udpin:14550").contains("port is missing"));
        assert!(e("udpin::14550").contains("host is empty"));
        assert!(e("tcp:host:99999").contains("port '99999'"));
        assert!(e("tcp:::1:5760").contains("brackets"));
        assert!(e("tcp:[::1:5760").contains("unclosed"));
        assert!(e("tcpin:[[1.1]:0").contains("stray bracket"));
        assert!(e("udpin:a]b:1").contains("stray bracket"));
        assert!(e("serial:").contains("device is missing"));
        assert!(e("serial:/dev/x:0").contains("positive"));
        assert!(e("/dev/ttyS0,fast").contains("not a number"));
    }
}
