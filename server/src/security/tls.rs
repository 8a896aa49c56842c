//! The service's own TLS acceptor, shared by gRPC and HTTP.
//!
//! Why not tonic's built-in TLS: certificates must be reloadable without a restart (an operator
//! rotates them while drones fly), the verified client certificate's names are the caller's
//! identity, and a handshake that never finishes must not hold the accept loop. So: one
//! [`CertStore`] that re-reads the files when they change, and [`handshake`], which the
//! connection layer ([`crate::transport::conn`]) runs in a task of its own per connection
//! (bounded in number by [`MAX_HANDSHAKES`] and in time by [`HANDSHAKE_TIMEOUT`]); the finished
//! connection carries the peer's names as [`PeerInfo`].

use std::io;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};
use std::time::{Duration, SystemTime};

use rustls::RootCertStore;
use rustls::server::WebPkiClientVerifier;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use tokio::net::TcpStream;
use tracing::{debug, info, warn};

use super::TlsConfig;

/// Handshakes in progress at once on one listener; beyond, new connections wait in the kernel's
/// accept queue (a slowloris of half-open handshakes cannot take every file descriptor).
pub const MAX_HANDSHAKES: usize = 256;
/// Time a client has to finish its TLS handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// A failure loading certificates or keys.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A file could not be read or parsed.
    #[error("security.tls.{field} {path}: {message}")]
    File {
        /// The configuration key.
        field: &'static str,
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// rustls refused the combination (e.g. the key does not match the certificate).
    #[error("security.tls: {0}")]
    Rustls(String),
}

/// Who is at the other end of a connection.
#[derive(Debug, Clone, Default)]
pub struct PeerInfo {
    /// The remote address.
    pub remote: Option<SocketAddr>,
    /// The verified client certificate's common names and DNS names (empty: no certificate).
    pub cert_names: Arc<[String]>,
}

/// The current server configurations (one per ALPN set), replaced when the files change.
#[derive(Debug)]
pub struct CertStore {
    settings: TlsConfig,
    current: RwLock<Loaded>,
}

#[derive(Debug, Clone)]
struct Loaded {
    grpc: Arc<rustls::ServerConfig>,
    http: Arc<rustls::ServerConfig>,
    stamps: Vec<Option<SystemTime>>,
}

impl CertStore {
    /// Loads the certificate, key and client CA named in `settings`.
    pub fn load(settings: &TlsConfig) -> Result<Arc<Self>, TlsError> {
        let loaded = load(settings)?;
        Ok(Arc::new(Self {
            settings: settings.clone(),
            current: RwLock::new(loaded),
        }))
    }

    fn grpc(&self) -> Arc<rustls::ServerConfig> {
        Arc::clone(&self.read().grpc)
    }

    fn http(&self) -> Arc<rustls::ServerConfig> {
        Arc::clone(&self.read().http)
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, Loaded> {
        self.current.read().unwrap_or_else(|e| e.into_inner())
    }

    /// Re-reads the files if any changed; a failed reload keeps the previous certificates.
    /// Returns whether new certificates are in use.
    pub fn reload_if_changed(&self) -> Result<bool, TlsError> {
        let stamps = stamps(&self.settings);
        if stamps == self.read().stamps {
            return Ok(false);
        }
        let loaded = load(&self.settings)?;
        *self.current.write().unwrap_or_else(|e| e.into_inner()) = loaded;
        Ok(true)
    }

    /// Watches the files every `reload_s` seconds until `stop` fires.
    pub fn spawn_reloader(
        self: &Arc<Self>,
        mut stop: tokio::sync::watch::Receiver<bool>,
        failures: prometheus_client::metrics::counter::Counter,
    ) {
        let period = Duration::from_secs_f64(self.settings.reload_s.max(0.1));
        let store = Arc::clone(self);
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = tokio::time::sleep(period) => {}
                    _ = stop.wait_for(|s| *s) => break,
                }
                match store.reload_if_changed() {
                    Ok(true) => info!("TLS certificates reloaded"),
                    Ok(false) => {}
                    Err(e) => {
                        failures.inc();
                        warn!(error = %e, "TLS certificates changed but do not load; the previous ones stay in use");
                    }
                }
            }
        });
    }
}

fn stamps(s: &TlsConfig) -> Vec<Option<SystemTime>> {
    [
        Some(&s.certificate),
        Some(&s.private_key),
        s.client_ca.as_ref(),
    ]
    .into_iter()
    .map(|p| p.and_then(|p| std::fs::metadata(p).and_then(|m| m.modified()).ok()))
    .collect()
}

fn file_err(field: &'static str, path: &Path, message: impl ToString) -> TlsError {
    TlsError::File {
        field,
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

fn certs(field: &'static str, path: &Path) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let certs = CertificateDer::pem_file_iter(path)
        .map_err(|e| file_err(field, path, e))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| file_err(field, path, e))?;
    if certs.is_empty() {
        return Err(file_err(field, path, "no PEM certificate in the file"));
    }
    Ok(certs)
}

fn load(s: &TlsConfig) -> Result<Loaded, TlsError> {
    let stamps = stamps(s);
    let chain = certs("certificate", &s.certificate)?;
    let key = PrivateKeyDer::from_pem_file(&s.private_key)
        .map_err(|e| file_err("private_key", &s.private_key, e))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = rustls::ServerConfig::builder_with_provider(Arc::clone(&provider))
        .with_safe_default_protocol_versions()
        .map_err(|e| TlsError::Rustls(e.to_string()))?;
    let builder = match &s.client_ca {
        Some(ca) => {
            let mut roots = RootCertStore::empty();
            for c in certs("client_ca", ca)? {
                roots.add(c).map_err(|e| file_err("client_ca", ca, e))?;
            }
            let verifier = WebPkiClientVerifier::builder_with_provider(Arc::new(roots), provider);
            let verifier = if s.require_client_certificate {
                verifier
            } else {
                verifier.allow_unauthenticated()
            };
            builder.with_client_cert_verifier(
                verifier
                    .build()
                    .map_err(|e| TlsError::Rustls(e.to_string()))?,
            )
        }
        None => builder.with_no_client_auth(),
    };
    let mut grpc = builder
        .with_single_cert(chain, key)
        .map_err(|e| TlsError::Rustls(format!("certificate and private_key: {e}")))?;
    let mut http = grpc.clone();
    grpc.alpn_protocols = vec![b"h2".to_vec()];
    http.alpn_protocols = vec![b"h2".to_vec(), b"http/1.1".to_vec()];
    Ok(Loaded {
        grpc: Arc::new(grpc),
        http: Arc::new(http),
        stamps,
    })
}

/// The names a client certificate proves: its subject's common names and its DNS
/// subject-alternative names.
pub fn certificate_names(der: &[u8]) -> Vec<String> {
    let Ok((_, cert)) = x509_parser::parse_x509_certificate(der) else {
        return Vec::new();
    };
    let mut names: Vec<String> = cert
        .subject()
        .iter_common_name()
        .filter_map(|cn| cn.as_str().ok().map(str::to_owned))
        .collect();
    if let Ok(Some(san)) = cert.subject_alternative_name() {
        for n in &san.value.general_names {
            if let x509_parser::extensions::GeneralName::DNSName(d) = n {
                names.push((*d).to_owned());
            }
        }
    }
    names
}

/// Which of the two protocol sets a listener speaks.
#[derive(Debug, Clone, Copy)]
pub enum Alpn {
    /// HTTP/2 only (gRPC).
    Grpc,
    /// HTTP/1.1 or HTTP/2 (metrics and probes).
    Http,
}

/// Runs the TLS handshake of an accepted connection (at most [`HANDSHAKE_TIMEOUT`]) and reads
/// the verified client certificate's names. `Err` is the metrics label of the failure
/// (`uavnav_tls_failures_total`), already logged at debug level.
pub async fn handshake(
    store: &CertStore,
    alpn: Alpn,
    tcp: TcpStream,
    remote: SocketAddr,
) -> Result<(tokio_rustls::server::TlsStream<TcpStream>, Arc<[String]>), &'static str> {
    let config = match alpn {
        Alpn::Grpc => store.grpc(),
        Alpn::Http => store.http(),
    };
    let acceptor = tokio_rustls::TlsAcceptor::from(config);
    let stream = match tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(tcp)).await {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => {
            debug!(%remote, error = %e, "TLS handshake failed");
            return Err(handshake_reason(&e));
        }
        Err(_) => {
            debug!(%remote, "TLS handshake timed out");
            return Err("timeout");
        }
    };
    let cert_names: Vec<String> = stream
        .get_ref()
        .1
        .peer_certificates()
        .and_then(|c| c.first())
        .map(|c| certificate_names(c))
        .unwrap_or_default();
    Ok((stream, cert_names.into()))
}

/// A metrics label for a failed handshake.
fn handshake_reason(e: &io::Error) -> &'static str {
    let text = e.to_string();
    if text.contains("Expired") || text.contains("expired") {
        "expired_certificate"
    } else if text.contains("UnknownIssuer") || text.contains("BadSignature") {
        "untrusted_certificate"
    } else if text.contains("NoCertificatesPresented") || text.contains("peer sent no certificates")
    {
        "no_client_certificate"
    } else if text.contains("InvalidContentType")
        || text.contains("corrupt message")
        || text.contains("received corrupt")
    {
        "not_tls"
    } else {
        "handshake"
    }
}
