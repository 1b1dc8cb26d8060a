//! Per-endpoint policy: how far the router trusts a client endpoint and how fast it may be fed.
//!
//! Contract:
//! - A `--serve` URL takes options in its query: `tcpin:127.0.0.1:5770?trust=read-only&rate=20&burst=40`.
//!   [`ServeSpec`] parses it; an unknown key, an unknown trust, a rate that is not a positive
//!   finite number or a burst that is not a whole number ≥ 1 is one [`PolicyError`] naming the URL.
//! - [`Trust::Trusted`] (the default): the client's frames go to the vehicle unchanged; a client
//!   that must be heard by a keyed vehicle signs them itself. [`Trust::Sign`]: the daemon signs
//!   the client's unsigned MAVLink 2 frames with its own key (an explicit choice, and only with a
//!   key: checked at start by the daemon). [`Trust::ReadOnly`]: nothing the client sends is
//!   routed or logged; it still receives what the vehicle sends.
//! - [`RateLimit`]: a token bucket on what the router sends *to* the endpoint's links, `rate`
//!   frames a second with room for `burst` at once (default: one second's worth, at least 1).
//!   A frame without a token is dropped for that link only and counted there.
//! - Every link of an endpoint (each TCP client, each UDP peer) carries the endpoint's policy
//!   and has its own bucket and counters ([`PolicyCounters`]).

use std::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use vtol_link::LinkUrl;

/// How far the router trusts what a client endpoint sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Trust {
    /// Frames go to the vehicle unchanged (the client signs them itself if the vehicle wants).
    #[default]
    Trusted,
    /// Unsigned frames are signed by the daemon with its key.
    Sign,
    /// Nothing from this endpoint is routed; it still receives telemetry.
    ReadOnly,
}

impl Trust {
    /// The word used in URLs and the config file.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Trust::Trusted => "trusted",
            Trust::Sign => "sign",
            Trust::ReadOnly => "read-only",
        }
    }
}

impl fmt::Display for Trust {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A rate limit on what an endpoint's links receive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimit {
    /// Frames per second, sustained.
    pub per_s: f64,
    /// Frames that may go at once after a quiet spell (the bucket's size).
    pub burst: u32,
}

impl RateLimit {
    /// The burst used when none is given: one second's worth, at least 1.
    #[must_use]
    pub fn default_burst(per_s: f64) -> u32 {
        // Saturating float-to-int cast; per_s is positive and finite.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let b = per_s.ceil().min(f64::from(u32::MAX)) as u32;
        b.max(1)
    }
}

/// One endpoint's policy, carried with each of its links.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EndpointPolicy {
    /// Trust.
    pub trust: Trust,
    /// Egress rate limit, if any.
    pub rate: Option<RateLimit>,
}

impl fmt::Display for EndpointPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.trust.as_str())?;
        if let Some(r) = self.rate {
            write!(f, ", {} msg/s burst {}", r.per_s, r.burst)?;
        }
        Ok(())
    }
}

impl EndpointPolicy {
    /// The URL query that gives this policy (`""` for the default), e.g. `?trust=sign&rate=5`.
    #[must_use]
    pub fn query(&self) -> String {
        let mut parts = Vec::new();
        if self.trust != Trust::Trusted {
            parts.push(format!("trust={}", self.trust));
        }
        if let Some(r) = self.rate {
            parts.push(format!("rate={}", r.per_s));
            if r.burst != RateLimit::default_burst(r.per_s) {
                parts.push(format!("burst={}", r.burst));
            }
        }
        if parts.is_empty() {
            String::new()
        } else {
            format!("?{}", parts.join("&"))
        }
    }
}

/// A `--serve` endpoint: where, and with which policy.
#[derive(Debug, Clone, PartialEq)]
pub struct ServeSpec {
    /// The endpoint.
    pub url: LinkUrl,
    /// Its policy.
    pub policy: EndpointPolicy,
}

impl From<LinkUrl> for ServeSpec {
    fn from(url: LinkUrl) -> Self {
        ServeSpec {
            url,
            policy: EndpointPolicy::default(),
        }
    }
}

impl fmt::Display for ServeSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", self.url, self.policy.query())
    }
}

/// Why a `--serve` URL's query is wrong. Names the URL and the option.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PolicyError {
    /// The part before `?` is not a link URL.
    #[error(transparent)]
    Url(#[from] vtol_link::UrlError),
    /// An option this daemon does not know.
    #[error("serve URL '{url}': unknown option '{key}' (expected trust, rate or burst)")]
    UnknownKey {
        /// The whole URL.
        url: String,
        /// The key given.
        key: String,
    },
    /// An option given twice, or without `=VALUE`.
    #[error("serve URL '{url}': {reason}")]
    Malformed {
        /// The whole URL.
        url: String,
        /// What is wrong.
        reason: String,
    },
    /// A trust word this daemon does not know.
    #[error("serve URL '{url}': unknown trust '{value}' (expected trusted, sign or read-only)")]
    UnknownTrust {
        /// The whole URL.
        url: String,
        /// The value given.
        value: String,
    },
    /// A rate that is not a positive finite number of messages a second.
    #[error("serve URL '{url}': rate '{value}' is not a positive number of messages a second")]
    BadRate {
        /// The whole URL.
        url: String,
        /// The value given.
        value: String,
    },
    /// A burst that is not a whole number of at least 1.
    #[error("serve URL '{url}': burst '{value}' is not a whole number of at least 1")]
    BadBurst {
        /// The whole URL.
        url: String,
        /// The value given.
        value: String,
    },
}

impl FromStr for ServeSpec {
    type Err = PolicyError;

    // Long: parses the URL and each query key, then checks the combinations (trust, rate, burst),
    // each with its own one-line error.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        let (base, query) = match s.split_once('?') {
            Some((b, q)) => (b, Some(q)),
            None => (s, None),
        };
        let url: LinkUrl = base.parse()?;
        let mut policy = EndpointPolicy::default();
        let Some(query) = query else {
            return Ok(ServeSpec { url, policy });
        };
        let whole = || s.to_owned();
        let (mut trust, mut rate, mut burst) = (None, None, None);
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(PolicyError::Malformed {
                    url: whole(),
                    reason: format!("option '{pair}' has no value (write {pair}=VALUE)"),
                });
            };
            let slot_taken = match key {
                "trust" => trust.replace(value).is_some(),
                "rate" => rate.replace(value).is_some(),
                "burst" => burst.replace(value).is_some(),
                _ => {
                    return Err(PolicyError::UnknownKey {
                        url: whole(),
                        key: key.to_owned(),
                    });
                }
            };
            if slot_taken {
                return Err(PolicyError::Malformed {
                    url: whole(),
                    reason: format!("option '{key}' is given twice"),
                });
            }
        }
        if let Some(t) = trust {
            policy.trust = match t {
                "trusted" => Trust::Trusted,
                "sign" => Trust::Sign,
                "read-only" | "readonly" => Trust::ReadOnly,
                _ => {
                    return Err(PolicyError::UnknownTrust {
                        url: whole(),
                        value: t.to_owned(),
                    });
                }
            };
        }
        match (rate, burst) {
            (None, None) => {}
            (None, Some(_)) => {
                return Err(PolicyError::Malformed {
                    url: whole(),
                    reason: "burst needs a rate (rate=MSGS_PER_S&burst=N)".into(),
                });
            }
            (Some(r), b) => {
                let per_s = r
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| PolicyError::BadRate {
                        url: whole(),
                        value: r.to_owned(),
                    })?;
                let burst = match b {
                    None => RateLimit::default_burst(per_s),
                    Some(b) => b.parse::<u32>().ok().filter(|v| *v >= 1).ok_or_else(|| {
                        PolicyError::BadBurst {
                            url: whole(),
                            value: b.to_owned(),
                        }
                    })?,
                };
                policy.rate = Some(RateLimit { per_s, burst });
            }
        }
        Ok(ServeSpec { url, policy })
    }
}

/// A token bucket: `burst` tokens at most, refilled at `per_s` a second. Pure: the caller
/// passes the time.
#[derive(Debug, Clone)]
pub struct TokenBucket {
    limit: RateLimit,
    tokens: f64,
    at: Instant,
}

impl TokenBucket {
    /// A full bucket at `now`.
    #[must_use]
    pub fn new(limit: RateLimit, now: Instant) -> Self {
        TokenBucket {
            limit,
            tokens: f64::from(limit.burst),
            at: now,
        }
    }

    /// Takes a token if there is one at `now`. A `now` before the last one adds nothing.
    pub fn take(&mut self, now: Instant) -> bool {
        let dt = now.saturating_duration_since(self.at).as_secs_f64();
        self.at = self.at.max(now);
        self.tokens = (self.tokens + dt * self.limit.per_s).min(f64::from(self.limit.burst));
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// What the router did to one link's traffic because of its policy.
#[derive(Debug, Default)]
pub struct PolicyCounters {
    /// Frames to this link dropped by its rate limit.
    pub dropped_rate: AtomicU64,
    /// Frames from this link not routed because it is read-only.
    pub refused_read_only: AtomicU64,
    /// Frames from this link signed by the daemon (trust `sign`).
    pub signed: AtomicU64,
    /// Frames from this link that could not be signed (MAVLink 1), not routed.
    pub unsignable: AtomicU64,
}

/// A copy of [`PolicyCounters`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PolicyCountersSnapshot {
    /// See [`PolicyCounters::dropped_rate`].
    pub dropped_rate: u64,
    /// See [`PolicyCounters::refused_read_only`].
    pub refused_read_only: u64,
    /// See [`PolicyCounters::signed`].
    pub signed: u64,
    /// See [`PolicyCounters::unsignable`].
    pub unsignable: u64,
}

impl PolicyCounters {
    /// Reads every counter.
    #[must_use]
    pub fn snapshot(&self) -> PolicyCountersSnapshot {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        PolicyCountersSnapshot {
            dropped_rate: g(&self.dropped_rate),
            refused_read_only: g(&self.refused_read_only),
            signed: g(&self.signed),
            unsignable: g(&self.unsignable),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    fn spec(s: &str) -> Result<ServeSpec, PolicyError> {
        s.parse()
    }

    #[test]
    fn queries_parse() {
        let s = spec("tcpin:127.0.0.1:5770").unwrap();
        assert_eq!(s.policy, EndpointPolicy::default());
        assert_eq!(s.to_string(), "tcpin:127.0.0.1:5770");
        let s = spec("tcpin:127.0.0.1:5770?trust=read-only").unwrap();
        assert_eq!(s.policy.trust, Trust::ReadOnly);
        assert_eq!(s.to_string(), "tcpin:127.0.0.1:5770?trust=read-only");
        let s = spec("udpin:0.0.0.0:14550?rate=20&trust=sign").unwrap();
        assert_eq!(s.policy.trust, Trust::Sign);
        assert_eq!(
            s.policy.rate,
            Some(RateLimit {
                per_s: 20.0,
                burst: 20
            })
        );
        let s = spec("tcpin:127.0.0.1:0?rate=0.5&burst=3").unwrap();
        assert_eq!(
            s.policy.rate,
            Some(RateLimit {
                per_s: 0.5,
                burst: 3
            })
        );
        assert_eq!(s.to_string(), "tcpin:127.0.0.1:0?rate=0.5&burst=3");
        assert_eq!(RateLimit::default_burst(0.5), 1);
        assert_eq!(
            spec("tcpin:127.0.0.1:0?").unwrap().policy,
            EndpointPolicy::default()
        );
    }

    #[test]
    fn bad_queries_are_one_clear_error() {
        let cases = [
            ("tcpin:127.0.0.1:0?trust=admin", "unknown trust 'admin'"),
            ("tcpin:127.0.0.1:0?speed=2", "unknown option 'speed'"),
            ("tcpin:127.0.0.1:0?rate=fast", "rate 'fast'"),
            ("tcpin:127.0.0.1:0?rate=0", "rate '0'"),
            ("tcpin:127.0.0.1:0?rate=-3", "rate '-3'"),
            ("tcpin:127.0.0.1:0?rate=nan", "rate 'nan'"),
            ("tcpin:127.0.0.1:0?rate=inf", "rate 'inf'"),
            ("tcpin:127.0.0.1:0?rate=5&burst=0", "burst '0'"),
            ("tcpin:127.0.0.1:0?rate=5&burst=2.5", "burst '2.5'"),
            ("tcpin:127.0.0.1:0?burst=4", "burst needs a rate"),
            ("tcpin:127.0.0.1:0?trust", "has no value"),
            ("tcpin:127.0.0.1:0?trust=sign&trust=trusted", "given twice"),
            ("tcpin:127.0.0.1?trust=sign", "port"),
        ];
        for (url, want) in cases {
            let e = spec(url).unwrap_err().to_string();
            assert!(e.contains(want), "{url}: {e}");
        }
    }

    #[test]
    fn bucket_gives_burst_then_rate() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(
            RateLimit {
                per_s: 10.0,
                burst: 3,
            },
            t0,
        );
        let taken = (0..10).filter(|_| b.take(t0)).count();
        assert_eq!(taken, 3);
        // 1 s later: 10 more at most (the bucket holds 3, so a single instant gives 3).
        let mut got = 0;
        for ms in 1..=1000u64 {
            if b.take(t0 + Duration::from_millis(ms)) {
                got += 1;
            }
        }
        assert_eq!(got, 10);
        // Time going back adds nothing.
        assert!(!b.take(t0));
    }
}
