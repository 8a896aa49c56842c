//! Zenoh over mutual TLS, with access control derived from the same grants as gRPC.
//!
//! Zenoh samples carry no caller identity the service could check per message, so on Zenoh the
//! grants are enforced by the Zenoh runtime of the service itself: its access-control
//! interceptors see every message that crosses a link, and a link's subject is the common name of
//! the certificate its peer presented. Each principal's grants become rules (deny by default):
//!
//! | verb | the peer may | and receives |
//! |---|---|---|
//! | feed | put on `uavnav/v1/vehicle/{fleet}/{imu,gnss,mag,baro,camera}` | |
//! | configure | put on `…/{fleet}/config` | |
//! | watch | subscribe to `…/{fleet}/{pose,health}`, query `…/{fleet}/pose/latest`, watch `uavnav/v1/alive/vehicle/{fleet}` | those puts, replies and tokens |
//! | list | (with the fleet `""` only) query `uavnav/v1/vehicles` | the reply |
//!
//! where `{fleet}` is `{prefix}$*` (`*` for the empty prefix). Every principal also receives the
//! service's own declarations (its input subscriber, its queryables, its liveliness token), so
//! that its publishers see a match and it can discover the service; it can never declare a
//! service token, nor publish a pose: those keys are not in any rule. Every put the service
//! sends a station is checked against that station's rules by its key, so a broader wildcard
//! (`uavnav/v1/vehicle/**`) still gets only the station's own fleet's outputs (tested). The
//! admin space is closed.

use anyhow::anyhow;
use uavnav_proto::keys::{self, Leaf, json_string as json_str};

use super::{SecurityConfig, Verb};

/// Applies TLS, access control and a closed admin space to a Zenoh session configuration.
pub fn apply(z: &mut zenoh::Config, sec: &SecurityConfig) -> anyhow::Result<()> {
    let mut set = |key: &str, value: String| {
        z.insert_json5(key, &value)
            .map_err(|e| anyhow!("zenoh config {key}: {e}"))
    };
    set("adminspace/enabled", "false".into())?;
    if let Some(tls) = &sec.tls {
        let path = |p: &std::path::Path| json_str(&p.to_string_lossy());
        set(
            "transport/link/tls/listen_certificate",
            path(&tls.certificate),
        )?;
        set(
            "transport/link/tls/listen_private_key",
            path(&tls.private_key),
        )?;
        // The service also connects out (to a router) with the same identity.
        set(
            "transport/link/tls/connect_certificate",
            path(&tls.certificate),
        )?;
        set(
            "transport/link/tls/connect_private_key",
            path(&tls.private_key),
        )?;
        if let Some(ca) = &tls.client_ca {
            set("transport/link/tls/root_ca_certificate", path(ca))?;
            set("transport/link/tls/enable_mtls", "true".into())?;
        }
        set("transport/link/tls/close_link_on_expiration", "true".into())?;
    }
    if !sec.principals.is_empty() {
        set("access_control", acl_json5(sec))?;
    }
    Ok(())
}

/// The `access_control` section for the configured principals.
pub fn acl_json5(sec: &SecurityConfig) -> String {
    let mut rules = Vec::new();
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    // What every principal receives: the service's declarations (no data).
    rules.push(rule(
        "service-declarations",
        &[
            "declare_subscriber",
            "declare_queryable",
            "liveliness_token",
        ],
        "egress",
        &[
            format!("{}/**", keys::VEHICLE_PREFIX),
            keys::VEHICLES.to_string(),
            format!("{}/**", keys::SERVICE_PREFIX),
        ],
    ));
    rules.push(rule(
        "service-discovery",
        &["declare_liveliness_subscriber", "liveliness_query"],
        "ingress",
        &[format!("{}/**", keys::SERVICE_PREFIX)],
    ));
    rules.push(rule(
        "service-discovery-replies",
        &["reply"],
        "egress",
        &[format!("{}/**", keys::SERVICE_PREFIX)],
    ));
    for (i, p) in sec.principals.iter().enumerate() {
        let subject = format!("principal-{i}");
        let mut rule_ids = vec![
            "service-declarations".to_string(),
            "service-discovery".to_string(),
            "service-discovery-replies".to_string(),
        ];
        for (j, g) in p.grants.iter().enumerate() {
            let fleet = if g.vehicles.is_empty() {
                "*".to_string()
            } else {
                format!("{}$*", g.vehicles)
            };
            let leaf = |l: Leaf| keys::vehicle_key(&fleet, l);
            let mut add = |suffix: &str, messages: &[&str], flow: &str, exprs: Vec<String>| {
                let id = format!("p{i}-g{j}-{suffix}");
                rules.push(rule(&id, messages, flow, &exprs));
                rule_ids.push(id);
            };
            if g.verbs.contains(&Verb::Feed) {
                let inputs = [Leaf::Imu, Leaf::Gnss, Leaf::Mag, Leaf::Baro, Leaf::Camera];
                add("feed", &["put"], "ingress", inputs.map(leaf).to_vec());
            }
            if g.verbs.contains(&Verb::Configure) {
                add("configure", &["put"], "ingress", vec![leaf(Leaf::Config)]);
                // Who configures may learn that a vehicle lost its configuration (the client
                // library's keeper re-puts it).
                let unconfigured = vec![leaf(Leaf::Unconfigured)];
                add(
                    "unconfigured-in",
                    &["declare_subscriber"],
                    "ingress",
                    unconfigured.clone(),
                );
                add("unconfigured-out", &["put"], "egress", unconfigured);
            }
            if g.verbs.contains(&Verb::Watch) {
                let outputs = Leaf::OUTPUTS.map(leaf).to_vec();
                let latest = keys::pose_latest_key(&fleet);
                let alive = keys::alive_key(&fleet);
                add(
                    "watch-in",
                    &["declare_subscriber"],
                    "ingress",
                    outputs.clone(),
                );
                add("watch-out", &["put"], "egress", outputs);
                add("latest-in", &["query"], "ingress", vec![latest.clone()]);
                add("latest-out", &["reply"], "egress", vec![latest]);
                add(
                    "alive-in",
                    &["declare_liveliness_subscriber", "liveliness_query"],
                    "ingress",
                    vec![alive.clone()],
                );
                add(
                    "alive-out",
                    &["liveliness_token", "reply"],
                    "egress",
                    vec![alive],
                );
            }
            // The vehicle list is one reply for every vehicle: only for a grant on all of them.
            if g.verbs.contains(&Verb::List) && g.vehicles.is_empty() {
                add(
                    "list-in",
                    &["query"],
                    "ingress",
                    vec![keys::VEHICLES.into()],
                );
                add(
                    "list-out",
                    &["reply"],
                    "egress",
                    vec![keys::VEHICLES.into()],
                );
            }
        }
        let names: Vec<String> = p.certificate_names.iter().map(|n| json_str(n)).collect();
        if names.is_empty() {
            // Token-only principals (gRPC) have no Zenoh identity: nothing to grant there.
            continue;
        }
        subjects.push(format!(
            "{{ id: {}, cert_common_names: [{}] }}",
            json_str(&subject),
            names.join(", ")
        ));
        let ids: Vec<String> = rule_ids.iter().map(|r| json_str(r)).collect();
        policies.push(format!(
            "{{ rules: [{}], subjects: [{}] }}",
            ids.join(", "),
            json_str(&subject)
        ));
    }
    format!(
        "{{ enabled: true, default_permission: \"deny\", rules: [{}], subjects: [{}], policies: [{}] }}",
        rules.join(", "),
        subjects.join(", "),
        policies.join(", ")
    )
}

fn rule(id: &str, messages: &[&str], flow: &str, exprs: &[String]) -> String {
    let m: Vec<String> = messages.iter().map(|m| json_str(m)).collect();
    let k: Vec<String> = exprs.iter().map(|k| json_str(k)).collect();
    format!(
        "{{ id: {}, messages: [{}], flows: [{}], permission: \"allow\", key_exprs: [{}] }}",
        json_str(id),
        m.join(", "),
        json_str(flow),
        k.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::security::{Grant, PrincipalConfig};

    #[test]
    fn the_acl_is_a_valid_zenoh_configuration() {
        let sec = SecurityConfig {
            principals: vec![
                PrincipalConfig {
                    name: "gs-alpha".into(),
                    certificate_names: vec!["gs-alpha".into()],
                    token_sha256: vec![],
                    grants: vec![Grant {
                        vehicles: "alpha-".into(),
                        verbs: vec![Verb::Feed, Verb::Watch, Verb::Configure, Verb::List],
                    }],
                },
                PrincipalConfig {
                    name: "ops".into(),
                    certificate_names: vec!["ops \"quoted\"".into()],
                    token_sha256: vec![],
                    grants: vec![Grant {
                        vehicles: String::new(),
                        verbs: vec![Verb::Watch, Verb::List],
                    }],
                },
            ],
            ..Default::default()
        };
        let acl = acl_json5(&sec);
        assert!(acl.contains("uavnav/v1/vehicle/alpha-$*/imu"), "{acl}");
        // Who configures may learn a vehicle lost its configuration (the client keeper's key).
        assert!(acl.contains("p0-g0-unconfigured-in"), "{acl}");
        assert!(
            acl.contains("uavnav/v1/vehicle/alpha-$*/unconfigured"),
            "{acl}"
        );
        assert!(
            !acl.contains("p1-g0-unconfigured-in"),
            "ops may not configure: {acl}"
        );
        let mut z = zenoh::Config::default();
        apply(&mut z, &sec).expect("zenoh accepts the generated access control");
        let text = format!("{z:?}");
        assert!(
            text.contains("alpha-$*"),
            "the rules are in the session config"
        );
    }
}
