//! [`Client`]: one API over gRPC, Zenoh and the discarding sink.
//!
//! ```no_run
//! # async fn demo() -> Result<(), uavnav_client::ClientError> {
//! use uavnav_client::{Client, ConnectOptions, Selector};
//! let client = Client::connect(&"grpc://127.0.0.1:50051".parse()?, ConnectOptions::default()).await?;
//! for v in client.list_vehicles("").await? {
//!     println!("{}", v.vehicle_id);
//! }
//! let mut poses = client.watch_poses(Selector::all().with_decimation(10)).await?;
//! while let Some(pose) = poses.next().await {
//!     let pose = pose?;
//!     println!("{} {}", pose.vehicle_id, pose.t_ns);
//! }
//! # Ok(()) }
//! ```

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;

use crate::backoff::Backoff;
use crate::endpoint::Endpoint;
use crate::error::{ClientError, check_vehicle_id};
use crate::grpc::{self, RawClient};
use crate::ingest::{Configs, Ingest, IngestStats, Sink, spawn_grpc_driver};
use crate::keys::Leaf;
use crate::pb;
use crate::security::TlsOptions;
use crate::watch::{Selector, Watch};
#[cfg(feature = "zenoh")]
use crate::zenoh_backend;

/// Connection settings.
#[derive(Clone)]
pub struct ConnectOptions {
    /// Time allowed to reach the service at connect.
    pub connect_timeout: Duration,
    /// Time allowed for one request (unary calls, Zenoh queries).
    pub request_timeout: Duration,
    /// Reconnection policy of unary calls, watches and ingest streams.
    pub backoff: Backoff,
    /// Envelopes buffered in an ingest stream before `send` waits.
    pub ingest_buffer: usize,
    /// TLS: required by `grpcs://` and Zenoh `tls/` locators, refused on plaintext endpoints.
    pub tls: Option<TlsOptions>,
    /// Bearer token sent as `authorization: Bearer <token>` on every gRPC request (Zenoh
    /// authenticates by certificate and does not send it).
    pub token: Option<String>,
    /// Send the token over plaintext `grpc://` to a non-loopback host anyway (refused otherwise:
    /// anyone on the path could read and replay it).
    pub allow_insecure_token: bool,
}

impl std::fmt::Debug for ConnectOptions {
    // By hand: the token is a secret and must not reach logs.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConnectOptions")
            .field("connect_timeout", &self.connect_timeout)
            .field("request_timeout", &self.request_timeout)
            .field("backoff", &self.backoff)
            .field("ingest_buffer", &self.ingest_buffer)
            .field("tls", &self.tls)
            .field("token", &self.token.as_ref().map(|_| "<redacted>"))
            .field("allow_insecure_token", &self.allow_insecure_token)
            .finish()
    }
}

impl Default for ConnectOptions {
    fn default() -> Self {
        Self {
            connect_timeout: Duration::from_secs(5),
            request_timeout: Duration::from_secs(5),
            backoff: Backoff::default(),
            ingest_buffer: 1024,
            tls: None,
            token: None,
            allow_insecure_token: false,
        }
    }
}

#[derive(Debug, Clone)]
enum Backend {
    // Boxed: the intercepted tonic client is some 200 bytes, the other backends a pointer.
    Grpc(Box<RawClient>),
    #[cfg(feature = "zenoh")]
    Zenoh(zenoh::Session),
    Discard,
}

/// A connected client (cheap to clone; clones share the connection).
#[derive(Debug, Clone)]
pub struct Client {
    endpoint: Endpoint,
    backend: Backend,
    opts: ConnectOptions,
    /// The vehicle configurations given through this client (and its clones), re-sent first
    /// when an ingest stream reopens (a restarted service has lost them).
    configs: Configs,
}

impl Client {
    /// Connects to `endpoint`; fails if the service is unreachable within the connect timeout.
    pub async fn connect(endpoint: &Endpoint, opts: ConnectOptions) -> Result<Client, ClientError> {
        let backend = match endpoint {
            Endpoint::Grpc { uri } => Backend::Grpc(Box::new(grpc::connect(uri, &opts).await?)),
            #[cfg(feature = "zenoh")]
            Endpoint::Zenoh {
                connect,
                client_mode,
            } => Backend::Zenoh(zenoh_backend::open(connect, *client_mode, &opts).await?),
            #[cfg(not(feature = "zenoh"))]
            Endpoint::Zenoh { .. } => {
                return Err(ClientError::Unsupported {
                    op: "connect",
                    transport: "Zenoh (uavnav-client was built without its `zenoh` feature)",
                });
            }
            Endpoint::Discard => Backend::Discard,
        };
        Ok(Client {
            endpoint: endpoint.clone(),
            backend,
            opts,
            configs: Configs::default(),
        })
    }

    /// Parses `url` and connects with default options.
    pub async fn connect_url(url: &str) -> Result<Client, ClientError> {
        Self::connect(&url.parse()?, ConnectOptions::default()).await
    }

    /// The endpoint connected to.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// The Zenoh session, when connected over Zenoh (for recording raw traffic).
    #[cfg(feature = "zenoh")]
    pub fn zenoh_session(&self) -> Option<&zenoh::Session> {
        match &self.backend {
            Backend::Zenoh(s) => Some(s),
            _ => None,
        }
    }

    /// Runs a unary operation, retrying transient failures with the backoff.
    async fn retry<T, F, Fut>(&self, op: &'static str, f: F) -> Result<T, ClientError>
    where
        F: Fn() -> Fut,
        Fut: Future<Output = Result<T, ClientError>>,
    {
        let mut attempt = 0;
        loop {
            let timeout = self.opts.request_timeout;
            let r = match tokio::time::timeout(timeout, f()).await {
                Ok(r) => r,
                Err(_) => Err(ClientError::Timeout {
                    op,
                    timeout_ms: timeout.as_millis() as u64,
                }),
            };
            match r {
                Err(e) if e.is_transient() => {
                    attempt += 1;
                    let Some(delay) = self.opts.backoff.delay(attempt) else {
                        return Err(ClientError::GaveUp {
                            op,
                            attempts: attempt - 1,
                            last: e.to_string(),
                        });
                    };
                    tracing::debug!(op, attempt, error = %e, "retrying in {delay:?}");
                    tokio::time::sleep(delay).await;
                }
                other => return other,
            }
        }
    }

    /// The vehicles the service knows whose id starts with `prefix` (empty = all), sorted by id.
    pub async fn list_vehicles(
        &self,
        prefix: &str,
    ) -> Result<Vec<pb::VehicleSummary>, ClientError> {
        match &self.backend {
            Backend::Grpc(c) => self.retry("ListVehicles", || grpc::list(c, prefix)).await,
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(s) => zenoh_backend::list(s, prefix, self.opts.request_timeout).await,
            Backend::Discard => Ok(Vec::new()),
        }
    }

    /// The latest pose of `id` ([`ClientError::NotFound`] if unknown or none yet).
    pub async fn get_pose(&self, id: &str) -> Result<pb::PoseEstimate, ClientError> {
        check_vehicle_id(id)?;
        match &self.backend {
            Backend::Grpc(c) => self.retry("GetPose", || grpc::get_pose(c, id)).await,
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(s) => zenoh_backend::get_pose(s, id, self.opts.request_timeout).await,
            Backend::Discard => Err(ClientError::NotFound(id.to_string())),
        }
    }

    /// Creates or reconfigures a vehicle. `Some(created)` over gRPC; `None` over Zenoh (a put has
    /// no reply).
    pub async fn configure(
        &self,
        id: &str,
        config: &pb::VehicleConfig,
    ) -> Result<Option<bool>, ClientError> {
        check_vehicle_id(id)?;
        match &self.backend {
            Backend::Grpc(c) => {
                let created = self
                    .retry("ConfigureVehicle", || grpc::configure(c, id, config))
                    .await?;
                self.configs.remember(id, config);
                Ok(Some(created))
            }
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(s) => {
                zenoh_backend::configure(s, id, config).await?;
                // Re-put by a Zenoh ingest stream's keeper when the service loses it.
                self.configs.remember(id, config);
                Ok(None)
            }
            Backend::Discard => Ok(None),
        }
    }

    /// Restarts a vehicle's estimator (gRPC only).
    pub async fn reset(&self, id: &str) -> Result<(), ClientError> {
        check_vehicle_id(id)?;
        match &self.backend {
            Backend::Grpc(c) => self.retry("ResetVehicle", || grpc::reset(c, id)).await,
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(_) => Err(ClientError::Unsupported {
                op: "reset",
                transport: "Zenoh",
            }),
            Backend::Discard => Ok(()),
        }
    }

    /// Pose estimates of the selected vehicles as they are produced (resumes after failures).
    pub async fn watch_poses(&self, sel: Selector) -> Result<Watch<pb::PoseEstimate>, ClientError> {
        self.watch(sel, Leaf::Pose, "WatchPoses", |mut c, req| async move {
            c.watch_poses(req).await.map(|r| r.into_inner())
        })
        .await
    }

    /// Health reports of the selected vehicles (resumes after failures).
    pub async fn watch_health(
        &self,
        sel: Selector,
    ) -> Result<Watch<pb::VehicleHealth>, ClientError> {
        self.watch(sel, Leaf::Health, "WatchHealth", |mut c, req| async move {
            c.watch_health(req).await.map(|r| r.into_inner())
        })
        .await
    }

    async fn watch<M, F, Fut>(
        &self,
        sel: Selector,
        leaf: Leaf,
        op: &'static str,
        call: F,
    ) -> Result<Watch<M>, ClientError>
    where
        M: prost::Message + Default + Send + 'static,
        F: Fn(RawClient, pb::WatchRequest) -> Fut + Send + Sync + Clone + 'static,
        Fut: Future<Output = Result<tonic::Streaming<M>, tonic::Status>> + Send,
    {
        if sel.is_empty() {
            return Err(ClientError::Rpc {
                op,
                code: tonic::Code::InvalidArgument,
                message: "the selector selects no vehicle".into(),
            });
        }
        for id in &sel.ids {
            check_vehicle_id(id)?;
        }
        // The Zenoh backend subscribes to the leaf's key; gRPC has one call per leaf.
        #[cfg(not(feature = "zenoh"))]
        let _ = leaf;
        let backoff = self.opts.backoff.clone();
        match &self.backend {
            Backend::Grpc(c) => {
                let (c, req) = (RawClient::clone(c), sel.to_request());
                // Fail now on a refusal (bad selector, service down) rather than inside the task.
                let first = call(c.clone(), req.clone())
                    .await
                    .map_err(|s| ClientError::rpc(op, s))?;
                let first = Arc::new(std::sync::Mutex::new(Some(first)));
                Ok(Watch::spawn(op, backoff, move || {
                    let (c, req, call, first) =
                        (c.clone(), req.clone(), call.clone(), Arc::clone(&first));
                    async move {
                        let taken = first.lock().ok().and_then(|mut f| f.take());
                        let stream = match taken {
                            Some(s) => s,
                            None => call(c, req).await.map_err(|s| ClientError::rpc(op, s))?,
                        };
                        Ok(Box::pin(futures::StreamExt::map(stream, move |r| {
                            r.map_err(|s| ClientError::rpc(op, s))
                        })))
                    }
                }))
            }
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(s) => {
                let first = zenoh_backend::subscribe::<M>(s, &sel, leaf).await?;
                let first = Arc::new(std::sync::Mutex::new(Some(first)));
                let s = s.clone();
                Ok(Watch::spawn(op, backoff, move || {
                    let (s, sel, first) = (s.clone(), sel.clone(), Arc::clone(&first));
                    async move {
                        let taken = first.lock().ok().and_then(|mut f| f.take());
                        match taken {
                            Some(st) => Ok(st),
                            None => zenoh_backend::subscribe::<M>(&s, &sel, leaf).await,
                        }
                    }
                }))
            }
            Backend::Discard => Ok(Watch::spawn(op, Backoff::none(), || async {
                Ok(futures::stream::pending::<Result<M, ClientError>>())
            })),
        }
    }

    /// Opens an ingest stream (see [`crate::ingest`]).
    pub async fn ingest(&self) -> Result<Ingest, ClientError> {
        let stats = Arc::new(IngestStats::default());
        Ok(match &self.backend {
            Backend::Grpc(c) => {
                let (tx, rx) = mpsc::channel(self.opts.ingest_buffer.max(1));
                let task = spawn_grpc_driver(
                    RawClient::clone(c),
                    rx,
                    Arc::clone(&stats),
                    self.opts.backoff.clone(),
                    self.configs.clone(),
                );
                Ingest::new(Sink::Grpc(tx), stats, Some(task))
            }
            #[cfg(feature = "zenoh")]
            Backend::Zenoh(s) => {
                let keeper = crate::zenoh_keeper::ConfigKeeper::spawn(
                    s.clone(),
                    self.configs.clone(),
                    Arc::clone(&stats),
                );
                Ingest::new(Sink::Zenoh(s.clone(), Arc::new(keeper)), stats, None)
            }
            Backend::Discard => Ingest::new(Sink::Discard, stats, None),
        })
    }

    /// Closes the connection (Zenoh: the session; gRPC: dropped with the last clone).
    pub async fn close(self) {
        #[cfg(feature = "zenoh")]
        if let Backend::Zenoh(s) = self.backend {
            let _ = s.close().await;
        }
    }
}
