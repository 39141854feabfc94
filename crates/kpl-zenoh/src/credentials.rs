//! A deployment's keys: the files that let its hosts authenticate each other, made by `kpl keys`
//! ([`make`]) or given by the user in the same layout, and read by each host ([`Credentials::load`]).
//!
//! ```text
//! KEYS/ca.pem            the deployment's certificate authority (every host needs it)
//! KEYS/ca.key            its private key: only `kpl keys` needs it, to add hosts; keep it apart
//! KEYS/secret            32 random bytes in hex: the key of the messages' authentication tags
//! KEYS/HOST.pem          each host's certificate, signed by the CA, common name HOST
//! KEYS/HOST.key          each host's private key
//! ```
//!
//! Hosts link over mutual TLS with these certificates (zenoh checks that the other side's
//! certificate is signed by the deployment's CA; its common name is the host's name, which zenoh's
//! access control matches), and every message they send carries an HMAC-SHA256 tag made with the
//! secret ([`crate::envelope`]).

use std::fmt;
use std::path::{Path, PathBuf};

use kpl_runtime::transport::TransportError;
use ring::hmac;

/// The certificate authority's certificate in a keys folder.
pub const CA_CERTIFICATE: &str = "ca.pem";
/// The certificate authority's private key.
pub const CA_KEY: &str = "ca.key";
/// The secret of the authentication tags.
pub const SECRET: &str = "secret";

/// The certificate of `host` in a keys folder.
pub fn certificate_file(host: &str) -> String {
    format!("{host}.pem")
}

/// The private key of `host` in a keys folder.
pub fn key_file(host: &str) -> String {
    format!("{host}.key")
}

/// The key of the messages' authentication tags (HMAC-SHA256). Its bytes are never printed.
#[derive(Clone)]
pub struct Secret(hmac::Key);

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Secret(..)")
    }
}

impl Secret {
    pub fn from_bytes(bytes: &[u8]) -> Secret {
        Secret(hmac::Key::new(hmac::HMAC_SHA256, bytes))
    }

    /// Reads the 64 hexadecimal digits of a `secret` file.
    pub fn parse(text: &str) -> Result<Secret, String> {
        let digits = text.trim();
        if digits.len() != 64 {
            return Err(format!("expected 64 hexadecimal digits, found {} characters", digits.len()));
        }
        let bytes = (0..32)
            .map(|i| u8::from_str_radix(&digits[2 * i..2 * i + 2], 16))
            .collect::<Result<Vec<u8>, _>>()
            .map_err(|_| "expected 64 hexadecimal digits".to_string())?;
        Ok(Secret::from_bytes(&bytes))
    }

    pub(crate) fn key(&self) -> &hmac::Key {
        &self.0
    }
}

/// What one host needs of its deployment's keys.
#[derive(Debug, Clone)]
pub struct Credentials {
    pub dir: PathBuf,
    /// Made on first use for hosts started without a keys folder: links stay `tcp/` by default
    /// (messages are authenticated, not encrypted); a given keys folder makes them `tls/`.
    pub made_on_first_use: bool,
    pub ca: PathBuf,
    pub certificate: PathBuf,
    pub private_key: PathBuf,
    pub secret: Secret,
}

impl Credentials {
    /// The credentials of `host` in the keys folder `dir`.
    pub fn load(dir: &Path, host: &str) -> Result<Credentials, TransportError> {
        let need = |name: String| -> Result<PathBuf, TransportError> {
            let path = dir.join(&name);
            if path.is_file() {
                Ok(path)
            } else {
                Err(TransportError(format!(
                    "the keys folder {} has no {name} (make the keys of a deployment with `kpl keys SPEC --out {}`)",
                    dir.display(),
                    dir.display()
                )))
            }
        };
        let ca = need(CA_CERTIFICATE.to_string())?;
        let certificate = need(certificate_file(host))?;
        let private_key = need(key_file(host))?;
        let secret_path = need(SECRET.to_string())?;
        let text = std::fs::read_to_string(&secret_path)
            .map_err(|e| TransportError(format!("cannot read {}: {e}", secret_path.display())))?;
        let secret = Secret::parse(&text).map_err(|e| {
            TransportError(format!("{} is not a deployment secret: {e}", secret_path.display()))
        })?;
        Ok(Credentials {
            dir: dir.to_path_buf(),
            made_on_first_use: false,
            ca,
            certificate,
            private_key,
            secret,
        })
    }
}

/// The folder of a deployment's keys made on first use, when no keys folder is given:
/// `STATE/keys/SPEC-HASH/DEPLOYMENT`, where `STATE` is `KPL_STATE_DIR`, else
/// `$XDG_STATE_HOME/kpl`, else `~/.local/state/kpl`, `SPEC` the spec's file stem and `HASH` 16
/// hexadecimal digits of the SHA-256 of the spec's canonical path. Every host of one deployment of
/// one spec file on this machine finds the same folder, so they agree on its keys without being
/// told; two copies of a spec elsewhere get different keys.
pub fn default_dir(spec_dir: &Path, spec_name: &str, deployment: &str) -> PathBuf {
    let state = std::env::var_os("KPL_STATE_DIR")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("XDG_STATE_HOME").filter(|v| !v.is_empty()).map(|d| PathBuf::from(d).join("kpl"))
        })
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".local/state/kpl"))
        })
        .unwrap_or_else(|| std::env::temp_dir().join("kpl-state"));
    let dir = if spec_dir.as_os_str().is_empty() { Path::new(".") } else { spec_dir };
    let path = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf()).join(format!("{spec_name}.kpl"));
    let digest = ring::digest::digest(&ring::digest::SHA256, path.to_string_lossy().as_bytes());
    let hash: String = digest.as_ref()[..8].iter().map(|b| format!("{b:02x}")).collect();
    state
        .join("keys")
        .join(format!("{}-{hash}", crate::keys::escape_chunk(spec_name)))
        .join(crate::keys::escape_chunk(deployment))
}

/// The keys of `hosts` in `dir`, made there first if `dir` does not exist yet. Several hosts
/// starting at once make them once: each makes its own in a folder beside `dir` and renames it to
/// `dir`, and a host that finds `dir` taken uses what is there.
pub fn made_on_first_use(dir: &Path, deployment: &str, hosts: &[String]) -> Result<bool, KeysError> {
    if dir.join(SECRET).is_file() {
        // Hosts added to the spec since get their files.
        make(dir, deployment, hosts)?;
        return Ok(false);
    }
    let parent = dir.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|error| KeysError::Io { path: parent.to_path_buf(), error })?;
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let draft = parent.join(format!(".{name}.{}-{:x}", std::process::id(), crate::transport::random_u64()));
    make(&draft, deployment, hosts)?;
    match std::fs::rename(&draft, dir) {
        Ok(()) => Ok(true),
        Err(_) if dir.join(SECRET).is_file() => {
            let _ = std::fs::remove_dir_all(&draft);
            make(dir, deployment, hosts)?;
            Ok(false)
        }
        Err(error) => {
            let _ = std::fs::remove_dir_all(&draft);
            Err(KeysError::Io { path: dir.to_path_buf(), error })
        }
    }
}

/// Why keys could not be made.
#[derive(Debug, thiserror::Error)]
pub enum KeysError {
    #[error("{}: {error}", .path.display())]
    Io { path: PathBuf, error: std::io::Error },
    #[error("cannot make a certificate: {0}")]
    Certificate(#[from] rcgen::Error),
    #[error("{0}")]
    Invalid(String),
}

/// What [`make`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Made {
    /// Files written.
    pub written: Vec<PathBuf>,
    /// Files that existed and were kept.
    pub kept: Vec<PathBuf>,
}

/// Makes the keys of a deployment with these hosts in `dir`: a certificate authority, a secret,
/// and a certificate and key per host. Files that exist are kept, so running it again after adding
/// a host to the spec adds that host's files (signed by the same authority).
pub fn make(dir: &Path, deployment: &str, hosts: &[String]) -> Result<Made, KeysError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| KeysError::Io { path, error }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut made = Made::default();
    let ca_path = dir.join(CA_CERTIFICATE);
    let ca_key_path = dir.join(CA_KEY);
    let (ca_pem, ca_key) = match (ca_path.exists(), ca_key_path.exists()) {
        (true, true) => {
            let pem = std::fs::read_to_string(&ca_path).map_err(io(&ca_path))?;
            let key_pem = std::fs::read_to_string(&ca_key_path).map_err(io(&ca_key_path))?;
            made.kept.extend([ca_path.clone(), ca_key_path.clone()]);
            (pem, rcgen::KeyPair::from_pem(&key_pem)?)
        }
        (false, false) => {
            let key = rcgen::KeyPair::generate()?;
            let mut params = rcgen::CertificateParams::new(Vec::<String>::new())?;
            params.distinguished_name.push(rcgen::DnType::CommonName, format!("kpl deployment {deployment}"));
            params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
            params.key_usages = vec![
                rcgen::KeyUsagePurpose::KeyCertSign,
                rcgen::KeyUsagePurpose::CrlSign,
                rcgen::KeyUsagePurpose::DigitalSignature,
            ];
            let certificate = params.self_signed(&key)?;
            write_new(&ca_key_path, &key.serialize_pem(), true, &mut made)?;
            write_new(&ca_path, &certificate.pem(), false, &mut made)?;
            (certificate.pem(), key)
        }
        _ => {
            return Err(KeysError::Invalid(format!(
                "{} has one of {CA_CERTIFICATE} and {CA_KEY} but not the other; remove it or add the missing one",
                dir.display()
            )));
        }
    };
    let issuer = rcgen::Issuer::from_ca_cert_pem(&ca_pem, ca_key)?;
    let secret_path = dir.join(SECRET);
    if secret_path.exists() {
        made.kept.push(secret_path);
    } else {
        let rng = ring::rand::SystemRandom::new();
        let bytes: [u8; 32] = ring::rand::generate(&rng)
            .map_err(|_| KeysError::Invalid("the system has no random numbers".into()))?
            .expose();
        let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        write_new(&secret_path, &(hex + "\n"), true, &mut made)?;
    }
    for host in hosts {
        let certificate_path = dir.join(certificate_file(host));
        let key_path = dir.join(key_file(host));
        if certificate_path.exists() && key_path.exists() {
            made.kept.extend([certificate_path, key_path]);
            continue;
        }
        let key = rcgen::KeyPair::generate()?;
        // The names only matter to peers that check them; kpl's hosts check the authority and the
        // common name (docs/streams.md).
        let mut params = rcgen::CertificateParams::new(vec![host.clone(), "localhost".to_string()])?;
        params.distinguished_name.push(rcgen::DnType::CommonName, host.clone());
        params.subject_alt_names.push(rcgen::SanType::IpAddress([127, 0, 0, 1].into()));
        params.extended_key_usages =
            vec![rcgen::ExtendedKeyUsagePurpose::ServerAuth, rcgen::ExtendedKeyUsagePurpose::ClientAuth];
        params.key_usages =
            vec![rcgen::KeyUsagePurpose::DigitalSignature, rcgen::KeyUsagePurpose::KeyEncipherment];
        let certificate = params.signed_by(&key, &issuer)?;
        write_new(&key_path, &key.serialize_pem(), true, &mut made)?;
        write_new(&certificate_path, &certificate.pem(), false, &mut made)?;
    }
    Ok(made)
}

/// Writes a file that must not exist yet; private ones readable by their owner only.
fn write_new(path: &Path, text: &str, private: bool, made: &mut Made) -> Result<(), KeysError> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(if private { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = private;
    let mut file = options.open(path).map_err(|error| KeysError::Io { path: path.to_path_buf(), error })?;
    file.write_all(text.as_bytes()).map_err(|error| KeysError::Io { path: path.to_path_buf(), error })?;
    made.written.push(path.to_path_buf());
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn fresh(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("kpl-keys-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn keys_are_made_once_and_hosts_added_later() {
        let dir = fresh("made");
        let made = make(&dir, "trial", &["a".into(), "b".into()]).unwrap();
        assert_eq!(made.written.len(), 7, "{made:?}");
        let a = Credentials::load(&dir, "a").unwrap();
        assert!(a.certificate.ends_with("a.pem"));
        assert!(Credentials::load(&dir, "c").unwrap_err().to_string().contains("has no c.pem"));
        let secret = std::fs::read_to_string(dir.join(SECRET)).unwrap();
        // Adding a host keeps the authority and the secret.
        let made = make(&dir, "trial", &["a".into(), "b".into(), "c".into()]).unwrap();
        assert_eq!(made.written, vec![dir.join("c.key"), dir.join("c.pem")]);
        assert_eq!(std::fs::read_to_string(dir.join(SECRET)).unwrap(), secret);
        Credentials::load(&dir, "c").unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.join("c.key")).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn keys_made_on_first_use_are_made_once_by_hosts_starting_together() {
        let dir = fresh("first-use").join("keys").join("default");
        let hosts = vec!["a".to_string(), "b".to_string()];
        let made: Vec<bool> = std::thread::scope(|scope| {
            let handles: Vec<_> =
                (0..4).map(|_| scope.spawn(|| made_on_first_use(&dir, "default", &hosts).unwrap())).collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(made.iter().filter(|m| **m).count(), 1, "{made:?}");
        Credentials::load(&dir, "b").unwrap();
        let leftovers = std::fs::read_dir(dir.parent().unwrap()).unwrap().count();
        assert_eq!(leftovers, 1, "no drafts are left beside the keys");
        std::fs::remove_dir_all(dir.parent().unwrap().parent().unwrap()).unwrap();
        let a = default_dir(Path::new("specs/zenoh"), "two_hosts", "default");
        assert!(
            a.ends_with("default") && a.to_string_lossy().contains("/keys/two_hosts-"),
            "{}",
            a.display()
        );
        assert_ne!(a, default_dir(Path::new("specs/zenoh"), "two_hosts", "other"));
        assert_ne!(a, default_dir(Path::new("specs"), "two_hosts", "default"));
    }

    #[test]
    fn secrets_are_64_hex_digits() {
        assert!(Secret::parse(&"ab".repeat(32)).is_ok());
        assert!(Secret::parse(&format!("{}\n", "0".repeat(64))).is_ok());
        assert!(Secret::parse("abc").unwrap_err().contains("64 hexadecimal"));
        assert!(Secret::parse(&"zz".repeat(32)).is_err());
        assert_eq!(format!("{:?}", Secret::from_bytes(b"k")), "Secret(..)");
    }
}
