//! The transport-neutral service facade: what a caller may ask of the fleet, with its identity.
//!
//! The gRPC and Zenoh adapters (and the HTTP port, for `/metrics`) call [`Service`] and nothing
//! below it for a caller's request: it checks the caller's [`Access`] for the verb on the vehicle,
//! counts a refusal by principal, reason and verb, and only then hands the request to the ingest
//! path or reads the registry. A refused feed never reaches the registry, so it never creates a
//! vehicle.

use std::sync::Arc;

use uavnav_proto::v1 as pb;

use crate::ingest::validate::{self, Rejection};
use crate::ingest::{Ingestor, Payload, Verdict};
use crate::metrics::{Cause, Metrics, Transport};
use crate::security::{Access, AuthError, AuthTransport, Authorizer, Refusals, Verb};
use crate::vehicle::actor::VehicleHandle;

/// The facade over the ingest path and the registry.
#[derive(Debug, Clone)]
pub struct Service {
    ingestor: Ingestor,
    auth: Arc<Authorizer>,
    refusals: Arc<Refusals>,
}

impl Service {
    /// A facade over `ingestor`, authorizing with `auth`.
    pub fn new(ingestor: Ingestor, auth: Arc<Authorizer>) -> Self {
        let family = ingestor
            .registry()
            .ctx()
            .metrics
            .security
            .auth_refused
            .clone();
        let refusals = Arc::new(Refusals::new(family, auth.principals()));
        Self {
            ingestor,
            auth,
            refusals,
        }
    }

    /// The ingest path (for the adapters' transport-level accounting: decode failures, sizes).
    pub fn ingestor(&self) -> &Ingestor {
        &self.ingestor
    }

    /// The service's metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.ingestor.registry().ctx().metrics
    }

    /// The output hub (what watches subscribe to).
    pub fn hub(&self) -> &crate::output::hub::Hub {
        &self.ingestor.registry().ctx().hub
    }

    /// Whether authorization is on (principals configured).
    pub fn auth_enabled(&self) -> bool {
        self.auth.enabled()
    }

    /// Recognises a caller from its verified certificate names and `authorization` value;
    /// a failure is counted under `transport`.
    pub fn authenticate(
        &self,
        transport: AuthTransport,
        cert_names: &[String],
        authorization: Option<&[u8]>,
    ) -> Result<Access, AuthError> {
        self.auth
            .authenticate(cert_names, authorization)
            .inspect_err(|e| {
                self.refusals.unauthenticated(transport, e);
                tracing::debug!(transport = transport.as_str(), reason = %e, "caller not recognised");
            })
    }

    /// Checks `verb` on `id` (or on every vehicle under `id` when `prefix`) for a request, and
    /// counts a refusal. The refusal's text (it becomes the request's status) names the vehicle.
    fn check(&self, access: &Access, verb: Verb, id: &str, prefix: bool) -> Result<(), Rejection> {
        if access.allows(verb, id) {
            return Ok(());
        }
        self.refusals.denied(access, AuthTransport::Grpc, verb);
        let what = match (prefix, id.is_empty()) {
            (true, true) => "every vehicle".to_string(),
            (true, false) => format!("the vehicles {id:?}*"),
            (false, _) => format!("vehicle_id {id:?}"),
        };
        Err(Rejection::new(
            pb::IngestStatus::PermissionDenied,
            Cause::PermissionDenied,
            format!(
                "permission denied: {:?} may not {} {what}",
                access.name(),
                verb.as_str()
            ),
        ))
    }

    /// Feeds one message for vehicle `id` (a configuration inside a stream needs `configure`).
    /// A refusal allocates nothing: its counter and its ack's reason were made once for the
    /// principal and verb (the ack carries the vehicle's id).
    pub async fn feed(
        &self,
        access: &Access,
        transport: Transport,
        id: &str,
        payload: Payload<'_>,
    ) -> Verdict {
        let verb = match payload {
            Payload::Config(_) => Verb::Configure,
            _ => Verb::Feed,
        };
        if !access.allows(verb, id) {
            let reason = self.refusals.denied(access, transport.into(), verb);
            return Verdict::refused_shared(pb::IngestStatus::PermissionDenied, reason);
        }
        self.ingestor.submit(transport, id, payload).await
    }

    /// Creates or reconfigures a vehicle (`wait`: until the actor applied it); whether it was
    /// created.
    pub async fn configure(
        &self,
        access: &Access,
        id: &str,
        config: &pb::VehicleConfig,
        wait: bool,
    ) -> Result<bool, Rejection> {
        validate::vehicle_id(id)?;
        self.check(access, Verb::Configure, id, false)?;
        self.ingestor.configure(id, config, wait).await
    }

    /// Restarts a vehicle's estimator; `None` when the vehicle is unknown.
    pub async fn reset(&self, access: &Access, id: &str) -> Result<Option<()>, Rejection> {
        validate::vehicle_id(id)?;
        self.check(access, Verb::Reset, id, false)?;
        self.ingestor.reset(id).await
    }

    /// The vehicle, if the caller may watch it (`None`: unknown).
    pub fn watched_vehicle(
        &self,
        access: &Access,
        id: &str,
    ) -> Result<Option<VehicleHandle>, Rejection> {
        validate::vehicle_id(id)?;
        self.check(access, Verb::Watch, id, false)?;
        Ok(self.ingestor.registry().get(id))
    }

    /// The vehicles under `prefix` the caller may list.
    pub fn list(&self, access: &Access, prefix: &str) -> Vec<VehicleHandle> {
        let mut all = self.ingestor.registry().list(prefix);
        all.retain(|h| access.allows(Verb::List, &h.shared.id));
        all
    }

    /// Whether the caller may watch this selection: every id, the prefix, or every vehicle.
    pub fn authorize_watch(
        &self,
        access: &Access,
        ids: &[String],
        prefix: &str,
        all: bool,
    ) -> Result<(), Rejection> {
        if all {
            self.check(access, Verb::Watch, "", true)?;
        }
        if !prefix.is_empty() {
            self.check(access, Verb::Watch, prefix, true)?;
        }
        for id in ids {
            self.check(access, Verb::Watch, id, false)?;
        }
        Ok(())
    }

    /// Whether a caller may read `/metrics`: authorization off, or a grant of `metrics`.
    pub fn may_read_metrics(&self, access: &Access) -> bool {
        match access {
            Access::Open => true,
            Access::Principal(p) => p.grants().iter().any(|g| g.verbs.contains(&Verb::Metrics)),
        }
    }

    /// Counts a `/metrics` refusal.
    pub fn count_metrics_refusal(&self, access: &Access) {
        self.refusals
            .denied(access, AuthTransport::Http, Verb::Metrics);
    }
}
