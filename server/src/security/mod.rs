//! Security: TLS on every listener, who is calling, what they may do.
//!
//! | module | responsibility |
//! |---|---|
//! | [`auth`] | principals (certificate names, token digests), grants by vehicle prefix and verb |
//! | [`tls`] | the reloadable TLS acceptor for gRPC and HTTP; peer certificate names |
//! | [`zenoh`] | Zenoh over mutual TLS and its access-control rules, derived from the same grants |
//! | [`refusals`] | the refusal counters, resolved once per label set (a refusal allocates nothing) |
//! | here | the `[security]` configuration, the startup exposure check, the metrics |
//!
//! The rule at startup ([`exposure`]): a listener without TLS is allowed on loopback only,
//! unless the operator sets `security.insecure` (`--insecure`), and then the service says so
//! loudly. Authorization is on as soon as one principal is configured, and then denies
//! everything not granted.

pub mod auth;
pub mod refusals;
pub mod tls;
pub mod zenoh;

use std::net::SocketAddr;
use std::path::PathBuf;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::registry::Registry;
use serde::Deserialize;
use uavnav_proto::net::is_loopback_host;

pub use auth::{Access, AuthError, Authorizer, Grant, PrincipalConfig, Verb};
pub use refusals::{ANONYMOUS, Refusals};
pub use tls::{CertStore, PeerInfo, TlsError};

/// `[security]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct SecurityConfig {
    /// Allow listeners without TLS on non-loopback addresses (said loudly at startup).
    pub insecure: bool,
    /// TLS for gRPC, HTTP and Zenoh; absent = plaintext (loopback only unless `insecure`).
    pub tls: Option<TlsConfig>,
    /// Ground stations and drones allowed in; empty = authorization off.
    pub principals: Vec<PrincipalConfig>,
}

/// `[security.tls]`: the service's certificate and the CA its clients' certificates come from.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// PEM certificate chain of the service (leaf first).
    pub certificate: PathBuf,
    /// PEM private key of the service.
    pub private_key: PathBuf,
    /// PEM CA certificate(s) that client certificates must chain to (mutual TLS). Required for
    /// Zenoh, where every peer must present a certificate.
    #[serde(default)]
    pub client_ca: Option<PathBuf>,
    /// gRPC and HTTP: refuse connections without a client certificate (else a bearer token may
    /// identify the caller instead).
    #[serde(default)]
    pub require_client_certificate: bool,
    /// How often the files are checked for changes, s (new connections use new certificates;
    /// Zenoh reads them at startup only).
    #[serde(default = "default_reload_s")]
    pub reload_s: f64,
}

fn default_reload_s() -> f64 {
    10.0
}

/// The transport a caller came by (the `transport` label of `uavnav_auth_refused_total`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AuthTransport {
    /// gRPC.
    Grpc,
    /// Zenoh.
    Zenoh,
    /// HTTP (`/metrics`).
    Http,
}

impl AuthTransport {
    /// Every transport, in declaration order (`t as usize` indexes this).
    pub const ALL: [AuthTransport; 3] = [Self::Grpc, Self::Zenoh, Self::Http];

    /// The label.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Grpc => "grpc",
            Self::Zenoh => "zenoh",
            Self::Http => "http",
        }
    }
}

impl From<crate::metrics::Transport> for AuthTransport {
    fn from(t: crate::metrics::Transport) -> Self {
        match t {
            crate::metrics::Transport::Grpc => Self::Grpc,
            crate::metrics::Transport::Zenoh => Self::Zenoh,
        }
    }
}

/// Labels of `uavnav_auth_refused_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct AuthLabels {
    /// `grpc`, `zenoh`, `http` ([`AuthTransport`]).
    pub transport: &'static str,
    /// The principal's configured name, or `anonymous`.
    pub principal: String,
    /// `unauthenticated` reasons (`bad_token`...) or `permission_denied`.
    pub reason: &'static str,
    /// The verb refused (`-` when the caller was not recognised).
    pub verb: &'static str,
}

/// Labels of `uavnav_tls_failures_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct TlsLabels {
    /// Why the connection failed.
    pub reason: &'static str,
}

/// Failed TLS connections, by reason.
#[derive(Debug, Clone, Default)]
pub struct TlsFailures(Family<TlsLabels, Counter>);

impl TlsFailures {
    /// Counts one failure.
    pub fn inc(&self, reason: &'static str) {
        self.0.get_or_create(&TlsLabels { reason }).inc();
    }

    /// The count for `reason`.
    pub fn get(&self, reason: &'static str) -> u64 {
        self.0.get_or_create(&TlsLabels { reason }).get()
    }
}

/// Security metrics.
#[derive(Debug, Clone, Default)]
pub struct SecurityMetrics {
    /// Callers refused: not recognised, or not granted the verb on the vehicle.
    pub auth_refused: Family<AuthLabels, Counter>,
    /// TLS connections that failed (handshake, expired or untrusted certificate, not TLS).
    pub tls_failures: TlsFailures,
    /// Certificate reloads that failed (the previous certificates stay in use).
    pub tls_reload_failures: Counter,
}

impl SecurityMetrics {
    /// Creates and registers the metrics.
    pub fn register(registry: &mut Registry) -> Self {
        let m = Self::default();
        registry.register(
            "auth_refused",
            "Callers refused, by transport, principal, reason (unauthenticated causes or permission_denied) and verb",
            m.auth_refused.clone(),
        );
        registry.register(
            "tls_failures",
            "TLS connections that failed, by reason",
            m.tls_failures.0.clone(),
        );
        registry.register(
            "tls_reload_failures",
            "Certificate reloads that failed (the previous certificates stay in use)",
            m.tls_reload_failures.clone(),
        );
        m
    }

    /// The number of refusals with these labels (a lookup: for tests and tools, not the hot
    /// path, which counts through [`Refusals`]).
    pub fn refused_count(
        &self,
        transport: &'static str,
        principal: &str,
        reason: &'static str,
        verb: Option<Verb>,
    ) -> u64 {
        self.auth_refused
            .get_or_create(&AuthLabels {
                transport,
                principal: principal.to_owned(),
                reason,
                verb: verb.map_or("-", Verb::as_str),
            })
            .get()
    }
}

/// A listener and whether it is encrypted.
#[derive(Debug, Clone, PartialEq)]
pub struct Listener {
    /// What it is (`grpc.addr`...).
    pub what: String,
    /// Its address as configured.
    pub addr: String,
    /// Whether it is on loopback only.
    pub loopback: bool,
    /// Whether it speaks TLS.
    pub tls: bool,
}

/// The host of a Zenoh locator `proto/HOST:PORT[?…][#…]`.
pub fn zenoh_locator_host(locator: &str) -> Option<(&str, &str)> {
    let (proto, rest) = locator.split_once('/')?;
    let addr = rest.split(['?', '#']).next()?;
    let (host, _port) = addr.rsplit_once(':')?;
    Some((proto, host))
}

/// What the service would expose with `config`: every listener (and Zenoh connection) with
/// whether it is loopback and encrypted.
pub fn listeners(config: &crate::Config) -> Vec<Listener> {
    let tls = config.security.tls.is_some();
    let sock = |what: &str, a: SocketAddr| Listener {
        what: what.into(),
        addr: a.to_string(),
        loopback: a.ip().is_loopback(),
        tls,
    };
    let mut out = vec![
        sock("grpc.addr", config.grpc.addr),
        sock("http.addr", config.http.addr),
    ];
    if config.zenoh.enabled {
        let z = |what: &str, l: &String| {
            let (proto, host) = zenoh_locator_host(l).unwrap_or(("?", ""));
            Listener {
                what: what.into(),
                addr: l.clone(),
                loopback: is_loopback_host(host),
                tls: proto == "tls",
            }
        };
        out.extend(config.zenoh.listen.iter().map(|l| z("zenoh.listen", l)));
        out.extend(config.zenoh.connect.iter().map(|l| z("zenoh.connect", l)));
    }
    if let Some(a) = &config.foxglove.addr {
        let host = a.rsplit_once(':').map_or(a.as_str(), |(h, _)| h);
        out.push(Listener {
            what: "foxglove.addr".into(),
            addr: a.clone(),
            loopback: is_loopback_host(host),
            tls: false,
        });
    }
    out
}

/// The startup check: refuses a plaintext listener off loopback unless `insecure`, and returns
/// the warnings to log loudly (insecure listeners, authorization off on a network).
pub fn exposure(config: &crate::Config) -> Result<Vec<String>, String> {
    let sec = &config.security;
    let all = listeners(config);
    let exposed: Vec<&Listener> = all.iter().filter(|l| !l.loopback && !l.tls).collect();
    if !exposed.is_empty() && !sec.insecure {
        let names: Vec<String> = exposed
            .iter()
            .map(|l| format!("{} {}", l.what, l.addr))
            .collect();
        return Err(format!(
            "{} would carry traffic in clear off loopback; configure [security.tls] (and tls/ \
             Zenoh locators), use 127.0.0.1, or accept the risk with security.insecure = true \
             (--insecure)",
            names.join(", ")
        ));
    }
    let mut warnings: Vec<String> = exposed
        .iter()
        .map(|l| {
            format!(
                "INSECURE: {} {} serves without TLS off loopback (security.insecure)",
                l.what, l.addr
            )
        })
        .collect();
    if config.zenoh.enabled
        && sec.tls.is_some()
        && sec.tls.as_ref().is_some_and(|t| t.client_ca.is_none())
    {
        return Err(
            "security.tls.client_ca is required with Zenoh: every Zenoh peer must present a \
             certificate (mutual TLS)"
                .into(),
        );
    }
    if sec.principals.is_empty() && all.iter().any(|l| !l.loopback) {
        warnings.push(
            "authorization is off (no [[security.principals]]): anyone who reaches the service \
             may feed, configure, reset and watch every vehicle"
                .into(),
        );
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transports_index_their_table() {
        for (i, t) in AuthTransport::ALL.into_iter().enumerate() {
            assert_eq!(t as usize, i, "{t:?}");
        }
    }

    #[test]
    fn plaintext_is_loopback_only_unless_insecure() {
        let mut c = crate::Config::default();
        assert!(exposure(&c).is_ok(), "the defaults are loopback");
        c.grpc.addr = "0.0.0.0:50051".parse().expect("addr");
        let e = exposure(&c).expect_err("plaintext gRPC on every interface");
        assert!(e.contains("grpc.addr 0.0.0.0:50051"), "{e}");
        c.security.insecure = true;
        let w = exposure(&c).expect("insecure accepted");
        assert!(
            w.iter().any(|w| w.starts_with("INSECURE: grpc.addr")),
            "{w:?}"
        );
        assert!(
            w.iter().any(|w| w.contains("authorization is off")),
            "{w:?}"
        );
        c.security.insecure = false;
        c.grpc.addr = "127.0.0.1:50051".parse().expect("addr");
        c.zenoh.listen = vec!["tcp/[::]:7447".into()];
        assert!(
            exposure(&c)
                .expect_err("zenoh tcp")
                .contains("zenoh.listen")
        );
        c.zenoh.listen = vec!["tcp/[::1]:7447".into(), "tcp/localhost:7448".into()];
        assert!(exposure(&c).is_ok());
    }
}
