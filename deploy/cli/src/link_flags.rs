//! How this host's bridge proves who it is across hosts: the flags `alfd run --listen` and
//! `alfd join --connect` share (`quic/` with the run's certificates, mutual TLS, or `tcp/` with
//! `--insecure`), checked into an [`alfd_bridge::Endpoint`].

use std::path::PathBuf;

#[cfg(feature = "hosts")]
use alfd_bridge::{Endpoint, Security, TlsFiles};

#[cfg(feature = "hosts")]
use crate::usage::usage;

/// The flags; read only in a build with the `hosts` feature.
#[derive(Debug, Clone, Default, clap::Args)]
#[cfg_attr(not(feature = "hosts"), allow(dead_code))]
pub struct LinkFlags {
    /// The run's CA certificate (PEM) for a quic/ endpoint (mutual TLS); `alfd certs DIR --host NAME` makes
    /// DIR/ca.pem, DIR/NAME.pem and DIR/NAME.key.
    #[arg(long, value_name = "FILE")]
    pub tls_ca: Option<PathBuf>,
    /// This host's certificate (PEM), signed by the run's CA.
    #[arg(long, value_name = "FILE")]
    pub tls_cert: Option<PathBuf>,
    /// This host's private key (PEM).
    #[arg(long, value_name = "FILE")]
    pub tls_key: Option<PathBuf>,
    /// Plain TCP (a tcp/ endpoint) without certificates: anyone who reaches the port can join
    /// the run. Only on a network you trust.
    #[arg(long)]
    pub insecure: bool,
}

#[cfg(feature = "hosts")]
impl LinkFlags {
    /// `text` (the value of `flag`) as an endpoint with these flags' security; exit 2 naming
    /// what is missing or does not fit.
    pub fn endpoint(&self, flag: &str, text: &str) -> anyhow::Result<Endpoint> {
        let security = self
            .security(text)
            .map_err(|e| usage(format!("{flag}: {e}")))?;
        Endpoint::parse(text, security).map_err(|e| usage(format!("{flag}: {e}")))
    }

    fn security(&self, text: &str) -> Result<Security, String> {
        match (self.insecure, &self.tls_ca, &self.tls_cert, &self.tls_key) {
            (false, Some(ca), Some(cert), Some(key)) => TlsFiles::checked(ca, cert, key)
                .map(Security::Tls)
                .map_err(|e| e.to_string()),
            (true, None, None, None) => Ok(Security::Insecure),
            (true, ..) => Err("--insecure and --tls-* together: choose one".to_owned()),
            (false, None, None, None) => match text.strip_prefix("tcp/") {
                Some(rest) => Err(format!(
                    "{text} is plain TCP: anyone who reaches the port could join the run. Use \
                     quic/{rest} with --tls-ca, --tls-cert and --tls-key (`alfd certs DIR \
                     --host NAME` makes them), or add --insecure on a network you trust"
                )),
                // quic/ without files, or not an endpoint: the endpoint's own check says so.
                None => Ok(Security::Insecure),
            },
            (false, ..) => Err("give all three of --tls-ca, --tls-cert and --tls-key".to_owned()),
        }
    }
}

#[cfg(all(test, feature = "hosts"))]
mod tests {
    use super::*;

    #[test]
    fn plain_tcp_needs_insecure_and_tls_needs_all_three_files() {
        let none = LinkFlags::default();
        let e = none.security("tcp/127.0.0.1:7447").unwrap_err();
        assert!(
            e.contains("--insecure") && e.contains("quic/127.0.0.1:7447"),
            "{e}"
        );
        let insecure = LinkFlags {
            insecure: true,
            ..LinkFlags::default()
        };
        assert_eq!(
            insecure.security("tcp/127.0.0.1:7447").unwrap(),
            Security::Insecure
        );
        let some = LinkFlags {
            tls_ca: Some("ca.pem".into()),
            ..LinkFlags::default()
        };
        assert!(some.security("quic/h:1").unwrap_err().contains("all three"));
        let both = LinkFlags {
            insecure: true,
            ..some
        };
        assert!(both.security("quic/h:1").unwrap_err().contains("together"));
        // quic/ without files is left to the endpoint, which names the flags.
        let e = none
            .endpoint("--listen", "quic/127.0.0.1:7447")
            .unwrap_err();
        assert!(e.to_string().contains("--tls-ca"), "{e}");
    }
}
