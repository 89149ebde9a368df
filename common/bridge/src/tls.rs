//! Peers that prove who they are: mutual TLS between the learner's host and remote hosts.
//!
//! A run's certificate authority (`ca.pem`, `ca.key`) signs one certificate per host
//! (`NAME.pem`, `NAME.key`). The learner's host listens on `quic/ADDR:PORT` (TLS 1.3 inside
//! QUIC) and takes only peers that show a certificate of that CA, valid today; a remote host
//! checks that the learner's host shows one too, issued for the name or address it connected to.
//! The TLS handshake itself refuses everyone else (no certificate, an expired one, one of another
//! CA), before any frame reaches the run. [`make_ca`] and [`make_host`] write such files (`alfd certs`); a user's own
//! PEM files work the same.

use std::fs;
use std::io::Write as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use time::{Duration, OffsetDateTime};

use crate::error::{BridgeError, Result};

/// How a bridge meets the other hosts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Security {
    /// Plain TCP: anyone who reaches the port can join. Only when the user says so (`--insecure`).
    Insecure,
    /// Mutual TLS with these files.
    Tls(TlsFiles),
}

/// The PEM files of one host: the run's CA certificate, this host's certificate and its key.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsFiles {
    pub ca: PathBuf,
    pub certificate: PathBuf,
    pub key: PathBuf,
}

impl TlsFiles {
    /// The three files, each checked to be readable and to hold what it should (a certificate,
    /// a certificate, a private key), so that a wrong path is said now rather than as a failed
    /// connection later.
    pub fn checked(ca: &Path, certificate: &Path, key: &Path) -> Result<Self> {
        check_pem(ca, "--tls-ca", "CERTIFICATE")?;
        check_pem(certificate, "--tls-cert", "CERTIFICATE")?;
        check_pem(key, "--tls-key", "PRIVATE KEY")?;
        Ok(Self {
            ca: ca.to_owned(),
            certificate: certificate.to_owned(),
            key: key.to_owned(),
        })
    }

    /// The files as `DIR/ca.pem`, `DIR/NAME.pem` and `DIR/NAME.key` (what [`make_host`] writes).
    pub fn in_dir(dir: &Path, name: &str) -> Result<Self> {
        Self::checked(
            &dir.join("ca.pem"),
            &dir.join(format!("{name}.pem")),
            &dir.join(format!("{name}.key")),
        )
    }
}

/// The TLS handshake's reason in a zenoh QUIC error's text (`... reason: "invalid peer
/// certificate: Expired" ...` or `reason: b"peer sent no certificates"`), when it holds one.
pub fn tls_reason(text: &str) -> Option<&str> {
    let (_, rest) = text.split_once("reason: ")?;
    let rest = rest.strip_prefix('b').unwrap_or(rest).strip_prefix('"')?;
    rest.split_once('"').map(|(why, _)| why)
}

fn check_pem(path: &Path, flag: &str, label: &str) -> Result<()> {
    let bad = |why: String| BridgeError::Tls(format!("{flag} {}: {why}", path.display()));
    let text = fs::read_to_string(path).map_err(|e| bad(format!("cannot read it: {e}")))?;
    if !text.contains("-----BEGIN ") || !text.contains(&format!("{label}-----")) {
        return Err(bad(format!("no PEM block of `{label}` in it")));
    }
    Ok(())
}

/// What [`make_ca`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaMade {
    Created,
    /// `ca.pem` and `ca.key` were there already and are used as they are.
    Kept,
}

/// Makes the run's certificate authority in `dir` (`ca.pem`, and `ca.key` readable by its owner
/// only), valid for `days`, unless both files are there already.
pub fn make_ca(dir: &Path, days: u32) -> Result<CaMade> {
    let (cert, key) = (dir.join("ca.pem"), dir.join("ca.key"));
    match (cert.exists(), key.exists()) {
        (true, true) => return Ok(CaMade::Kept),
        (false, false) => {}
        _ => {
            return Err(BridgeError::Tls(format!(
                "{} has one of ca.pem and ca.key but not the other: remove it or give another \
                 directory",
                dir.display()
            )))
        }
    }
    fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    let mut params = CertificateParams::default();
    params
        .distinguished_name
        .push(DnType::CommonName, "alfd run CA");
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    (params.not_before, params.not_after) = valid_for(days);
    let key_pair = KeyPair::generate().map_err(rcgen_error)?;
    let ca = params.self_signed(&key_pair).map_err(rcgen_error)?;
    write_private(&key, &key_pair.serialize_pem())?;
    write_public(&cert, &ca.pem())?;
    Ok(CaMade::Created)
}

/// Makes `DIR/NAME.pem` and `DIR/NAME.key` (owner-only): a certificate for the host `name` (a
/// DNS name or an IP address: the learner's host's is the address remote hosts connect to),
/// signed by the CA in `dir`, for both ends of a connection, valid from `not_before` to
/// `not_after`.
pub fn make_host(
    dir: &Path,
    name: &str,
    not_before: OffsetDateTime,
    not_after: OffsetDateTime,
) -> Result<TlsFiles> {
    let valid_name = !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b".-:".contains(&b));
    if !valid_name {
        return Err(BridgeError::Tls(format!(
            "host name `{name}`: expected a DNS name or an IP address"
        )));
    }
    let issuer = load_issuer(dir)?;
    let mut params = CertificateParams::new(vec![name.to_owned()]).map_err(rcgen_error)?;
    params.distinguished_name = rcgen::DistinguishedName::new();
    params.distinguished_name.push(DnType::CommonName, name);
    params.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    params.use_authority_key_identifier_extension = true;
    params.not_before = not_before;
    params.not_after = not_after;
    let key_pair = KeyPair::generate().map_err(rcgen_error)?;
    let cert = params.signed_by(&key_pair, &issuer).map_err(rcgen_error)?;
    let file = dir.join(format!("{name}.pem"));
    write_private(&dir.join(format!("{name}.key")), &key_pair.serialize_pem())?;
    write_public(&file, &cert.pem())?;
    TlsFiles::in_dir(dir, name)
}

/// A certificate valid from an hour ago for `days` days.
pub fn valid_for(days: u32) -> (OffsetDateTime, OffsetDateTime) {
    let now = OffsetDateTime::now_utc();
    (
        now - Duration::hours(1),
        now + Duration::days(i64::from(days)),
    )
}

fn load_issuer(dir: &Path) -> Result<Issuer<'static, KeyPair>> {
    let read = |file: &str| {
        let path = dir.join(file);
        fs::read_to_string(&path).map_err(|e| {
            BridgeError::Tls(format!(
                "cannot read {}: {e} (make the CA first: `alfd certs {}`)",
                path.display(),
                dir.display()
            ))
        })
    };
    let key = KeyPair::from_pem(&read("ca.key")?).map_err(rcgen_error)?;
    Issuer::from_ca_cert_pem(&read("ca.pem")?, key).map_err(rcgen_error)
}

fn write_private(path: &Path, text: &str) -> Result<()> {
    let mut file = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(|e| io_error(path, e))?;
    file.write_all(text.as_bytes())
        .and_then(|()| file.sync_all())
        .map_err(|e| io_error(path, e))
}

fn write_public(path: &Path, text: &str) -> Result<()> {
    fs::write(path, text).map_err(|e| io_error(path, e))
}

fn io_error(path: &Path, e: std::io::Error) -> BridgeError {
    BridgeError::Tls(format!("{}: {e}", path.display()))
}

fn rcgen_error(e: rcgen::Error) -> BridgeError {
    BridgeError::Tls(format!("certificate: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    #[test]
    fn a_ca_and_host_files_are_made_keys_owner_only_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(make_ca(dir.path(), 30).unwrap(), CaMade::Created);
        assert_eq!(make_ca(dir.path(), 30).unwrap(), CaMade::Kept);
        let (from, to) = valid_for(30);
        let files = make_host(dir.path(), "127.0.0.1", from, to).unwrap();
        assert_eq!(files, TlsFiles::in_dir(dir.path(), "127.0.0.1").unwrap());
        for key in ["ca.key", "127.0.0.1.key"] {
            let mode = fs::metadata(dir.path().join(key))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600, "{key}");
        }
        // A host's key is never overwritten.
        let again = make_host(dir.path(), "127.0.0.1", from, to).unwrap_err();
        assert!(again.to_string().contains("127.0.0.1.key"), "{again}");
    }

    #[test]
    fn wrong_files_and_names_are_refused_naming_the_flag_and_path() {
        let dir = tempfile::tempdir().unwrap();
        make_ca(dir.path(), 1).unwrap();
        let ca = dir.path().join("ca.pem");
        let key = dir.path().join("ca.key");
        let missing = dir.path().join("nothing.pem");
        let e = TlsFiles::checked(&ca, &missing, &key).unwrap_err();
        assert!(e.to_string().contains("--tls-cert") && e.to_string().contains("nothing.pem"));
        let e = TlsFiles::checked(&ca, &ca, &ca).unwrap_err();
        assert!(
            e.to_string().contains("--tls-key") && e.is_bad_input(),
            "{e}"
        );
        let (from, to) = valid_for(1);
        for bad in ["", "a b", "../x", "host/1"] {
            assert!(make_host(dir.path(), bad, from, to).is_err(), "{bad}");
        }
        let other = tempfile::tempdir().unwrap();
        let e = make_host(other.path(), "h", from, to).unwrap_err();
        assert!(e.to_string().contains("alfd certs"), "{e}");
        fs::remove_file(&key).unwrap();
        assert!(make_ca(dir.path(), 1).is_err());
    }
}
