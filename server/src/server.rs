//! [`Server::start`]: binds every port (port 0 works), starts the transports and returns a
//! [`RunningServer`] that reports the bound addresses and shuts down gracefully. Tests and
//! `uavnav demo` run the service in-process through it.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, anyhow};
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tonic::codec::CompressionEncoding;
use tracing::{info, warn};
use uavnav_proto::v1::uav_nav_server::UavNavServer;

use crate::config::Config;
use crate::ingest::Ingestor;
use crate::ingest::validate::ImageLimits;
use crate::metrics::Metrics;
use crate::output::hub::Hub;
use crate::output::record::Recorder;
use crate::security::tls::{Alpn, CertStore};
use crate::security::{Authorizer, exposure};
use crate::service::Service;
use crate::transport::arrivals::{ArrivalBudget, ArrivalLayer};
use crate::transport::conn::{self, ConnLimits, ListenerKind, TlsSide};
use crate::transport::grpc::{UavNavService, remap_transport_status};
use crate::transport::grpc_serve::{self, Http2Settings};
use crate::transport::http::{HttpState, router};
use crate::transport::stream_limit::{StreamLimit, StreamLimitService};
use crate::transport::zenoh::ZenohIo;
use crate::vehicle::actor::{Ctx, Msg};
use crate::vehicle::engine::{SharedFactory, default_factory};
use crate::vehicle::registry::Registry;
use crate::vehicle::vision_pool::VisionPool;
use uavnav_liveview::{LiveTap, LiveView};

/// How long the gRPC and HTTP servers get to finish in-flight calls at shutdown.
const SERVE_DRAIN: Duration = Duration::from_secs(5);

/// Entry point of the service.
#[derive(Debug, Clone, Copy)]
pub struct Server;

/// A started service.
#[derive(Debug)]
pub struct RunningServer {
    /// The bound gRPC address.
    pub grpc_addr: SocketAddr,
    /// The bound HTTP address.
    pub http_addr: SocketAddr,
    /// The Zenoh locators listened on (empty without Zenoh).
    pub zenoh_locators: Vec<String>,
    registry: Arc<Registry>,
    stop_tx: watch::Sender<bool>,
    ready: Arc<AtomicBool>,
    health: tonic_health::server::HealthReporter,
    zenoh: Option<ZenohIo>,
    grpc: (JoinHandle<()>, oneshot::Sender<()>),
    http: (JoinHandle<()>, oneshot::Sender<()>),
    pool: Arc<VisionPool>,
    live: Option<LiveView>,
    recorder: Option<Recorder>,
}

impl Server {
    /// Starts the service with the product estimator.
    pub async fn start(config: Config) -> anyhow::Result<RunningServer> {
        Self::start_with(config, default_factory()).await
    }

    /// Starts the service with a given engine factory (tests plug scripted engines here).
    pub async fn start_with(
        config: Config,
        factory: SharedFactory,
    ) -> anyhow::Result<RunningServer> {
        let (mut ingestor, stop_tx) = ingest_path(&config, factory)?;
        let fds = conn::fd_budget(conn::fds_needed(&config)).map_err(|e| anyhow!(e))?;
        if fds.raised {
            info!(
                limit = fds.limit,
                "raised the open-file limit to the configuration's budget"
            );
        }
        for w in exposure(&config).map_err(|e| anyhow!(e))? {
            warn!("{w}");
        }
        let auth = Arc::new(Authorizer::new(&config.security.principals).map_err(|e| anyhow!(e))?);
        let certs = match &config.security.tls {
            Some(t) => {
                let store = CertStore::load(t)?;
                store.spawn_reloader(
                    stop_tx.subscribe(),
                    ingestor
                        .registry()
                        .ctx()
                        .metrics
                        .security
                        .tls_reload_failures
                        .clone(),
                );
                Some(store)
            }
            None => None,
        };
        let registry = Arc::clone(ingestor.registry());
        let (metrics, hub) = (registry.ctx().metrics.clone(), registry.ctx().hub.clone());
        let pool = Arc::clone(&registry.ctx().pool);
        let recorder = match &config.record.directory {
            Some(dir) => {
                let r = Recorder::start(dir, &config.record, &metrics, &hub)?;
                ingestor = ingestor.with_recorder(r.tap());
                Some(r)
            }
            None => None,
        };
        let live = match &config.foxglove.addr {
            Some(addr) => {
                let dropped = metrics.foxglove_dropped.clone();
                let on_drop = std::sync::Arc::new(move |n: u64| {
                    dropped.inc_by(n);
                });
                let view = LiveView::start(addr, on_drop).await?;
                ingestor = ingestor.with_live_view(view.tap());
                tokio::spawn(forward_poses(hub.clone(), view.tap()));
                info!(port = view.port(), "Foxglove live view serving");
                Some(view)
            }
            None => None,
        };

        let service = Service::new(ingestor, auth);
        let zenoh = if config.zenoh.enabled {
            Some(
                ZenohIo::start(
                    &config.zenoh,
                    &config.security,
                    service.clone(),
                    hub.clone(),
                )
                .await?,
            )
        } else {
            None
        };
        let (health, health_service) = tonic_health::server::health_reporter();
        health.set_serving::<UavNavServer<UavNavService>>().await;
        let stop = stop_tx.subscribe();
        let (grpc_addr, grpc) = serve_grpc(
            &config,
            service.clone(),
            health_service,
            certs.clone(),
            stop.clone(),
        )
        .await?;
        let ready = Arc::new(AtomicBool::new(true));
        let (http_addr, http) = serve_http(
            &config.http,
            HttpState {
                metrics,
                ready: Arc::clone(&ready),
                service,
            },
            certs.clone(),
            stop,
        )
        .await?;
        let zenoh_locators = zenoh
            .as_ref()
            .map(|z| z.locators.clone())
            .unwrap_or_default();
        info!(
            %grpc_addr,
            %http_addr,
            zenoh = ?zenoh_locators,
            tls = certs.is_some(),
            authorization = !config.security.principals.is_empty(),
            "uavnavd serving"
        );
        Ok(RunningServer {
            grpc_addr,
            http_addr,
            zenoh_locators,
            registry,
            stop_tx,
            ready,
            health,
            zenoh,
            grpc,
            http,
            pool,
            live,
            recorder,
        })
    }
}

/// The service without its transports, outputs and recorder: the vision pool, the context every
/// vehicle actor shares, the empty registry and the ingest path over it, with the sender that
/// starts shutdown. [`Server::start_with`] wires the transports to it; the test kit's paused-time
/// harness (`uavnav_tests::paused`) drives it alone, under tokio's paused clock. Refuses an
/// invalid configuration.
pub fn ingest_path(
    config: &Config,
    factory: SharedFactory,
) -> anyhow::Result<(Ingestor, watch::Sender<bool>)> {
    config.check()?;
    let (hub, stop_tx) = Hub::new();
    let pool = VisionPool::new(config.vision.effective_workers(), config.vision.queue)
        .context("starting the vision pool")?;
    let ctx = Arc::new(Ctx {
        vehicles: config.vehicles.clone(),
        health_period: Duration::from_millis(config.health.period_ms),
        metrics: Metrics::new(),
        hub,
        pool,
        factory,
        camera_bytes: crate::vehicle::budgets::CameraBytes {
            queued: Default::default(),
            limit: config.vision.queue_bytes,
        },
        input_bytes: crate::vehicle::budgets::ByteBudget::new(config.vehicles.input_bytes),
        camera_pixels: crate::vehicle::budgets::CameraPixels::new(
            config.vision.max_total_camera_pixels,
        ),
    });
    let limits = ImageLimits {
        max_bytes: config.vision.max_image_bytes,
        max_width_px: config.vision.max_camera_width_px,
        max_height_px: config.vision.max_camera_height_px,
        max_pixels: config.vision.max_camera_pixels,
    };
    let ingestor = Ingestor::new(Registry::new(ctx), limits, config.grpc.max_message_bytes);
    Ok((ingestor, stop_tx))
}

/// Shows every pose on the live view until shutdown (a lagging view skips poses, counted by the tap).
async fn forward_poses(hub: Hub, tap: LiveTap) {
    let mut poses = hub.poses.subscribe();
    let mut stopping = hub.stopping.clone();
    loop {
        tokio::select! {
            p = poses.recv() => match p {
                Ok(b) => tap.poses(b),
                Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => tap.count_dropped(n),
                Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
            },
            _ = stopping.changed() => break,
        }
    }
}

async fn serve_grpc(
    config: &Config,
    service: Service,
    health_service: tonic_health::pb::health_server::HealthServer<
        impl tonic_health::pb::health_server::Health,
    >,
    certs: Option<Arc<CertStore>>,
    stop: watch::Receiver<bool>,
) -> anyhow::Result<(SocketAddr, (JoinHandle<()>, oneshot::Sender<()>))> {
    let max = config.grpc.max_message_bytes;
    let tls_failures = service.metrics().security.tls_failures.clone();
    let conn_metrics = service.metrics().connections.clone();
    let arrivals = Arc::new(ArrivalBudget::new(
        config.grpc.arrival_bytes,
        max as u64,
        service.metrics().arrivals.clone(),
    ));
    let streams = Arc::new(StreamLimit::new(
        config.grpc.max_streams,
        config.grpc.max_streams_per_peer,
        service.metrics().streams.clone(),
    ));
    let uavnav = UavNavServer::new(UavNavService::new(service, config.grpc.ack_buffer))
        .max_decoding_message_size(max)
        .max_encoding_message_size(max)
        .accept_compressed(CompressionEncoding::Gzip)
        .accept_compressed(CompressionEncoding::Zstd)
        .send_compressed(CompressionEncoding::Gzip)
        .send_compressed(CompressionEncoding::Zstd);
    let listener = tokio::net::TcpListener::bind(config.grpc.addr)
        .await
        .with_context(|| format!("binding gRPC on {}", config.grpc.addr))?;
    let addr = listener.local_addr()?;
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    // The health service stays open to every caller (probes carry no credentials); reflection
    // lists the whole API, so it is served only when asked for.
    let keepalive = (config.grpc.keepalive_interval_s > 0.0).then(|| {
        (
            Duration::from_secs_f64(config.grpc.keepalive_interval_s),
            Duration::from_secs_f64(config.grpc.keepalive_timeout_s),
        )
    });
    let mut routes = tonic::service::Routes::builder();
    routes.add_service(uavnav).add_service(health_service);
    if config.grpc.reflection {
        let fds = uavnav_proto::FILE_DESCRIPTOR_SET;
        let reflection_v1 = tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(fds)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
            .build_v1()
            .map_err(|e| anyhow!("reflection v1: {e}"))?;
        let reflection_v1alpha = tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(fds)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
            .build_v1alpha()
            .map_err(|e| anyhow!("reflection v1alpha: {e}"))?;
        routes
            .add_service(reflection_v1)
            .add_service(reflection_v1alpha);
    }
    let routes = tower::ServiceBuilder::new()
        .layer(axum::middleware::map_response(
            remap_transport_status::<tonic::body::Body>,
        ))
        .layer(tower::layer::layer_fn(move |inner| {
            StreamLimitService::new(inner, streams.clone())
        }))
        .layer(ArrivalLayer::new(arrivals))
        .service(routes.routes().prepare());
    let settings = Http2Settings {
        max_streams: config.grpc.max_streams_per_connection,
        // Stated, not left to hyper's defaults: the memory budget counts them per connection.
        receive_window: crate::budget::GRPC_CONNECTION_WINDOW,
        keepalive,
    };
    let shutdown = async {
        let _ = stop_rx.await;
    };
    let tls = certs.map(|store| TlsSide {
        store,
        alpn: Alpn::Grpc,
        failures: tls_failures,
    });
    let limits = ConnLimits {
        max_connections: config.grpc.max_connections,
        idle_timeout: Duration::from_secs_f64(config.grpc.idle_timeout_s),
    };
    let conns = conn::accept(
        listener,
        ListenerKind::Grpc,
        limits,
        tls,
        conn_metrics,
        stop,
    );
    let task = tokio::spawn(grpc_serve::serve(conns, routes, settings, shutdown));
    Ok((addr, (task, stop_tx)))
}

async fn serve_http(
    settings: &crate::config::HttpConfig,
    state: HttpState,
    certs: Option<Arc<CertStore>>,
    stop: watch::Receiver<bool>,
) -> anyhow::Result<(SocketAddr, (JoinHandle<()>, oneshot::Sender<()>))> {
    let addr = settings.addr;
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("binding HTTP on {addr}"))?;
    let bound = listener.local_addr()?;
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let metrics = state.service.metrics();
    let tls = certs.map(|store| TlsSide {
        store,
        alpn: Alpn::Http,
        failures: metrics.security.tls_failures.clone(),
    });
    let limits = ConnLimits {
        max_connections: settings.max_connections,
        idle_timeout: Duration::from_secs_f64(settings.idle_timeout_s),
    };
    let conn_metrics = metrics.connections.clone();
    let conns = conn::accept(
        listener,
        ListenerKind::Http,
        limits,
        tls,
        conn_metrics,
        stop,
    );
    let app = router(state);
    let header_timeout = Duration::from_secs_f64(settings.header_timeout_s);
    let shutdown = async {
        let _ = stop_rx.await;
    };
    let task = tokio::spawn(crate::transport::http::serve(
        conns,
        app,
        header_timeout,
        shutdown,
    ));
    Ok((bound, (task, stop_tx)))
}

impl RunningServer {
    /// The vehicle registry (for in-process inspection).
    pub fn registry(&self) -> &Arc<Registry> {
        &self.registry
    }

    /// The port of the Foxglove live view, when one is configured.
    pub fn foxglove_port(&self) -> Option<u16> {
        self.live.as_ref().map(LiveView::port)
    }

    /// The metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.registry.ctx().metrics
    }

    /// Runs until SIGTERM / SIGINT, then shuts down gracefully.
    pub async fn run_until_signal(self) -> anyhow::Result<()> {
        crate::shutdown::signal().await;
        self.shutdown().await
    }

    /// Graceful shutdown (see [`crate::shutdown`] for the order).
    pub async fn shutdown(mut self) -> anyhow::Result<()> {
        info!("shutting down: draining vehicles");
        self.ready.store(false, Ordering::Release);
        self.health
            .set_not_serving::<UavNavServer<UavNavService>>()
            .await;
        let _ = self.stop_tx.send(true);
        if let Some(z) = self.zenoh.as_mut() {
            z.stop_inputs();
        }
        let (grpc_task, grpc_stop) = self.grpc;
        let _ = grpc_stop.send(());
        drain_actors(&self.registry).await;
        if tokio::time::timeout(SERVE_DRAIN, grpc_task).await.is_err() {
            warn!("gRPC calls still open after {SERVE_DRAIN:?}; closing them");
        }
        if let Some(z) = self.zenoh.take() {
            z.close().await;
        }
        let (http_task, http_stop) = self.http;
        let _ = http_stop.send(());
        let _ = tokio::time::timeout(SERVE_DRAIN, http_task).await;
        if let Some(view) = self.live.take() {
            view.stop().await;
        }
        // After the drain: the recording ends with the vehicles' last poses.
        if let Some(r) = self.recorder.take() {
            r.stop().await;
        }
        let pool = Arc::clone(&self.pool);
        let _ = tokio::task::spawn_blocking(move || pool.shutdown()).await;
        info!("shutdown complete");
        Ok(())
    }
}

/// Stops every actor and waits until each has fused its queue and published its final health.
async fn drain_actors(registry: &Registry) {
    let handles = registry.take_all();
    let n = handles.len();
    let mut waits = Vec::with_capacity(n);
    for h in handles {
        let mut final_health = h.shared.latest_health.subscribe();
        final_health.mark_unchanged();
        if h.send(Msg::Stop).await.is_ok() {
            waits.push(async move {
                // The actor's last act is publishing health; a closed channel means it is gone.
                let _ = tokio::time::timeout(SERVE_DRAIN, final_health.changed()).await;
            });
        }
    }
    futures::future::join_all(waits).await;
    info!(vehicles = n, "vehicles drained");
}
