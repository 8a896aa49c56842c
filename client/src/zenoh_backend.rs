//! The Zenoh backend: a session configured from the endpoint, puts on the vehicle input keys,
//! subscribers on the output keys, queries on the queryables (see [`crate::keys`]). `tls/`
//! locators take their settings from [`crate::TlsOptions`] ([`crate::security::zenoh_tls`]).

use std::collections::BTreeMap;
use std::time::Duration;

use futures::Stream;
use prost::Message;
use zenoh::Session;
use zenoh::bytes::Encoding;

use crate::client::ConnectOptions;
use crate::error::ClientError;
use crate::keys::{self, Leaf};
use crate::pb;
use crate::security::{self, TlsOptions};
use crate::watch::Selector;

/// The Zenoh encoding of a uavnav.v1 message ([`keys::encoding_for`], the service's too).
pub fn encoding(full_name: &str) -> Encoding {
    Encoding::from(keys::encoding_for(full_name))
}

/// The session configuration for an endpoint's locators (none = default config with scouting),
/// with TLS when `tls` is given (needed by `tls/` locators, refused without one: the caller expects
/// an encrypted link).
pub fn session_config(
    connect: &[String],
    client_mode: bool,
    tls: Option<&TlsOptions>,
) -> Result<zenoh::Config, ClientError> {
    let mut z = zenoh::Config::default();
    let uses_tls = connect.iter().any(|c| c.starts_with("tls/"));
    match tls {
        Some(t) if uses_tls => security::zenoh_tls(&mut z, t)?,
        Some(_) => {
            return Err(ClientError::Tls {
                reason: "TLS options given for a Zenoh endpoint without a tls/HOST:PORT locator"
                    .into(),
            });
        }
        None if uses_tls => {
            return Err(ClientError::Tls {
                reason: "a tls/ Zenoh locator needs TLS options: at least the CA that signed the service certificate".into(),
            });
        }
        None => {}
    }
    let set = |z: &mut zenoh::Config, key: &str, value: String| {
        z.insert_json5(key, &value)
            .map_err(|e| ClientError::Connect {
                endpoint: format!("zenoh/{}", connect.join(",")),
                reason: format!("zenoh config {key}={value}: {e}"),
            })
    };
    if client_mode {
        set(&mut z, "mode", "\"client\"".into())?;
    }
    if !connect.is_empty() {
        let list: Vec<String> = connect.iter().map(|c| format!("\"{c}\"")).collect();
        set(&mut z, "connect/endpoints", format!("[{}]", list.join(",")))?;
        // Explicit locators: no LAN discovery. Peers keep their default ephemeral listener so that
        // gossip lets two tools on the same service (a replayer, a recorder) reach each other.
        set(&mut z, "scouting/multicast/enabled", "false".into())?;
    }
    Ok(z)
}

/// Opens a session; with explicit locators, waits (up to `timeout`) until a peer or router is
/// connected so that an unreachable service is reported instead of silently publishing nowhere.
pub async fn open(
    connect: &[String],
    client_mode: bool,
    opts: &ConnectOptions,
) -> Result<Session, ClientError> {
    let timeout = opts.connect_timeout;
    if opts.token.is_some() {
        tracing::debug!("Zenoh authenticates by client certificate: the token is not sent");
    }
    let endpoint = if connect.is_empty() {
        "zenoh".to_string()
    } else {
        format!("zenoh/{}", connect.join(","))
    };
    let session = zenoh::open(session_config(connect, client_mode, opts.tls.as_ref())?)
        .await
        .map_err(|e| ClientError::Connect {
            endpoint: endpoint.clone(),
            reason: e.to_string(),
        })?;
    if connect.is_empty() {
        return Ok(session);
    }
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let peers = session.info().peers_zid().await.count();
        let routers = session.info().routers_zid().await.count();
        if peers + routers > 0 {
            return Ok(session);
        }
        if tokio::time::Instant::now() >= deadline {
            let _ = session.close().await;
            return Err(ClientError::Connect {
                endpoint,
                reason: if opts.tls.is_some() {
                    format!(
                        "no Zenoh peer or router reachable within {timeout:?} (with TLS: also a \
                         refused certificate, e.g. an unknown CA, a name mismatch or no client \
                         certificate where mutual TLS is required)"
                    )
                } else {
                    format!("no Zenoh peer or router reachable within {timeout:?}")
                },
            });
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// How long a first put for a vehicle waits for the service's subscription to be known here.
pub const SUBSCRIBER_WAIT: Duration = Duration::from_secs(5);

/// Waits (up to `timeout`) until a subscriber matching `key` is known to this session.
///
/// Why: a Zenoh put goes only where matching subscriptions are known, and a session that has just
/// connected learns the service's subscriptions a moment later; a burst published in that moment
/// is silently routed nowhere. Returns whether a subscriber matched.
pub async fn wait_for_subscriber(session: &Session, key: &str, timeout: Duration) -> bool {
    let Ok(publisher) = session.declare_publisher(key.to_string()).await else {
        return false;
    };
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        if publisher
            .matching_status()
            .await
            .is_ok_and(|m| m.matching())
        {
            return true;
        }
        if tokio::time::Instant::now() >= deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Queries `key` and decodes every reply as `M`.
pub async fn query<M: Message + Default>(
    session: &Session,
    key: &str,
    timeout: Duration,
) -> Result<Vec<M>, ClientError> {
    let replies = session
        .get(key)
        .timeout(timeout)
        .await
        .map_err(|e| ClientError::Zenoh {
            op: "get",
            key: key.to_string(),
            reason: e.to_string(),
        })?;
    let mut out = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        match reply.into_result() {
            Ok(sample) => {
                let bytes = sample.payload().to_bytes();
                let m = M::decode(bytes.as_ref()).map_err(|source| ClientError::Decode {
                    what: key.to_string(),
                    source,
                })?;
                out.push(m);
            }
            Err(e) => {
                let reason = String::from_utf8_lossy(&e.payload().to_bytes()).into_owned();
                return Err(ClientError::Zenoh {
                    op: "get",
                    key: key.to_string(),
                    reason,
                });
            }
        }
    }
    Ok(out)
}

/// The vehicle list from every service instance answering (merged, sorted by id).
pub async fn list(
    session: &Session,
    prefix: &str,
    timeout: Duration,
) -> Result<Vec<pb::VehicleSummary>, ClientError> {
    let answers: Vec<pb::ListVehiclesResponse> = query(session, keys::VEHICLES, timeout).await?;
    let mut by_id = BTreeMap::new();
    for v in answers.into_iter().flat_map(|a| a.vehicles) {
        if v.vehicle_id.starts_with(prefix) {
            by_id.insert(v.vehicle_id.clone(), v);
        }
    }
    Ok(by_id.into_values().collect())
}

/// The latest pose of `id` (the newest if several services answer).
pub async fn get_pose(
    session: &Session,
    id: &str,
    timeout: Duration,
) -> Result<pb::PoseEstimate, ClientError> {
    let poses: Vec<pb::PoseEstimate> = query(session, &keys::pose_latest_key(id), timeout).await?;
    poses
        .into_iter()
        .max_by_key(|p| p.t_ns)
        .ok_or_else(|| ClientError::NotFound(id.to_string()))
}

/// Publishes a configuration on the vehicle's `config` key.
pub async fn configure(
    session: &Session,
    id: &str,
    config: &pb::VehicleConfig,
) -> Result<(), ClientError> {
    let key = keys::vehicle_key(id, Leaf::Config);
    if !wait_for_subscriber(session, &key, SUBSCRIBER_WAIT).await {
        return Err(ClientError::Zenoh {
            op: "put",
            key,
            reason: format!("no service subscribes to this key (waited {SUBSCRIBER_WAIT:?})"),
        });
    }
    session
        .put(&key, config.encode_to_vec())
        .encoding(encoding(Leaf::Config.message_name()))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .map_err(|e| ClientError::Zenoh {
            op: "put",
            key,
            reason: e.to_string(),
        })
}

/// The subscription key for a selector on `leaf` (one vehicle: its key; else every vehicle, filtered here).
fn watch_key(sel: &Selector, leaf: Leaf) -> String {
    match sel.ids.as_slice() {
        [one] if !sel.all && sel.prefix.is_empty() => keys::vehicle_key(one, leaf),
        _ => keys::vehicle_key("*", leaf),
    }
}

/// Subscribes to `leaf` of the selected vehicles, decoding `M`, decimating per vehicle here.
pub async fn subscribe<M>(
    session: &Session,
    sel: &Selector,
    leaf: Leaf,
) -> Result<impl Stream<Item = Result<M, ClientError>> + Send + Unpin + use<M>, ClientError>
where
    M: Message + Default + Send + 'static,
{
    let key = watch_key(sel, leaf);
    let sub = session
        .declare_subscriber(&key)
        .await
        .map_err(|e| ClientError::Zenoh {
            op: "subscribe",
            key: key.clone(),
            reason: e.to_string(),
        })?;
    let sel = sel.clone();
    let every = sel.decimation.max(1) as u64;
    let state = (sub, sel, BTreeMap::<String, u64>::new());
    Ok(Box::pin(futures::stream::unfold(
        state,
        move |(sub, sel, mut counts)| async move {
            loop {
                let sample = sub.recv_async().await.ok()?;
                let key = sample.key_expr().as_str();
                let Some((id, l)) = keys::split(key) else {
                    continue;
                };
                if l != leaf || !sel.matches(id) {
                    continue;
                }
                let n = counts.entry(id.to_string()).or_default();
                *n += 1;
                if (*n - 1) % every != 0 {
                    continue;
                }
                let item = M::decode(sample.payload().to_bytes().as_ref()).map_err(|source| {
                    ClientError::Decode {
                        what: key.to_string(),
                        source,
                    }
                });
                return Some((item, (sub, sel, counts)));
            }
        },
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zenoh reads the shared string as its well-known protobuf encoding with the message name as
    /// schema (what a peer that checks the encoding id expects), not as a custom encoding.
    #[test]
    fn the_shared_encoding_is_zenohs_protobuf_with_schema() {
        for leaf in Leaf::INPUTS.into_iter().chain(Leaf::OUTPUTS) {
            let name = leaf.message_name();
            assert_eq!(
                encoding(name),
                Encoding::APPLICATION_PROTOBUF.with_schema(name)
            );
            assert_eq!(encoding(name).to_string(), keys::encoding_for(name));
        }
    }
}
