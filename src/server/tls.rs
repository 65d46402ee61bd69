//! TLS for a daemon reachable beyond loopback: a certificate the operator gives, or one the
//! daemon makes for itself on first start and keeps in the data directory. A self-made
//! certificate is trusted by its SHA-256 fingerprint, which the daemon prints when it starts and
//! the console shows beside the token prompt: a technician compares the two once, and a client
//! ([`super::client::Client::pinned`]) checks it on every connection.
//!
//! rustls with the `ring` provider: no OpenSSL, and nothing to build but what `ring` brings.

use crate::error::{Error, Result};
use crate::image_io::{Access, atomic_write_as, create_private_dir_durably};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use std::path::Path;
use std::sync::Arc;

/// The daemon's TLS identity: what it serves with and the fingerprint clients pin.
#[derive(Clone)]
pub struct Tls {
    config: Arc<rustls::ServerConfig>,
    fingerprint: [u8; 32],
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls")
            .field("fingerprint", &self.fingerprint())
            .finish_non_exhaustive()
    }
}

/// Where a self-made certificate and its key are kept, under the data directory.
pub const DIR: &str = "tls";

impl Tls {
    /// The certificate chain (PEM, the daemon's own certificate first) and private key (PEM)
    /// the operator gives.
    pub fn from_pem(cert: &Path, key: &Path) -> Result<Tls> {
        let chain = CertificateDer::pem_file_iter(cert)
            .and_then(|certs| certs.collect::<std::result::Result<Vec<_>, _>>())
            .map_err(|e| Error::file(cert, format!("not a PEM certificate chain: {e}")))?;
        if chain.is_empty() {
            return Err(Error::file(cert, "holds no certificate"));
        }
        let key = PrivateKeyDer::from_pem_file(key)
            .map_err(|e| Error::file(key, format!("not a PEM private key: {e}")))?;
        Tls::new(chain, key)
    }

    /// The certificate kept in `dir`/tls (made there on first start, for `names`: host names
    /// and addresses clients reach the daemon by), or, without a data directory, one made for
    /// this run only.
    pub fn self_signed(dir: Option<&Path>, names: &[String]) -> Result<Tls> {
        let Some(dir) = dir else {
            let (cert, key) = make(names)?;
            return Tls::from_pem_text(&cert, &key);
        };
        let tls = dir.join(DIR);
        let (cert, key) = (tls.join("cert.pem"), tls.join("key.pem"));
        if !cert.exists() {
            create_private_dir_durably(&tls)?;
            let (cert_pem, key_pem) = make(names)?;
            // The key first, so a certificate on disk always has its key beside it.
            for (path, text) in [(&key, &key_pem), (&cert, &cert_pem)] {
                atomic_write_as(path, Access::Private, true, |f| {
                    std::io::Write::write_all(f, text.as_bytes()).map_err(|e| Error::file(path, e))
                })?;
            }
        }
        Tls::from_pem(&cert, &key)
    }

    fn from_pem_text(cert: &str, key: &str) -> Result<Tls> {
        let chain = vec![
            CertificateDer::from_pem_slice(cert.as_bytes())
                .map_err(|e| Error::invalid("tls", e.to_string()))?,
        ];
        let key = PrivateKeyDer::from_pem_slice(key.as_bytes())
            .map_err(|e| Error::invalid("tls", e.to_string()))?;
        Tls::new(chain, key)
    }

    fn new(chain: Vec<CertificateDer<'static>>, key: PrivateKeyDer<'static>) -> Result<Tls> {
        let fingerprint = sha256(&chain[0]);
        let mut config = rustls::ServerConfig::builder_with_provider(provider())
            .with_safe_default_protocol_versions()
            .and_then(|b| b.with_no_client_auth().with_single_cert(chain, key))
            .map_err(|e| Error::invalid("tls", format!("the certificate and key: {e}")))?;
        // The daemon speaks HTTP/1.1 only.
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        Ok(Tls {
            config: Arc::new(config),
            fingerprint,
        })
    }

    /// The server side, for accepting connections.
    pub fn acceptor(&self) -> tokio_rustls::TlsAcceptor {
        tokio_rustls::TlsAcceptor::from(self.config.clone())
    }

    /// The SHA-256 fingerprint of the daemon's certificate, as browsers show it:
    /// `AB:CD:…`, 32 bytes in hex.
    pub fn fingerprint(&self) -> String {
        hex_colons(&self.fingerprint)
    }
}

/// The crypto rustls runs on, chosen here once for server and client. rustls marks ring's
/// provider deprecated for lacking post-quantum key exchange, which guards recordings decrypted
/// years later; a venue's warp edits are not worth that, and aws-lc-rs, which has it, would add
/// a large C library to every build.
#[allow(deprecated)]
pub(crate) fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// SHA-256 of a certificate's DER bytes.
pub(crate) fn sha256(cert: &CertificateDer<'_>) -> [u8; 32] {
    let d = ring::digest::digest(&ring::digest::SHA256, cert.as_ref());
    d.as_ref().try_into().expect("SHA-256 is 32 bytes")
}

fn hex_colons(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

/// A fingerprint as written by [`Tls::fingerprint`] (colons and case optional).
pub fn parse_fingerprint(text: &str) -> Result<[u8; 32]> {
    let hex: String = text.chars().filter(|c| *c != ':').collect();
    let bad = || {
        Error::invalid(
            "fingerprint",
            "must be 32 bytes of hex (64 digits, colons allowed), as the daemon prints it",
        )
    };
    if hex.len() != 64 || !hex.is_ascii() {
        return Err(bad());
    }
    let mut out = [0u8; 32];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).map_err(|_| bad())?;
    }
    Ok(out)
}

/// A new self-signed certificate and key (PEM) for `names`, good for ten years: a venue's
/// daemon should not stop being trusted in the middle of a season.
fn make(names: &[String]) -> Result<(String, String)> {
    let mut params = rcgen::CertificateParams::new(names.to_vec())
        .map_err(|e| Error::invalid("tls", format!("a certificate for {names:?}: {e}")))?;
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "omniwarp daemon");
    params.not_before = rcgen::date_time_ymd(2024, 1, 1);
    params.not_after = rcgen::date_time_ymd(2036, 1, 1);
    let key = rcgen::KeyPair::generate().map_err(|e| Error::invalid("tls", e.to_string()))?;
    let cert = params
        .self_signed(&key)
        .map_err(|e| Error::invalid("tls", e.to_string()))?;
    Ok((cert.pem(), key.serialize_pem()))
}

/// Accepts exactly the certificate whose SHA-256 is `pin`, with the handshake's signatures
/// checked as usual; names and dates are not checked, since the pin names the certificate.
#[derive(Debug)]
pub(crate) struct Pinned {
    pub pin: [u8; 32],
    pub provider: Arc<rustls::crypto::CryptoProvider>,
}

impl rustls::client::danger::ServerCertVerifier for Pinned {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &rustls::pki_types::ServerName<'_>,
        _ocsp: &[u8],
        _now: rustls::pki_types::UnixTime,
    ) -> std::result::Result<rustls::client::danger::ServerCertVerified, rustls::Error> {
        if sha256(end_entity) == self.pin {
            Ok(rustls::client::danger::ServerCertVerified::assertion())
        } else {
            Err(rustls::Error::General(format!(
                "the daemon's certificate has fingerprint {}, not the pinned {}",
                hex_colons(&sha256(end_entity)),
                hex_colons(&self.pin)
            )))
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> std::result::Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> std::result::Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.provider
            .signature_verification_algorithms
            .supported_schemes()
    }
}
