//! Daemon configuration: a TOML file (see `config/vtol-gcs.toml`) overridden by command-line
//! flags. A broken file is a clear error naming the file and the problem, never a silent default.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use vtol_link::{LinkOptions, SigningKey};

use crate::log::replay::{ReplaySource, ReplayUrlError};
use crate::trust::policy::ServeSpec;

/// Default client endpoints: a TCP server for scripts and MAVProxy (clear of the twin's 5760 and
/// SITL's 5760/5762/5763), and a UDP stream to a ground station listening on 14550 (QGC).
pub const DEFAULT_SERVE: [&str; 2] = ["tcpin:127.0.0.1:5770", "udpout:127.0.0.1:14550"];

/// Where the vehicle is.
#[derive(Debug, Clone, PartialEq)]
pub enum VehicleSource {
    /// The twin, running inside the daemon on an in-memory byte link.
    Embedded,
    /// A real vehicle or a standalone twin at this URL.
    Url(vtol_link::LinkUrl),
    /// A tlog played back as the vehicle (`replay:FILE[?speed=N]`).
    Replay(ReplaySource),
}

/// A `--vehicle` value that is neither `embedded`, a link URL nor a replay.
#[derive(Debug, thiserror::Error)]
pub enum VehicleSourceError {
    /// A bad link URL.
    #[error(transparent)]
    Url(#[from] vtol_link::UrlError),
    /// A bad `replay:` URL.
    #[error(transparent)]
    Replay(#[from] ReplayUrlError),
}

impl std::str::FromStr for VehicleSource {
    type Err = VehicleSourceError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "embedded" {
            Ok(Self::Embedded)
        } else if let Some(rest) = s.strip_prefix("replay:") {
            Ok(Self::Replay(ReplaySource::parse(rest)?))
        } else {
            Ok(Self::Url(s.parse()?))
        }
    }
}

impl std::fmt::Display for VehicleSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Embedded => f.write_str("embedded twin"),
            Self::Url(u) => write!(f, "{u}"),
            Self::Replay(r) => write!(f, "{r}"),
        }
    }
}

/// The daemon's settings after merging file and flags.
#[derive(Debug, Clone)]
pub struct Config {
    /// The vehicle link.
    pub vehicle: VehicleSource,
    /// Client endpoints, each with its policy (trust, rate limit).
    pub serve: Vec<ServeSpec>,
    /// Where tlogs go; `None` disables logging.
    pub log_dir: Option<PathBuf>,
    /// Status lines instead of the terminal UI.
    pub headless: bool,
    /// The daemon's own system id (255: vehicles accept RC overrides and run the GCS failsafe).
    pub system_id: u8,
    /// The daemon's component id (190, MISSIONPLANNER).
    pub component_id: u8,
    /// Link tuning.
    pub link: LinkOptions,
    /// Seconds between status lines.
    pub status_interval: Duration,
    /// How often the vehicle tracker takes the routed frames and publishes its state: the
    /// terminal UI's frame rate ([`crate::tracker::UI_PERIOD`]); the headless daemon sets
    /// [`crate::tracker::HEADLESS_PERIOD`].
    pub tracker_period: Duration,
    /// Download the vehicle's parameters when it is first heard and after each reboot
    /// ([`crate::reboot`]).
    pub fetch_params: bool,
    /// MAVLink 2 signing key: the daemon signs its own traffic and `sign` clients' frames and
    /// verifies the vehicle's.
    pub signing: Option<SigningKey>,
    /// Where the signing timestamp is kept; `None`: the default state file
    /// ([`crate::trust::signing::default_state_file`]).
    pub signing_state: Option<PathBuf>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            vehicle: VehicleSource::Embedded,
            serve: DEFAULT_SERVE
                .iter()
                .map(|s| s.parse().expect("valid default URL"))
                .collect(),
            log_dir: Some(PathBuf::from("logs")),
            headless: false,
            system_id: 255,
            component_id: 190,
            link: LinkOptions::default(),
            status_interval: Duration::from_secs(1),
            tracker_period: crate::tracker::UI_PERIOD,
            fetch_params: false,
            signing: None,
            signing_state: None,
        }
    }
}

/// The file's shape. Every key is optional; unknown keys are errors (typos must not pass).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileConfig {
    /// `"embedded"` or a link URL.
    pub vehicle: Option<String>,
    /// Client endpoint URLs.
    pub serve: Option<Vec<String>>,
    /// Log directory; `""` disables logging.
    pub log_dir: Option<String>,
    /// Status lines instead of the UI.
    pub headless: Option<bool>,
    /// Own system id.
    pub system_id: Option<u8>,
    /// Own component id.
    pub component_id: Option<u8>,
    /// Egress queue length per link, frames.
    pub queue_len: Option<usize>,
    /// Seconds of silence before a UDP client is dropped.
    pub udp_peer_timeout_s: Option<f64>,
    /// Seconds between status lines.
    pub status_interval_s: Option<f64>,
    /// Wait for a serial vehicle device that does not exist yet instead of failing at start.
    pub wait_for_device: Option<bool>,
    /// Download the vehicle's parameters when it is first heard and after each reboot.
    pub fetch_params: Option<bool>,
    /// MAVLink 2 signing key as SHA-256 of this passphrase.
    pub signing_passphrase: Option<Passphrase>,
    /// MAVLink 2 signing key file (64 hex characters).
    pub signing_key_file: Option<String>,
    /// Where the daemon keeps its signing timestamp.
    pub signing_state: Option<String>,
    /// Zenoh session mode for `zenoh:` links: `"peer"` (default), `"client"` or `"router"`.
    pub zenoh_mode: Option<String>,
    /// Zenoh endpoints to connect to, e.g. `["tcp/192.168.1.10:7447"]`.
    pub zenoh_connect: Option<Vec<String>>,
    /// Zenoh endpoints to listen on, e.g. `["tcp/0.0.0.0:7447"]`.
    pub zenoh_listen: Option<Vec<String>>,
}

/// A signing passphrase from the file: its `Debug` shows no text.
#[derive(Clone, Deserialize)]
#[serde(transparent)]
pub struct Passphrase(pub String);

impl std::fmt::Debug for Passphrase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Passphrase(<secret>)")
    }
}

/// A configuration problem.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config {path}: {source}")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML for this schema.
    #[error("invalid config {path}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// What the parser said (with line and column).
        message: String,
    },
    /// A value is out of its domain.
    #[error("invalid config value {key}: {message}")]
    Value {
        /// Key.
        key: &'static str,
        /// Why.
        message: String,
    },
}

impl FileConfig {
    /// Reads and parses a file.
    ///
    /// # Errors
    /// [`ConfigError::Read`] or [`ConfigError::Parse`].
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text).map_err(|message| ConfigError::Parse {
            path: path.to_owned(),
            message,
        })
    }

    /// Parses TOML text.
    ///
    /// # Errors
    /// The parser's message.
    pub fn parse(text: &str) -> Result<Self, String> {
        // The parser's report spans several lines (it draws the line and a caret): keep its
        // message and give the position in words, so the error is one line.
        toml::from_str(text).map_err(|e| {
            let message = e.message().trim_end().replace('\n', "; ");
            match e.span() {
                Some(span) => {
                    let before = &text[..span.start.min(text.len())];
                    let line = before.matches('\n').count() + 1;
                    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                    format!("line {line}, column {column}: {message}")
                }
                None => message,
            }
        })
    }

    /// Applies the file's values over `config`.
    ///
    /// # Errors
    /// [`ConfigError::Value`] for a bad URL or number.
    // Long: one `if let` per key of the file, applied in the order the file documents them.
    pub fn apply(self, config: &mut Config) -> Result<(), ConfigError> {
        if let Some(v) = self.vehicle {
            config.vehicle = v.parse().map_err(|e| ConfigError::Value {
                key: "vehicle",
                message: format!("{e}"),
            })?;
        }
        if let Some(serve) = self.serve {
            config.serve = serve
                .iter()
                .map(|s| s.parse())
                .collect::<Result<_, _>>()
                .map_err(|e| ConfigError::Value {
                    key: "serve",
                    message: format!("{e}"),
                })?;
        }
        if let Some(d) = self.log_dir {
            config.log_dir = if d.is_empty() {
                None
            } else {
                Some(PathBuf::from(d))
            };
        }
        if let Some(h) = self.headless {
            config.headless = h;
        }
        if let Some(s) = self.system_id {
            if s == 0 {
                return Err(ConfigError::Value {
                    key: "system_id",
                    message: "0 is the broadcast id".into(),
                });
            }
            config.system_id = s;
        }
        if let Some(c) = self.component_id {
            config.component_id = c;
        }
        if let Some(q) = self.queue_len {
            if q == 0 {
                return Err(ConfigError::Value {
                    key: "queue_len",
                    message: "must be at least 1".into(),
                });
            }
            config.link.queue_len = q;
        }
        if let Some(t) = self.udp_peer_timeout_s {
            config.link.udp_peer_timeout = positive_secs("udp_peer_timeout_s", t)?;
        }
        if let Some(t) = self.status_interval_s {
            config.status_interval = positive_secs("status_interval_s", t)?;
        }
        if let Some(w) = self.wait_for_device {
            config.link.wait_for_device = w;
        }
        if let Some(f) = self.fetch_params {
            config.fetch_params = f;
        }
        match (self.signing_passphrase, self.signing_key_file) {
            (Some(_), Some(_)) => {
                return Err(ConfigError::Value {
                    key: "signing_passphrase",
                    message: "give signing_passphrase or signing_key_file, not both".into(),
                });
            }
            (Some(text), None) => config.signing = Some(SigningKey::from_passphrase(&text.0)),
            (None, Some(file)) => {
                let key = SigningKey::from_key_file(Path::new(&file)).map_err(|e| {
                    ConfigError::Value {
                        key: "signing_key_file",
                        message: e.to_string(),
                    }
                })?;
                config.signing = Some(key);
            }
            (None, None) => {}
        }
        if let Some(f) = self.signing_state {
            config.signing_state = Some(PathBuf::from(f));
        }
        if let Some(m) = self.zenoh_mode {
            config.link.zenoh.mode = m.parse().map_err(|message| ConfigError::Value {
                key: "zenoh_mode",
                message,
            })?;
        }
        if let Some(c) = self.zenoh_connect {
            config.link.zenoh.connect = zenoh_endpoints("zenoh_connect", c)?;
        }
        if let Some(l) = self.zenoh_listen {
            config.link.zenoh.listen = zenoh_endpoints("zenoh_listen", l)?;
        }
        Ok(())
    }
}

/// Checks Zenoh endpoints: `PROTOCOL/ADDRESS`, e.g. `tcp/127.0.0.1:7447`.
///
/// # Errors
/// [`ConfigError::Value`] naming the first one that is not.
pub fn zenoh_endpoints(key: &'static str, v: Vec<String>) -> Result<Vec<String>, ConfigError> {
    for e in &v {
        check_zenoh_endpoint(e).map_err(|message| ConfigError::Value { key, message })?;
    }
    Ok(v)
}

/// Checks one Zenoh endpoint, `PROTOCOL/ADDRESS` (this build speaks `tcp`).
///
/// # Errors
/// Why it is not one.
pub fn check_zenoh_endpoint(e: &str) -> Result<(), String> {
    match e.split_once('/') {
        Some(("tcp", addr)) if !addr.is_empty() => Ok(()),
        Some((proto, _)) if proto != "tcp" => Err(format!(
            "Zenoh endpoint '{e}': this build speaks tcp only (e.g. tcp/127.0.0.1:7447)"
        )),
        _ => Err(format!(
            "Zenoh endpoint '{e}' is not PROTOCOL/ADDRESS (e.g. tcp/127.0.0.1:7447)"
        )),
    }
}

fn positive_secs(key: &'static str, v: f64) -> Result<Duration, ConfigError> {
    // `try_`: a number of seconds too large for a Duration is an error, not a panic.
    // Not zero either: 1e-12 s rounds to a zero Duration, which a timer cannot tick at.
    if let Some(d) = Duration::try_from_secs_f64(v)
        .ok()
        .filter(|d| v > 0.0 && !d.is_zero())
    {
        Ok(d)
    } else {
        Err(ConfigError::Value {
            key,
            message: format!("must be a positive number of seconds, got {v}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_default_config_parses_and_matches_the_defaults() {
        let text = include_str!("../config/vtol-gcs.toml");
        let mut c = Config::default();
        FileConfig::parse(text).unwrap().apply(&mut c).unwrap();
        let d = Config::default();
        assert_eq!(c.serve, d.serve);
        assert_eq!(c.vehicle, d.vehicle);
        assert_eq!(c.system_id, 255);
    }

    #[test]
    fn broken_files_are_clear_errors() {
        let e = FileConfig::parse("serve = [\"tcpin:127.0.0.1:1\"\n").unwrap_err();
        assert!(e.contains("line"), "{e}");
        let e = FileConfig::parse("srve = []").unwrap_err();
        assert!(e.contains("unknown field"), "{e}");
        let mut c = Config::default();
        let e = FileConfig::parse("serve = [\"bogus:1\"]")
            .unwrap()
            .apply(&mut c)
            .unwrap_err();
        assert!(e.to_string().contains("serve"), "{e}");
        let e = FileConfig::parse("udp_peer_timeout_s = nan")
            .unwrap()
            .apply(&mut c)
            .unwrap_err();
        assert!(e.to_string().contains("udp_peer_timeout_s"), "{e}");
        let e = FileConfig::parse("serve = [\"tcpin:127.0.0.1:0?trust=root\"]")
            .unwrap()
            .apply(&mut c)
            .unwrap_err();
        assert!(e.to_string().contains("unknown trust 'root'"), "{e}");
    }

    #[test]
    fn zenoh_settings_from_the_file() {
        let mut c = Config::default();
        FileConfig::parse(
            "zenoh_mode = \"client\"\nzenoh_connect = [\"tcp/10.0.0.1:7447\"]\n\
             zenoh_listen = [\"tcp/0.0.0.0:7448\"]\n",
        )
        .unwrap()
        .apply(&mut c)
        .unwrap();
        assert_eq!(c.link.zenoh.mode, vtol_link::ZenohMode::Client);
        assert_eq!(c.link.zenoh.connect, vec!["tcp/10.0.0.1:7447".to_string()]);
        assert_eq!(c.link.zenoh.listen, vec!["tcp/0.0.0.0:7448".to_string()]);
        for (text, key) in [
            ("zenoh_mode = \"mesh\"", "zenoh_mode"),
            ("zenoh_connect = [\"127.0.0.1:7447\"]", "zenoh_connect"),
            ("zenoh_listen = [\"udp/0.0.0.0:7447\"]", "zenoh_listen"),
        ] {
            let e = FileConfig::parse(text)
                .unwrap()
                .apply(&mut Config::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains(key), "{e}");
        }
    }

    #[test]
    fn signing_and_policies_from_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let key_file = dir.path().join("k");
        let hex = "ab".repeat(32);
        std::fs::write(&key_file, &hex).unwrap();
        let text = format!(
            "serve = [\"tcpin:127.0.0.1:0?trust=read-only&rate=20\"]\n\
             signing_key_file = \"{}\"\nsigning_state = \"/tmp/s.toml\"\n",
            key_file.display()
        );
        let mut c = Config::default();
        let file = FileConfig::parse(&text).unwrap();
        file.apply(&mut c).unwrap();
        assert_eq!(
            c.serve[0].policy.trust,
            crate::trust::policy::Trust::ReadOnly
        );
        assert_eq!(
            c.signing.as_ref().map(SigningKey::to_hex),
            Some(hex.clone())
        );
        assert_eq!(c.signing_state, Some(PathBuf::from("/tmp/s.toml")));
        assert!(!format!("{c:?}").contains(&hex));

        let both = format!(
            "signing_passphrase = \"p\"\nsigning_key_file = \"{}\"\n",
            key_file.display()
        );
        let e = FileConfig::parse(&both)
            .unwrap()
            .apply(&mut Config::default())
            .unwrap_err();
        assert!(e.to_string().contains("not both"), "{e}");
        let secret = FileConfig::parse("signing_passphrase = \"hunter2\"").unwrap();
        assert!(!format!("{secret:?}").contains("hunter2"));
        std::fs::write(&key_file, "nothex").unwrap();
        let e = FileConfig::parse(&format!("signing_key_file = \"{}\"", key_file.display()))
            .unwrap()
            .apply(&mut Config::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("signing_key_file") && !e.contains("nothex"),
            "{e}"
        );
    }
}
