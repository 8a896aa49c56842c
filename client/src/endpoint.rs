//! [`Endpoint`]: the one place where service URLs are parsed.
//!
//! | URL | meaning |
//! |---|---|
//! | `grpc://HOST:PORT` | gRPC (HTTP/2, plaintext) at HOST:PORT (`http://HOST:PORT` accepted too) |
//! | `grpcs://HOST:PORT` | gRPC over TLS (`https://HOST:PORT` accepted too); needs [`crate::TlsOptions`] with the service's CA |
//! | `zenoh` | a Zenoh peer with the default configuration (multicast scouting on the LAN) |
//! | `zenoh/ENDPOINT[,ENDPOINT…]` | a Zenoh peer connecting to these locators (e.g. `zenoh/tcp/127.0.0.1:7447`, or over TLS `zenoh/tls/uavnavd:7447`), no scouting |
//! | `zenoh-client/ENDPOINT[,…]` | the same in Zenoh client mode (through a router) |
//! | `discard` | a built-in sink that encodes and drops everything (load-generator ceiling) |

use std::fmt;
use std::str::FromStr;

use crate::error::ClientError;

/// Where the service is and over which transport.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// gRPC at an `http://HOST:PORT` (plaintext) or `https://HOST:PORT` (TLS) URI.
    Grpc {
        /// The URI given to tonic (`http://HOST:PORT` or `https://HOST:PORT`).
        uri: String,
    },
    /// Zenoh.
    Zenoh {
        /// Locators to connect to (empty = scouting only).
        connect: Vec<String>,
        /// Client mode (through a router) instead of peer.
        client_mode: bool,
    },
    /// The built-in discarding sink.
    Discard,
}

impl Endpoint {
    /// The transport's name, for messages.
    pub fn transport(&self) -> &'static str {
        match self {
            Endpoint::Grpc { .. } => "gRPC",
            Endpoint::Zenoh { .. } => "Zenoh",
            Endpoint::Discard => "discard",
        }
    }

    /// Whether the transport is encrypted: `grpcs://`, or Zenoh with at least one `tls/` locator.
    pub fn uses_tls(&self) -> bool {
        match self {
            Endpoint::Grpc { uri } => uri.starts_with("https://"),
            Endpoint::Zenoh { connect, .. } => connect.iter().any(|c| c.starts_with("tls/")),
            Endpoint::Discard => false,
        }
    }
}

impl FromStr for Endpoint {
    type Err = ClientError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let bad = |reason: &str| ClientError::Endpoint {
            url: url.to_string(),
            reason: reason.to_string(),
        };
        let url_t = url.trim();
        if url_t == "discard" {
            return Ok(Endpoint::Discard);
        }
        for (scheme, client_mode) in [("zenoh-client", true), ("zenoh", false)] {
            if url_t == scheme {
                return if client_mode {
                    Err(bad(
                        "zenoh-client needs a router locator, e.g. zenoh-client/tcp/HOST:7447",
                    ))
                } else {
                    Ok(Endpoint::Zenoh {
                        connect: Vec::new(),
                        client_mode,
                    })
                };
            }
            if let Some(rest) = url_t.strip_prefix(scheme).and_then(|r| r.strip_prefix('/')) {
                let connect: Vec<String> = rest
                    .split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect();
                if connect.is_empty() {
                    return Err(bad("no Zenoh locator after '/'"));
                }
                for c in &connect {
                    if !c.contains('/') {
                        return Err(bad("a Zenoh locator looks like tcp/HOST:PORT"));
                    }
                }
                return Ok(Endpoint::Zenoh {
                    connect,
                    client_mode,
                });
            }
        }
        let (scheme, rest) = [
            ("http", "grpc://"),
            ("http", "http://"),
            ("https", "grpcs://"),
            ("https", "https://"),
        ]
        .into_iter()
        .find_map(|(scheme, prefix)| url_t.strip_prefix(prefix).map(|r| (scheme, r)))
        .ok_or_else(|| bad("unknown scheme"))?;
        let rest = rest.trim_end_matches('/');
        let (host, port) = rest.rsplit_once(':').ok_or_else(|| bad("missing :PORT"))?;
        if host.is_empty() {
            return Err(bad("missing HOST"));
        }
        port.parse::<u16>()
            .map_err(|_| bad("PORT is not a number in 0-65535"))?;
        Ok(Endpoint::Grpc {
            uri: format!("{scheme}://{rest}"),
        })
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::Grpc { uri } => match uri.strip_prefix("https://") {
                Some(rest) => write!(f, "grpcs://{rest}"),
                None => write!(f, "grpc://{}", uri.trim_start_matches("http://")),
            },
            Endpoint::Zenoh {
                connect,
                client_mode,
            } => {
                let scheme = if *client_mode {
                    "zenoh-client"
                } else {
                    "zenoh"
                };
                if connect.is_empty() {
                    write!(f, "{scheme}")
                } else {
                    write!(f, "{scheme}/{}", connect.join(","))
                }
            }
            Endpoint::Discard => write!(f, "discard"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form() {
        assert_eq!(
            "grpc://127.0.0.1:50051".parse::<Endpoint>().unwrap(),
            Endpoint::Grpc {
                uri: "http://127.0.0.1:50051".into()
            }
        );
        assert_eq!(
            "http://h:1".parse::<Endpoint>().unwrap(),
            Endpoint::Grpc {
                uri: "http://h:1".into()
            }
        );
        assert_eq!(
            "zenoh".parse::<Endpoint>().unwrap(),
            Endpoint::Zenoh {
                connect: vec![],
                client_mode: false
            }
        );
        assert_eq!(
            "zenoh/tcp/127.0.0.1:7447,udp/h:1"
                .parse::<Endpoint>()
                .unwrap(),
            Endpoint::Zenoh {
                connect: vec!["tcp/127.0.0.1:7447".into(), "udp/h:1".into()],
                client_mode: false
            }
        );
        assert_eq!(
            "zenoh-client/tcp/r:7447".parse::<Endpoint>().unwrap(),
            Endpoint::Zenoh {
                connect: vec!["tcp/r:7447".into()],
                client_mode: true
            }
        );
        assert_eq!(
            "grpcs://uavnavd:50051".parse::<Endpoint>().unwrap(),
            Endpoint::Grpc {
                uri: "https://uavnavd:50051".into()
            }
        );
        assert!("grpcs://uavnavd:1".parse::<Endpoint>().unwrap().uses_tls());
        assert!(!"grpc://uavnavd:1".parse::<Endpoint>().unwrap().uses_tls());
        assert!(
            "zenoh/tls/uavnavd:7447"
                .parse::<Endpoint>()
                .unwrap()
                .uses_tls()
        );
        assert_eq!("discard".parse::<Endpoint>().unwrap(), Endpoint::Discard);
        for s in [
            "grpc://h",
            "grpc://:1",
            "grpc://h:x",
            "grpcs://h",
            "ftp://h:1",
            "zenoh/",
            "zenoh/h:1",
            "zenoh-client",
        ] {
            assert!(s.parse::<Endpoint>().is_err(), "{s}");
        }
        for s in [
            "grpc://h:1",
            "grpcs://h:1",
            "zenoh",
            "zenoh/tcp/a:1",
            "zenoh/tls/a:1",
            "discard",
        ] {
            assert_eq!(s.parse::<Endpoint>().unwrap().to_string(), s);
        }
    }
}
