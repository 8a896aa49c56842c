//! Who is calling, and what they may do.
//!
//! A *principal* is a ground station (or a drone's link) named in the configuration. It is
//! recognised by its client certificate's name (common name or DNS subject-alternative name,
//! verified by the TLS layer against the configured CA) or by a bearer token, stored only as its
//! SHA-256 and compared in constant time. Each principal has *grants*: a vehicle-id prefix (its
//! fleet; `""` = every vehicle) and the verbs it may use on those vehicles. Everything not granted
//! is denied.
//!
//! With no principal configured, authorization is off ([`Access::Open`]): every caller may do
//! everything. The service allows that only on loopback or when the operator says `insecure`
//! (see [`super::exposure`]).

use std::collections::HashMap;
use std::sync::Arc;

use serde::Deserialize;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// What a caller does to a vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verb {
    /// Send sensor data (IMU, GNSS, magnetometer, barometer, camera).
    Feed,
    /// Watch poses and health, get the latest pose.
    Watch,
    /// Configure a vehicle (also a configuration sent inside an ingest stream).
    Configure,
    /// Reset a vehicle's filter.
    Reset,
    /// List vehicles (only those granted are shown).
    List,
    /// Read `/metrics` (not per vehicle: needs a grant whatever its prefix).
    Metrics,
}

impl Verb {
    /// Every verb, in declaration order (`verb as usize` indexes this).
    pub const ALL: [Verb; 6] = [
        Verb::Feed,
        Verb::Watch,
        Verb::Configure,
        Verb::Reset,
        Verb::List,
        Verb::Metrics,
    ];

    /// The verb's name in configuration, metrics and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Verb::Feed => "feed",
            Verb::Watch => "watch",
            Verb::Configure => "configure",
            Verb::Reset => "reset",
            Verb::List => "list",
            Verb::Metrics => "metrics",
        }
    }
}

/// One grant: these verbs on the vehicles whose id starts with `vehicles`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grant {
    /// Vehicle-id prefix (a fleet, e.g. `"alpha-"`); `""` = every vehicle.
    pub vehicles: String,
    /// Allowed verbs.
    pub verbs: Vec<Verb>,
}

/// A principal as configured (`[[security.principals]]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrincipalConfig {
    /// Name shown in logs and metrics.
    pub name: String,
    /// Client-certificate names (CN or DNS SAN) that identify this principal.
    #[serde(default)]
    pub certificate_names: Vec<String>,
    /// Hex SHA-256 digests of this principal's bearer tokens (`uavnav certs token` prints one).
    #[serde(default)]
    pub token_sha256: Vec<String>,
    /// What it may do.
    #[serde(default)]
    pub grants: Vec<Grant>,
}

/// A recognised principal.
#[derive(Debug, Clone, PartialEq)]
pub struct Principal {
    /// Its configured name.
    pub name: Arc<str>,
    /// Its position in the authorizer (the refusal counters are kept by it).
    index: usize,
    grants: Vec<Grant>,
}

impl Principal {
    /// Whether it may do `verb` to `vehicle_id`, or to every vehicle whose id starts with
    /// `vehicle_id` when that is a prefix (a watch by prefix; `""`: every vehicle): either way
    /// some grant's prefix must be a prefix of it.
    pub fn allows(&self, verb: Verb, vehicle_id: &str) -> bool {
        self.grants
            .iter()
            .any(|g| g.verbs.contains(&verb) && vehicle_id.starts_with(&g.vehicles))
    }

    /// Its position among the authorizer's principals.
    pub fn index(&self) -> usize {
        self.index
    }

    /// Its grants.
    pub fn grants(&self) -> &[Grant] {
        &self.grants
    }
}

/// What a caller may do: everything (authorization off), or what a principal was granted.
#[derive(Debug, Clone, PartialEq)]
pub enum Access {
    /// Authorization is off (no principal configured).
    Open,
    /// An authenticated principal.
    Principal(Arc<Principal>),
}

impl Access {
    /// Whether `verb` on `vehicle_id` (or on every vehicle under that prefix) is allowed.
    pub fn allows(&self, verb: Verb, vehicle_id: &str) -> bool {
        match self {
            Access::Open => true,
            Access::Principal(p) => p.allows(verb, vehicle_id),
        }
    }

    /// The principal's name for metrics and logs (`"open"` when authorization is off).
    pub fn name(&self) -> &str {
        match self {
            Access::Open => "open",
            Access::Principal(p) => &p.name,
        }
    }
}

/// Why a caller was not recognised.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AuthError {
    /// No certificate name and no token.
    #[error("no credentials: present a client certificate or an `authorization: Bearer` token")]
    NoCredentials,
    /// A token that matches no principal.
    #[error("the bearer token is not recognised")]
    BadToken,
    /// A malformed `authorization` value.
    #[error("malformed authorization metadata (expected `Bearer <token>`)")]
    MalformedToken,
    /// A verified certificate whose names match no principal.
    #[error("client certificate {0:?} names no configured principal")]
    UnknownCertificate(String),
    /// A certificate and a token naming two different principals.
    #[error("client certificate and token name different principals ({cert} and {token})")]
    Conflict {
        /// Principal of the certificate.
        cert: String,
        /// Principal of the token.
        token: String,
    },
}

impl AuthError {
    /// Short reason label for metrics.
    pub fn label(&self) -> &'static str {
        match self {
            AuthError::NoCredentials => "no_credentials",
            AuthError::BadToken => "bad_token",
            AuthError::MalformedToken => "malformed_token",
            AuthError::UnknownCertificate(_) => "unknown_certificate",
            AuthError::Conflict { .. } => "conflicting_credentials",
        }
    }
}

/// A configuration error in `[[security.principals]]`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("security.principals[{index}] ({name:?}): {message}")]
pub struct PrincipalError {
    /// Position in the list.
    pub index: usize,
    /// Its name.
    pub name: String,
    /// What is wrong.
    pub message: String,
}

/// Recognises callers and answers what they may do.
#[derive(Debug, Default)]
pub struct Authorizer {
    principals: Vec<Arc<Principal>>,
    by_cert_name: HashMap<String, usize>,
    /// (digest, principal index) for every configured token.
    tokens: Vec<([u8; 32], usize)>,
}

impl Authorizer {
    /// Builds the authorizer; refuses duplicate names, malformed digests, bad prefixes and
    /// principals that can never be recognised.
    pub fn new(configs: &[PrincipalConfig]) -> Result<Self, PrincipalError> {
        let mut out = Self::default();
        for (index, c) in configs.iter().enumerate() {
            let err = |message: String| PrincipalError {
                index,
                name: c.name.clone(),
                message,
            };
            if c.name.is_empty() || out.principals.iter().any(|p| *p.name == *c.name) {
                return Err(err("name: empty or used twice".into()));
            }
            if c.certificate_names.is_empty() && c.token_sha256.is_empty() {
                return Err(err(
                    "needs certificate_names or token_sha256 to be recognised".into(),
                ));
            }
            for g in &c.grants {
                if let Some(ch) = g
                    .vehicles
                    .chars()
                    .find(|ch| !(ch.is_ascii_alphanumeric() || matches!(ch, '_' | '.' | '-')))
                {
                    return Err(err(format!(
                        "grants.vehicles {:?}: character {ch:?} is not in a vehicle id",
                        g.vehicles
                    )));
                }
                if g.verbs.is_empty() {
                    return Err(err(format!("grants.vehicles {:?}: no verbs", g.vehicles)));
                }
            }
            for n in &c.certificate_names {
                if out.by_cert_name.insert(n.clone(), index).is_some() {
                    return Err(err(format!(
                        "certificate name {n:?} belongs to two principals"
                    )));
                }
            }
            for h in &c.token_sha256 {
                let digest = hex::decode(h.trim())
                    .ok()
                    .and_then(|v| <[u8; 32]>::try_from(v).ok())
                    .ok_or_else(|| err(format!("token_sha256 {h:?}: not 64 hex digits")))?;
                out.tokens.push((digest, index));
            }
            out.principals.push(Arc::new(Principal {
                name: c.name.as_str().into(),
                index,
                grants: c.grants.clone(),
            }));
        }
        Ok(out)
    }

    /// Whether any principal is configured (authorization on).
    pub fn enabled(&self) -> bool {
        !self.principals.is_empty()
    }

    /// The configured principals.
    pub fn principals(&self) -> &[Arc<Principal>] {
        &self.principals
    }

    /// Recognises a caller from the names of its verified client certificate (empty: none) and
    /// the value of its `authorization` metadata.
    pub fn authenticate(
        &self,
        cert_names: &[String],
        authorization: Option<&[u8]>,
    ) -> Result<Access, AuthError> {
        if !self.enabled() {
            return Ok(Access::Open);
        }
        let by_token = match authorization {
            None => None,
            Some(v) => Some(self.token_principal(bearer(v)?)?),
        };
        let by_cert = if cert_names.is_empty() {
            None
        } else {
            Some(
                cert_names
                    .iter()
                    .find_map(|n| self.by_cert_name.get(n).copied())
                    .ok_or_else(|| AuthError::UnknownCertificate(cert_names[0].clone()))?,
            )
        };
        let index = match (by_cert, by_token) {
            (None, None) => return Err(AuthError::NoCredentials),
            (Some(c), Some(t)) if c != t => {
                return Err(AuthError::Conflict {
                    cert: self.principals[c].name.to_string(),
                    token: self.principals[t].name.to_string(),
                });
            }
            (Some(i), _) | (None, Some(i)) => i,
        };
        Ok(Access::Principal(Arc::clone(&self.principals[index])))
    }

    /// The principal of a token. Every configured digest is compared, in constant time, so the
    /// answer's timing does not tell how much of a digest matched nor which one.
    fn token_principal(&self, token: &[u8]) -> Result<usize, AuthError> {
        let digest: [u8; 32] = Sha256::digest(token).into();
        let mut found = None;
        for (d, i) in &self.tokens {
            if bool::from(d.ct_eq(&digest)) {
                found = Some(*i);
            }
        }
        found.ok_or(AuthError::BadToken)
    }
}

/// The token of an `authorization: Bearer <token>` value.
fn bearer(value: &[u8]) -> Result<&[u8], AuthError> {
    let v = value.trim_ascii();
    let (scheme, rest) = v.split_at_checked(6).ok_or(AuthError::MalformedToken)?;
    if !scheme.eq_ignore_ascii_case(b"bearer") {
        return Err(AuthError::MalformedToken);
    }
    let token = rest.trim_ascii();
    if token.is_empty() || rest.first() != Some(&b' ') {
        return Err(AuthError::MalformedToken);
    }
    Ok(token)
}

/// Hex SHA-256 of a token (what `token_sha256` holds).
pub fn token_digest_hex(token: &str) -> String {
    hex::encode(Sha256::digest(token.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn alpha_bravo() -> Authorizer {
        let p = |name: &str, fleet: &str, verbs: Vec<Verb>| PrincipalConfig {
            name: name.into(),
            certificate_names: vec![name.into()],
            token_sha256: vec![token_digest_hex(&format!("token-of-{name}"))],
            grants: vec![Grant {
                vehicles: fleet.into(),
                verbs,
            }],
        };
        Authorizer::new(&[
            p(
                "gs-alpha",
                "alpha-",
                vec![Verb::Feed, Verb::Watch, Verb::List],
            ),
            p(
                "gs-bravo",
                "bravo-",
                vec![Verb::Feed, Verb::Configure, Verb::Reset],
            ),
        ])
        .expect("valid principals")
    }

    #[test]
    fn tokens_and_certificates_name_principals() {
        let a = alpha_bravo();
        let by_token = a
            .authenticate(&[], Some(b"Bearer token-of-gs-alpha"))
            .expect("alpha's token");
        assert_eq!(by_token.name(), "gs-alpha");
        let by_cert = a
            .authenticate(&["gs-bravo".into()], None)
            .expect("bravo's certificate");
        assert_eq!(by_cert.name(), "gs-bravo");
        assert_eq!(
            a.authenticate(&[], Some(b"Bearer token-of-gs-alphx")),
            Err(AuthError::BadToken)
        );
        assert_eq!(a.authenticate(&[], None), Err(AuthError::NoCredentials));
        assert_eq!(
            a.authenticate(&[], Some(b"Basic dXNlcjpwYXNz")),
            Err(AuthError::MalformedToken)
        );
        assert!(matches!(
            a.authenticate(&["gs-alpha".into()], Some(b"Bearer token-of-gs-bravo")),
            Err(AuthError::Conflict { .. })
        ));
        assert!(matches!(
            a.authenticate(&["mallory".into()], None),
            Err(AuthError::UnknownCertificate(_))
        ));
    }

    #[test]
    fn grants_are_by_prefix_and_verb_and_deny_by_default() {
        let a = alpha_bravo();
        let alpha = a.authenticate(&["gs-alpha".into()], None).expect("alpha");
        assert!(alpha.allows(Verb::Feed, "alpha-1"));
        assert!(!alpha.allows(Verb::Feed, "bravo-1"));
        assert!(!alpha.allows(Verb::Configure, "alpha-1"));
        assert!(!alpha.allows(Verb::Metrics, "alpha-1"));
        // By prefix: the grant's prefix must be a prefix of the watched one.
        assert!(alpha.allows(Verb::Watch, "alpha-"));
        assert!(alpha.allows(Verb::Watch, "alpha-7"));
        assert!(!alpha.allows(Verb::Watch, "alpha"));
        assert!(!alpha.allows(Verb::Watch, ""));
        assert!(Access::Open.allows(Verb::Watch, ""));
    }

    #[test]
    fn verbs_index_their_table() {
        for (i, v) in Verb::ALL.into_iter().enumerate() {
            assert_eq!(v as usize, i, "{v:?}");
        }
    }

    #[test]
    fn bad_configurations_are_refused_with_the_principal_named() {
        let bad = PrincipalConfig {
            name: "gs".into(),
            certificate_names: vec![],
            token_sha256: vec!["abc".into()],
            grants: vec![],
        };
        let e = Authorizer::new(&[bad]).expect_err("short digest");
        assert!(
            e.to_string().contains("security.principals[0] (\"gs\")"),
            "{e}"
        );
        let wildcard = PrincipalConfig {
            name: "gs".into(),
            certificate_names: vec!["gs".into()],
            token_sha256: vec![],
            grants: vec![Grant {
                vehicles: "alpha/*".into(),
                verbs: vec![Verb::Feed],
            }],
        };
        assert!(Authorizer::new(&[wildcard]).is_err());
        assert!(!Authorizer::new(&[]).expect("empty").enabled());
    }
}
