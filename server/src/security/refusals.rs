//! `uavnav_auth_refused_total`, counted without allocating.
//!
//! A refused message must cost less than an accepted one (issue 20). Looking a counter up in the
//! prometheus-client [`Family`] builds its label set (the principal's name as an owned `String`),
//! hashes it and takes a lock, on every refusal. Here each label set of a configured principal
//! (transport × verb, reason `permission_denied`) and of unrecognised callers (transport ×
//! reason, principal `anonymous`) is looked up once, at its first refusal, and later refusals
//! increment the cached handle: one atomic load and one atomic add. The series still appear in
//! `/metrics` at their first count, with the same names and labels.
//!
//! The reason a refused message's ack carries is made here too, once per principal and verb, and
//! shared by every such ack ([`Refusals::denied`]).

use std::sync::{Arc, OnceLock};

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;

use super::auth::{Access, AuthError, Principal, Verb};
use super::{AuthLabels, AuthTransport};

const TRANSPORTS: usize = AuthTransport::ALL.len();
const VERBS: usize = Verb::ALL.len();
/// The [`AuthError`] kinds ([`auth_error_index`]).
const AUTH_ERRORS: usize = 5;

/// The `principal` label of callers that were not recognised.
pub const ANONYMOUS: &str = "anonymous";

type Slots<const N: usize> = [[OnceLock<Counter>; N]; TRANSPORTS];

/// One principal's counters and ack reasons.
#[derive(Debug)]
struct Denials {
    name: Arc<str>,
    counters: Slots<VERBS>,
    /// Per verb: "permission denied: \"gs-alpha\" may not feed this vehicle".
    reasons: [Arc<str>; VERBS],
}

/// The refusal counters of the configured principals and of unrecognised callers.
#[derive(Debug)]
pub struct Refusals {
    family: Family<AuthLabels, Counter>,
    /// By principal index ([`Principal::index`]).
    principals: Vec<Denials>,
    anonymous: Slots<AUTH_ERRORS>,
}

/// The ack reason of a refused message: the principal named, the vehicle not (the ack carries
/// its id).
fn denied_reason(principal: &str, verb: Verb) -> Arc<str> {
    format!(
        "permission denied: {principal:?} may not {} this vehicle",
        verb.as_str()
    )
    .into()
}

fn auth_error_index(e: &AuthError) -> usize {
    match e {
        AuthError::NoCredentials => 0,
        AuthError::BadToken => 1,
        AuthError::MalformedToken => 2,
        AuthError::UnknownCertificate(_) => 3,
        AuthError::Conflict { .. } => 4,
    }
}

impl Refusals {
    /// The counters of `family` for `principals` (an [`super::Authorizer`]'s, in its order).
    pub fn new(family: Family<AuthLabels, Counter>, principals: &[Arc<Principal>]) -> Self {
        Self {
            family,
            principals: principals
                .iter()
                .map(|p| Denials {
                    name: Arc::clone(&p.name),
                    counters: Default::default(),
                    reasons: Verb::ALL.map(|v| denied_reason(&p.name, v)),
                })
                .collect(),
            anonymous: Default::default(),
        }
    }

    /// Counts a refusal of `verb` to `access` and returns the reason its ack carries.
    pub fn denied(&self, access: &Access, transport: AuthTransport, verb: Verb) -> Arc<str> {
        // A principal of this service's authorizer (the name guards against another's index).
        let known = match access {
            Access::Principal(p) => self
                .principals
                .get(p.index())
                .filter(|d| Arc::ptr_eq(&d.name, &p.name)),
            Access::Open => None,
        };
        match known {
            Some(d) => {
                let slot = &d.counters[transport as usize][verb as usize];
                slot.get_or_init(|| {
                    self.lookup(transport, &d.name, "permission_denied", Some(verb))
                })
                .inc();
                Arc::clone(&d.reasons[verb as usize])
            }
            // Never on the service's paths (an open service allows everything): counted all the
            // same, the slow way.
            None => {
                self.lookup(transport, access.name(), "permission_denied", Some(verb))
                    .inc();
                denied_reason(access.name(), verb)
            }
        }
    }

    /// Counts a caller that was not recognised.
    pub fn unauthenticated(&self, transport: AuthTransport, e: &AuthError) {
        self.anonymous[transport as usize][auth_error_index(e)]
            .get_or_init(|| self.lookup(transport, ANONYMOUS, e.label(), None))
            .inc();
    }

    fn lookup(
        &self,
        transport: AuthTransport,
        principal: &str,
        reason: &'static str,
        verb: Option<Verb>,
    ) -> Counter {
        self.family
            .get_or_create(&AuthLabels {
                transport: transport.as_str(),
                principal: principal.to_owned(),
                reason,
                verb: verb.map_or("-", Verb::as_str),
            })
            .clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::security::{Authorizer, Grant, PrincipalConfig};

    #[test]
    fn cached_counters_are_the_family_series() {
        let auth = Authorizer::new(&[PrincipalConfig {
            name: "gs-alpha".into(),
            certificate_names: vec!["gs-alpha".into()],
            token_sha256: vec![],
            grants: vec![Grant {
                vehicles: "alpha-".into(),
                verbs: vec![Verb::Feed],
            }],
        }])
        .expect("valid principal");
        let family = Family::<AuthLabels, Counter>::default();
        let r = Refusals::new(family.clone(), auth.principals());
        let alpha = auth
            .authenticate(&["gs-alpha".into()], None)
            .expect("alpha");
        for _ in 0..3 {
            let reason = r.denied(&alpha, AuthTransport::Grpc, Verb::Reset);
            assert_eq!(
                &*reason,
                "permission denied: \"gs-alpha\" may not reset this vehicle"
            );
        }
        r.unauthenticated(AuthTransport::Http, &AuthError::BadToken);
        let get = |transport, principal: &str, reason, verb| {
            family
                .get_or_create(&AuthLabels {
                    transport,
                    principal: principal.into(),
                    reason,
                    verb,
                })
                .get()
        };
        assert_eq!(get("grpc", "gs-alpha", "permission_denied", "reset"), 3);
        assert_eq!(get("grpc", "gs-alpha", "permission_denied", "feed"), 0);
        assert_eq!(get("http", ANONYMOUS, "bad_token", "-"), 1);
        // Another authorizer's principal of the same name: counted under its name all the same.
        let other = Authorizer::new(&[PrincipalConfig {
            name: "gs-alpha".into(),
            certificate_names: vec!["gs-alpha".into()],
            token_sha256: vec![],
            grants: vec![],
        }])
        .expect("valid principal")
        .authenticate(&["gs-alpha".into()], None)
        .expect("alpha");
        r.denied(&other, AuthTransport::Grpc, Verb::Reset);
        assert_eq!(get("grpc", "gs-alpha", "permission_denied", "reset"), 4);
    }
}
