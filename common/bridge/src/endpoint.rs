//! Where hosts meet: a `quic/HOST:PORT` endpoint (mutual TLS 1.3 over QUIC, UDP) or a
//! `tcp/HOST:PORT` one (insecure), with how its peers prove who they are, checked, and the zenoh
//! configurations of the two sides (the learner's host listens, a remote host connects; no
//! scouting, so nothing is multicast and a session talks only to the endpoint it was given).
//!
//! zenoh's TLS-over-TCP link (`tls/`) is not offered: in zenoh 1.10 its reader and writer share
//! one TLS stream without a common lock, and on 127.0.0.1 a run's first connection fails with
//! "handshake not complete" within a second, dropping the remote host. Its QUIC link takes the
//! same certificates and keys.

use std::fmt;
use std::net::ToSocketAddrs as _;

use crate::error::{zenoh_error, BridgeError, Result};
use crate::tls::{Security, TlsFiles};

/// A checked `quic/HOST:PORT` with its certificates, or `tcp/HOST:PORT` (insecure).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    host: String,
    port: u16,
    security: Security,
}

impl Endpoint {
    /// Parses `quic/HOST:PORT` or `tcp/HOST:PORT` (HOST a name, an IPv4 address or `[IPv6]`;
    /// PORT 1 to 65535) to be used with `security`: certificates for `quic/`,
    /// [`Security::Insecure`] for `tcp/`.
    pub fn parse(text: &str, security: Security) -> Result<Self> {
        let bad = || BridgeError::InvalidEndpoint(text.to_owned());
        let (scheme, rest) = text.split_once('/').ok_or_else(bad)?;
        let tls = match scheme {
            "quic" => true,
            "tcp" => false,
            "tls" => {
                return Err(BridgeError::Tls(format!(
                    "{text}: zenoh's TLS-over-TCP link drops new connections (a race in zenoh \
                     1.10); use quic/{rest} with the same certificates (UDP)"
                )))
            }
            _ => return Err(bad()),
        };
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
        match (tls, &security) {
            (true, Security::Insecure) => Err(BridgeError::Tls(format!(
                "{text}: TLS needs the run's CA certificate, this host's certificate and its \
                 key (--tls-ca, --tls-cert, --tls-key; `alfd certs` makes them)"
            ))),
            (false, Security::Tls(_)) => Err(BridgeError::Tls(format!(
                "{text} is plain TCP but certificates were given: use quic/{rest}"
            ))),
            _ => Ok(Self {
                host: host.to_owned(),
                port,
                security,
            }),
        }
    }

    pub fn port(&self) -> u16 {
        self.port
    }

    /// Whether peers are checked by certificate.
    pub fn is_secure(&self) -> bool {
        matches!(self.security, Security::Tls(_))
    }

    /// The zenoh configuration of the learner's host: a peer listening on this endpoint (with
    /// TLS: showing its certificate and taking only peers that show one of the run's CA).
    pub fn listen_config(&self) -> Result<zenoh::Config> {
        let mut cfg = base_config("peer")?;
        cfg.insert_json5("listen/endpoints", &format!("[\"{self}\"]"))
            .map_err(zenoh_error)?;
        if let Security::Tls(files) = &self.security {
            tls_config(&mut cfg, files, "listen")?;
        }
        Ok(cfg)
    }

    /// The zenoh configuration of a remote host: a client connecting to this endpoint (with
    /// TLS: showing its certificate and checking the other's, issued for HOST, against the
    /// run's CA).
    pub fn connect_config(&self) -> Result<zenoh::Config> {
        let mut cfg = base_config("client")?;
        cfg.insert_json5("connect/endpoints", &format!("[\"{self}\"]"))
            .map_err(zenoh_error)?;
        if let Security::Tls(files) = &self.security {
            tls_config(&mut cfg, files, "connect")?;
        }
        Ok(cfg)
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = if self.is_secure() { "quic" } else { "tcp" };
        write!(f, "{scheme}/{}:{}", self.host, self.port)
    }
}

/// Mutual TLS: `side` is `listen` or `connect`. Links close when a certificate expires.
fn tls_config(cfg: &mut zenoh::Config, files: &TlsFiles, side: &str) -> Result<()> {
    let path = |p: &std::path::Path| {
        serde_json::to_string(&p.to_string_lossy()).expect("a string is JSON")
    };
    for (key, value) in [
        ("root_ca_certificate".to_owned(), path(&files.ca)),
        (format!("{side}_certificate"), path(&files.certificate)),
        (format!("{side}_private_key"), path(&files.key)),
        ("enable_mtls".to_owned(), "true".to_owned()),
        ("verify_name_on_connect".to_owned(), "true".to_owned()),
        ("close_link_on_expiration".to_owned(), "true".to_owned()),
    ] {
        cfg.insert_json5(&format!("transport/link/tls/{key}"), &value)
            .map_err(zenoh_error)?;
    }
    Ok(())
}

/// The largest message a bridge takes from a peer.
pub const MAX_MESSAGE_BYTES: usize = 64 << 20;

fn base_config(mode: &str) -> Result<zenoh::Config> {
    let mut cfg = zenoh::Config::default();
    for (key, value) in [
        ("mode", format!("\"{mode}\"")),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("listen/endpoints", "[]".to_owned()),
        ("connect/endpoints", "[]".to_owned()),
        // No admin space, no timestamps: nothing the run does not use.
        ("adminspace/enabled", "false".to_owned()),
        // A message larger than any the run sends (its weights, `demos.jsonl` whole) is
        // dropped by zenoh before it is put together: a peer cannot make this host hold a GiB.
        (
            "transport/link/rx/max_message_size",
            MAX_MESSAGE_BYTES.to_string(),
        ),
    ] {
        cfg.insert_json5(key, &value).map_err(zenoh_error)?;
    }
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plain(text: &str) -> Result<Endpoint> {
        Endpoint::parse(text, Security::Insecure)
    }

    #[test]
    fn endpoints_are_checked_and_printed_back() {
        let e = plain("tcp/127.0.0.1:7447").unwrap();
        assert_eq!(e.to_string(), "tcp/127.0.0.1:7447");
        assert_eq!(e.port(), 7447);
        assert!(!e.is_secure());
        assert!(plain("tcp/localhost:80").is_ok());
        for bad in [
            "127.0.0.1:7447",
            "udp/127.0.0.1:7447",
            "tcp/127.0.0.1",
            "tcp/127.0.0.1:0",
            "tcp/127.0.0.1:70000",
            "tcp/:7447",
            "tcp/no such host:1",
            "quic/127.0.0.1",
        ] {
            let err = plain(bad).unwrap_err();
            assert!(err.is_bad_input(), "{bad}");
            assert!(err.to_string().contains(bad), "{err}");
        }
    }

    #[test]
    fn both_sides_have_a_configuration() {
        let e = plain("tcp/127.0.0.1:7447").unwrap();
        let l = e.listen_config().unwrap();
        assert!(l.get_json("listen/endpoints").unwrap().contains("7447"));
        let c = e.connect_config().unwrap();
        assert!(c.get_json("connect/endpoints").unwrap().contains("7447"));
        assert!(c.get_json("mode").unwrap().contains("client"));
        for cfg in [l, c] {
            let max = cfg.get_json("transport/link/rx/max_message_size").unwrap();
            assert_eq!(max, MAX_MESSAGE_BYTES.to_string());
        }
    }

    #[test]
    fn a_tls_endpoint_over_quic_needs_certificates_and_names_them_in_both_configurations() {
        let dir = tempfile::tempdir().unwrap();
        crate::tls::make_ca(dir.path(), 1).unwrap();
        let (from, to) = crate::tls::valid_for(1);
        let files = crate::tls::make_host(dir.path(), "127.0.0.1", from, to).unwrap();
        let tls = Security::Tls(files.clone());
        let e = Endpoint::parse("quic/127.0.0.1:7447", tls.clone()).unwrap();
        assert!(e.is_secure());
        assert_eq!(e.to_string(), "quic/127.0.0.1:7447");
        let l = e.listen_config().unwrap();
        assert!(l
            .get_json("listen/endpoints")
            .unwrap()
            .contains("quic/127.0.0.1:7447"));
        let key = files.key.to_string_lossy().into_owned();
        assert!(l
            .get_json("transport/link/tls/listen_private_key")
            .unwrap()
            .contains(&key));
        assert_eq!(
            l.get_json("transport/link/tls/enable_mtls").unwrap(),
            "true"
        );
        let c = e.connect_config().unwrap();
        assert!(c
            .get_json("transport/link/tls/connect_private_key")
            .unwrap()
            .contains(&key));
        // A scheme that does not fit the security is refused, naming the fix.
        let e = plain("quic/127.0.0.1:7447").unwrap_err();
        assert!(
            e.is_bad_input() && e.to_string().contains("--tls-ca"),
            "{e}"
        );
        let e = Endpoint::parse("tcp/127.0.0.1:7447", tls.clone()).unwrap_err();
        assert!(e.to_string().contains("use quic/127.0.0.1:7447"), "{e}");
        // zenoh's TLS over TCP is refused, naming the QUIC endpoint to use instead.
        let e = Endpoint::parse("tls/127.0.0.1:7447", tls).unwrap_err();
        assert!(
            e.is_bad_input() && e.to_string().contains("quic/127.0.0.1:7447"),
            "{e}"
        );
    }
}
