//! `alfd certs`: a run's certificate authority and one certificate per host, for runs across
//! hosts over mutual TLS (`alfd run --listen quic/…`, `alfd join --connect quic/…`).

use std::path::PathBuf;

use crate::usage::usage;

#[derive(Debug, clap::Args)]
pub struct CertsArgs {
    /// Where the files go: DIR/ca.pem and DIR/ca.key (made unless both are there), then
    /// DIR/NAME.pem and DIR/NAME.key per --host. Keys are readable by their owner only; copy a
    /// host's NAME.pem, NAME.key and ca.pem to that host, never ca.key.
    pub dir: PathBuf,
    /// A host to certify, by the DNS name or IP address the others reach it at (repeatable).
    /// The learner's host needs the address in `--listen quic/ADDR:PORT` as remote hosts write
    /// it in `--connect`; for remote hosts any name will do.
    #[arg(long = "host", value_name = "NAME")]
    pub hosts: Vec<String>,
    /// Days the certificates are valid (1..=3650).
    #[arg(long, default_value_t = 365)]
    pub days: u32,
}

pub fn run(args: CertsArgs) -> anyhow::Result<()> {
    if !(1..=3650).contains(&args.days) {
        return Err(usage(format!(
            "--days must be in 1..=3650, got {}",
            args.days
        )));
    }
    make(&args)
}

#[cfg(not(feature = "hosts"))]
fn make(_: &CertsArgs) -> anyhow::Result<()> {
    Err(crate::usage::without_hosts("alfd certs"))
}

/// The CA (made unless there) and each host's certificate and key.
#[cfg(feature = "hosts")]
fn make(args: &CertsArgs) -> anyhow::Result<()> {
    let bad = |e: alfd_bridge::BridgeError| usage(e.to_string());
    let dir = &args.dir;
    match alfd_bridge::make_ca(dir, args.days).map_err(bad)? {
        alfd_bridge::CaMade::Created => {
            println!("made the run's CA: {}", dir.join("ca.pem").display())
        }
        alfd_bridge::CaMade::Kept => println!("using the CA in {}", dir.display()),
    }
    let (from, to) = alfd_bridge::valid_for(args.days);
    for host in &args.hosts {
        let files = alfd_bridge::make_host(dir, host, from, to).map_err(bad)?;
        println!(
            "{host}: --tls-ca {} --tls-cert {} --tls-key {}",
            files.ca.display(),
            files.certificate.display(),
            files.key.display()
        );
    }
    Ok(())
}
