//! TLS and bearer tokens: how a client proves who it is and checks that it talks to the service.
//!
//! - [`TlsOptions`]: the CA that signed the service certificate, optionally a client certificate
//!   and key (mutual TLS), and the name expected in the service certificate.
//! - gRPC (`grpcs://HOST:PORT`): [`grpc_tls_config`] builds tonic's rustls configuration; the
//!   bearer token rides on every request through [`AuthInterceptor`], installed once on the
//!   generated client, so no call site (unary, watch, ingest, reconnection) can forget it.
//! - Zenoh (`tls/HOST:PORT` locators): [`zenoh_tls`] sets the link's TLS keys (root CA, client
//!   certificate, mutual TLS, name verification) and closes what a TLS client does not need (the
//!   admin space, multicast scouting, the plaintext ephemeral listener). Zenoh authenticates by
//!   certificate only: a token is not sent over Zenoh.
//! - [`check_token_transport`]: a token in clear over a network is a leak, so a token on a
//!   plaintext `grpc://` endpoint is refused unless the host is loopback or the caller opted in
//!   with `allow_insecure_token`.

use std::path::{Path, PathBuf};

use tonic::metadata::{Ascii, MetadataValue};
use tonic::transport::{Certificate, ClientTlsConfig, Identity};
use uavnav_proto::net::is_loopback_host;

use crate::error::ClientError;

/// TLS settings of a connection.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TlsOptions {
    /// PEM file of the CA that signed the service certificate (the only trusted root).
    pub ca_pem: PathBuf,
    /// PEM file of this client's certificate (mutual TLS); needs `key_pem`.
    pub cert_pem: Option<PathBuf>,
    /// PEM file of this client's private key; needs `cert_pem`.
    pub key_pem: Option<PathBuf>,
    /// Name expected in the service certificate (default: the URL's host). gRPC only: Zenoh
    /// checks the locator's host, so give it a locator with the certificate's name.
    pub domain: Option<String>,
}

impl TlsOptions {
    /// Trust `ca_pem`, no client certificate.
    pub fn with_ca(ca_pem: impl Into<PathBuf>) -> Self {
        Self {
            ca_pem: ca_pem.into(),
            ..Self::default()
        }
    }

    /// Adds a client certificate and its key (mutual TLS).
    pub fn with_identity(
        mut self,
        cert_pem: impl Into<PathBuf>,
        key_pem: impl Into<PathBuf>,
    ) -> Self {
        self.cert_pem = Some(cert_pem.into());
        self.key_pem = Some(key_pem.into());
        self
    }

    /// The client certificate and key, both or neither (one without the other is a mistake that
    /// would otherwise silently connect without mutual TLS).
    fn identity_paths(&self) -> Result<Option<(&Path, &Path)>, ClientError> {
        match (&self.cert_pem, &self.key_pem) {
            (Some(c), Some(k)) => Ok(Some((c.as_path(), k.as_path()))),
            (None, None) => Ok(None),
            (Some(_), None) => Err(tls_err("a client certificate was given without its key")),
            (None, Some(_)) => Err(tls_err("a client key was given without its certificate")),
        }
    }
}

fn tls_err(reason: impl Into<String>) -> ClientError {
    ClientError::Tls {
        reason: reason.into(),
    }
}

/// Reads a PEM file, checking that it holds a PEM block (a wrong path or a DER file is reported
/// here, not as an obscure handshake failure later).
fn read_pem(path: &Path, what: &str) -> Result<Vec<u8>, ClientError> {
    let bytes = std::fs::read(path)
        .map_err(|e| tls_err(format!("cannot read the {what} {}: {e}", path.display())))?;
    if !bytes.windows(11).any(|w| w == b"-----BEGIN ") {
        return Err(tls_err(format!(
            "the {what} {} is not a PEM file",
            path.display()
        )));
    }
    Ok(bytes)
}

/// tonic's TLS configuration for `tls` (the CA as the only root, the client identity, the
/// expected name).
pub fn grpc_tls_config(tls: &TlsOptions) -> Result<ClientTlsConfig, ClientError> {
    let ca = read_pem(&tls.ca_pem, "CA certificate")?;
    let mut cfg = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca));
    if let Some((cert, key)) = tls.identity_paths()? {
        let cert = read_pem(cert, "client certificate")?;
        let key = read_pem(key, "client key")?;
        cfg = cfg.identity(Identity::from_pem(cert, key));
    }
    if let Some(d) = &tls.domain {
        cfg = cfg.domain_name(d.clone());
    }
    Ok(cfg)
}

/// Adds `authorization: Bearer <token>` to every gRPC request (nothing without a token).
#[derive(Clone, Default)]
pub struct AuthInterceptor {
    header: Option<MetadataValue<Ascii>>,
}

impl std::fmt::Debug for AuthInterceptor {
    // The header is a secret: never in logs.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AuthInterceptor")
            .field("token", &self.header.as_ref().map(|_| "<redacted>"))
            .finish()
    }
}

impl AuthInterceptor {
    /// An interceptor sending `token` (refused if it is empty or not visible ASCII, which a
    /// header cannot carry).
    pub fn new(token: Option<&str>) -> Result<Self, ClientError> {
        let Some(token) = token else {
            return Ok(Self::default());
        };
        let token = token.trim();
        if token.is_empty() {
            return Err(ClientError::Token {
                reason: "the token is empty".into(),
            });
        }
        if !token.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(ClientError::Token {
                reason: "the token must be visible ASCII characters without spaces".into(),
            });
        }
        let header = format!("Bearer {token}")
            .parse::<MetadataValue<Ascii>>()
            .map_err(|_| ClientError::Token {
                reason: "the token is not a valid header value".into(),
            })?;
        Ok(Self {
            header: Some(header),
        })
    }
}

impl tonic::service::Interceptor for AuthInterceptor {
    fn call(&mut self, mut req: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(h) = &self.header {
            req.metadata_mut().insert("authorization", h.clone());
        }
        Ok(req)
    }
}

/// The host of `grpc://HOST:PORT` / `http(s)://HOST:PORT` (brackets of an IPv6 address removed).
pub fn uri_host(uri: &str) -> &str {
    let rest = uri.split_once("://").map_or(uri, |(_, r)| r);
    let rest = rest.trim_end_matches('/');
    let host = rest.rsplit_once(':').map_or(rest, |(h, _)| h);
    host.trim_start_matches('[').trim_end_matches(']')
}

/// Refuses a token sent in clear to another machine (plaintext `grpc://` to a non-loopback host)
/// unless `allow_insecure` says the operator accepts it.
pub fn check_token_transport(
    uri: &str,
    tls: bool,
    token: Option<&str>,
    allow_insecure: bool,
) -> Result<(), ClientError> {
    if token.is_none() || tls || allow_insecure || is_loopback_host(uri_host(uri)) {
        return Ok(());
    }
    Err(ClientError::InsecureToken {
        endpoint: uri.replacen("http://", "grpc://", 1),
    })
}

/// Sets the Zenoh TLS link keys of `tls` on `z`, and turns off what a TLS client must not expose.
#[cfg(feature = "zenoh")]
pub fn zenoh_tls(z: &mut zenoh::Config, tls: &TlsOptions) -> Result<(), ClientError> {
    let path = |p: &Path| -> Result<String, ClientError> {
        // Checked here: Zenoh reports a missing file only as a failed link, much later.
        read_pem(p, "PEM file")?;
        let s = p
            .to_str()
            .ok_or_else(|| tls_err(format!("{} is not a UTF-8 path", p.display())))?;
        Ok(uavnav_proto::keys::json_string(s))
    };
    let mut set = |key: &str, value: String| {
        z.insert_json5(key, &value)
            .map_err(|e| tls_err(format!("zenoh config {key}={value}: {e}")))
    };
    set("transport/link/tls/root_ca_certificate", path(&tls.ca_pem)?)?;
    if let Some((cert, key)) = tls.identity_paths()? {
        set("transport/link/tls/connect_certificate", path(cert)?)?;
        set("transport/link/tls/connect_private_key", path(key)?)?;
        set("transport/link/tls/enable_mtls", "true".into())?;
    }
    set("transport/link/tls/verify_name_on_connect", "true".into())?;
    // The service closes links whose certificate expired; so does this end.
    set("transport/link/tls/close_link_on_expiration", "true".into())?;
    // Nothing to discover or to serve: no multicast scouting, no admin space, and no listener (a
    // peer's default ephemeral listener is plaintext TCP on every interface).
    set("scouting/multicast/enabled", "false".into())?;
    set("adminspace/enabled", "false".into())?;
    set("listen/endpoints", "[]".into())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uri_hosts() {
        assert_eq!(uri_host("http://127.0.0.1:50051"), "127.0.0.1");
        assert_eq!(uri_host("https://[::1]:1"), "::1");
        assert_eq!(uri_host("http://gs.example:1/"), "gs.example");
    }

    #[test]
    fn a_token_in_clear_leaves_loopback_only_when_allowed() {
        let t = Some("s3cret");
        assert!(check_token_transport("http://127.0.0.1:1", false, t, false).is_ok());
        assert!(check_token_transport("https://uavnavd:1", true, t, false).is_ok());
        assert!(check_token_transport("http://uavnavd:1", false, None, false).is_ok());
        assert!(check_token_transport("http://uavnavd:1", false, t, true).is_ok());
        let e = check_token_transport("http://uavnavd:1", false, t, false).unwrap_err();
        assert!(e.to_string().contains("grpcs://"), "{e}");
    }

    #[test]
    fn the_interceptor_sends_the_bearer_token_and_hides_it() {
        use tonic::service::Interceptor;
        let mut i = AuthInterceptor::new(Some(" abc123\n")).unwrap();
        let req = i.call(tonic::Request::new(())).unwrap();
        assert_eq!(
            req.metadata().get("authorization").unwrap(),
            "Bearer abc123"
        );
        assert!(!format!("{i:?}").contains("abc123"));
        let mut none = AuthInterceptor::new(None).unwrap();
        assert!(
            none.call(tonic::Request::new(()))
                .unwrap()
                .metadata()
                .is_empty()
        );
        assert!(AuthInterceptor::new(Some("a b")).is_err());
        assert!(AuthInterceptor::new(Some("  ")).is_err());
    }
}
