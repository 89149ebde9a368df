//! Where hosts meet: a `tcp/HOST:PORT` endpoint, checked, and the zenoh configurations of the
//! two sides (the learner's host listens, a remote host connects; no scouting, so nothing is
//! multicast and a session talks only to the endpoint it was given).

use std::fmt;
use std::net::ToSocketAddrs as _;

use crate::error::{zenoh_error, BridgeError, Result};

/// A checked `tcp/HOST:PORT`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    host: String,
    port: u16,
}

impl Endpoint {
    /// Parses `tcp/HOST:PORT` (HOST a name, an IPv4 address or `[IPv6]`; PORT 1 to 65535).
    pub fn parse(text: &str) -> Result<Self> {
        let bad = || BridgeError::InvalidEndpoint(text.to_owned());
        let rest = text.strip_prefix("tcp/").ok_or_else(bad)?;
        let (host, port) = rest.rsplit_once(':').ok_or_else(bad)?;
        let port: u16 = port.parse().map_err(|_| bad())?;
        let host_ok = !host.is_empty()
            && host
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b".-_[]:".contains(&b));
        if port == 0 || !host_ok {
            return Err(bad());
        }
        // The name must resolve (an unknown host is bad input, said now rather than as a
        // timeout later).
        (host.trim_matches(['[', ']']), port)
            .to_socket_addrs()
            .map_err(|_| bad())?;
        Ok(Self {
            host: host.to_owned(),
            port,
        })
    }

    pub fn port(&self) -> u16 {
        self.port
    }

    /// The zenoh configuration of the learner's host: a peer listening on this endpoint.
    pub fn listen_config(&self) -> Result<zenoh::Config> {
        let mut cfg = base_config("peer")?;
        cfg.insert_json5("listen/endpoints", &format!("[\"{self}\"]"))
            .map_err(zenoh_error)?;
        Ok(cfg)
    }

    /// The zenoh configuration of a remote host: a client connecting to this endpoint.
    pub fn connect_config(&self) -> Result<zenoh::Config> {
        let mut cfg = base_config("client")?;
        cfg.insert_json5("connect/endpoints", &format!("[\"{self}\"]"))
            .map_err(zenoh_error)?;
        Ok(cfg)
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "tcp/{}:{}", self.host, self.port)
    }
}

fn base_config(mode: &str) -> Result<zenoh::Config> {
    let mut cfg = zenoh::Config::default();
    for (key, value) in [
        ("mode", format!("\"{mode}\"")),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("listen/endpoints", "[]".to_owned()),
        ("connect/endpoints", "[]".to_owned()),
        // No admin space, no timestamps: nothing the run does not use.
        ("adminspace/enabled", "false".to_owned()),
    ] {
        cfg.insert_json5(key, &value).map_err(zenoh_error)?;
    }
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_are_checked_and_printed_back() {
        let e = Endpoint::parse("tcp/127.0.0.1:7447").unwrap();
        assert_eq!(e.to_string(), "tcp/127.0.0.1:7447");
        assert_eq!(e.port(), 7447);
        assert!(Endpoint::parse("tcp/localhost:80").is_ok());
        for bad in [
            "127.0.0.1:7447",
            "udp/127.0.0.1:7447",
            "tcp/127.0.0.1",
            "tcp/127.0.0.1:0",
            "tcp/127.0.0.1:70000",
            "tcp/:7447",
            "tcp/no such host:1",
        ] {
            let err = Endpoint::parse(bad).unwrap_err();
            assert!(err.is_bad_input(), "{bad}");
            assert!(err.to_string().contains(bad), "{err}");
        }
    }

    #[test]
    fn both_sides_have_a_configuration() {
        let e = Endpoint::parse("tcp/127.0.0.1:7447").unwrap();
        let l = e.listen_config().unwrap();
        assert!(l.get_json("listen/endpoints").unwrap().contains("7447"));
        let c = e.connect_config().unwrap();
        assert!(c.get_json("connect/endpoints").unwrap().contains("7447"));
        assert!(c.get_json("mode").unwrap().contains("client"));
    }
}
