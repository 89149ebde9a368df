//! Mutual TLS on 127.0.0.1 (zenoh's QUIC link, as `alfd run --listen quic/…` uses it): a peer
//! with a certificate of the run's CA is served; one with no certificate, an expired one or one
//! of another CA is refused by the handshake, and the listener goes on serving.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use alfd_bridge::{make_ca, make_host, valid_for, Endpoint, Security, TlsFiles};
use time::{Date, Month, OffsetDateTime, Time};
use zenoh::Wait as _;

/// What zenoh's QUIC listener logs at warning level, kept (the process's only subscriber).
fn listener_warnings() -> Arc<Mutex<Vec<u8>>> {
    #[derive(Clone)]
    struct Kept(Arc<Mutex<Vec<u8>>>);
    impl std::io::Write for Kept {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let kept = Kept(Arc::default());
    let writer = kept.clone();
    use tracing_subscriber::prelude::*;
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_ansi(false)
                .with_writer(move || writer.clone()),
        )
        .with(
            tracing_subscriber::filter::Targets::new()
                .with_target("zenoh_link_commons::quic", tracing::Level::WARN),
        )
        .init();
    kept.0
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn at(year: i32) -> OffsetDateTime {
    Date::from_calendar_date(year, Month::January, 1)
        .unwrap()
        .with_time(Time::MIDNIGHT)
        .assume_utc()
}

fn endpoint(port: u16, files: TlsFiles) -> Endpoint {
    Endpoint::parse(&format!("quic/127.0.0.1:{port}"), Security::Tls(files)).unwrap()
}

/// The answer of the listener's `ping` queryable to a client opened with `cfg`, or why not.
fn ping(cfg: zenoh::Config) -> Result<String, String> {
    let session = zenoh::open(cfg).wait().map_err(|e| e.to_string())?;
    let replies = session
        .get("alfd/test/ping")
        .timeout(Duration::from_secs(2))
        .wait()
        .map_err(|e| e.to_string())?;
    let reply = replies.recv().map_err(|e| e.to_string())?;
    let sample = reply.result().map_err(|_| "an error reply".to_owned())?;
    let text = sample
        .payload()
        .try_to_string()
        .map_err(|e| e.to_string())?;
    Ok(text.into_owned())
}

#[test]
fn tls_peers_without_a_certificate_of_the_runs_ca_are_refused_and_the_listener_goes_on() {
    let warnings = listener_warnings();
    let (run, other) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (from, to) = valid_for(1);
    make_ca(run.path(), 1).unwrap();
    let server = make_host(run.path(), "127.0.0.1", from, to).unwrap();
    let good = make_host(run.path(), "good", from, to).unwrap();
    let expired = make_host(run.path(), "expired", at(2020), at(2021)).unwrap();
    let not_yet = make_host(run.path(), "not-yet", at(2090), at(2091)).unwrap();
    make_ca(other.path(), 1).unwrap();
    let stranger = make_host(other.path(), "stranger", from, to).unwrap();
    let port = free_udp_port();

    let listener = zenoh::open(endpoint(port, server.clone()).listen_config().unwrap())
        .wait()
        .unwrap();
    let _ping = listener
        .declare_queryable("alfd/test/ping")
        .callback(|q| {
            let _ = q.reply("alfd/test/ping", "pong").wait();
        })
        .wait()
        .unwrap();
    let client = |files: TlsFiles| endpoint(port, files).connect_config().unwrap();
    assert_eq!(ping(client(good.clone())), Ok("pong".to_owned()));

    // Our CA trusted, the certificate shown another's: refused by the listener.
    let another_ca = TlsFiles {
        ca: good.ca.clone(),
        ..stranger.clone()
    };
    // No certificate at all.
    let mut none = client(good.clone());
    none.insert_json5("transport/link/tls/enable_mtls", "false")
        .unwrap();
    // The listener's certificate not of the CA this client trusts: refused by the client.
    let wrong_server = stranger.clone();
    for (what, cfg) in [
        ("a certificate of another CA", client(another_ca)),
        ("an expired certificate", client(expired)),
        ("a certificate not valid yet", client(not_yet)),
        ("no certificate", none),
        ("a listener of another CA", client(wrong_server)),
    ] {
        let got = ping(cfg);
        // Refused when connecting, not later (a timeout of the query would hide a link made).
        let refused = got.as_ref().is_err_and(|e| e.contains("Unable to connect"));
        assert!(refused, "{what}: {got:?}");
    }
    // The listener goes on serving its run's hosts.
    assert_eq!(ping(client(good)), Ok("pong".to_owned()));
    // And said why it refused each (the handshake's reasons, as rustls names them).
    let said = String::from_utf8_lossy(&warnings.lock().unwrap()).into_owned();
    for reason in [
        "BadSignature",
        "certificate expired",
        "certificate not valid yet",
        "peer sent no certificates",
    ] {
        assert!(
            said.contains(reason),
            "{reason} not in the listener's log:\n{said}"
        );
    }
}
