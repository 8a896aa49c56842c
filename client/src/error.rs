//! [`ClientError`]: every failure names the operation, the target and the transport's reason.

/// What went wrong in a client operation.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The endpoint URL could not be parsed.
    #[error(
        "bad endpoint '{url}': {reason} (expected grpc://HOST:PORT, zenoh[/ENDPOINT] or discard)"
    )]
    Endpoint {
        /// The URL as given.
        url: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The service could not be reached.
    #[error("cannot connect to {endpoint}: {reason}")]
    Connect {
        /// The endpoint.
        endpoint: String,
        /// The transport's reason.
        reason: String,
    },
    /// A gRPC call failed with a status.
    #[error("{op} failed: {code:?}: {message}")]
    Rpc {
        /// The operation (e.g. `ListVehicles`).
        op: &'static str,
        /// The gRPC status code.
        code: tonic::Code,
        /// The status message.
        message: String,
    },
    /// A Zenoh operation failed.
    #[error("zenoh {op} on '{key}' failed: {reason}")]
    Zenoh {
        /// The operation (`put`, `get`, `subscribe`...).
        op: &'static str,
        /// The key expression.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// The operation does not exist on this transport.
    #[error("{op} is not available over {transport}")]
    Unsupported {
        /// The operation.
        op: &'static str,
        /// The transport.
        transport: &'static str,
    },
    /// A reply could not be decoded.
    #[error("{what}: malformed protobuf reply: {source}")]
    Decode {
        /// What was being decoded.
        what: String,
        /// The decoder's error.
        source: prost::DecodeError,
    },
    /// The vehicle is unknown to the service (or has no pose yet).
    #[error("vehicle '{0}' not found (unknown, or no pose yet)")]
    NotFound(String),
    /// A vehicle id that the service would refuse.
    #[error("invalid vehicle id '{id}': {reason}")]
    InvalidId {
        /// The id.
        id: String,
        /// Why.
        reason: &'static str,
    },
    /// No reply in time.
    #[error("{op}: no reply within {timeout_ms} ms")]
    Timeout {
        /// The operation.
        op: &'static str,
        /// The timeout, ms.
        timeout_ms: u64,
    },
    /// The stream or client was closed.
    #[error("{0}: closed")]
    Closed(&'static str),
    /// Reconnecting gave up after the backoff's attempts.
    #[error("{op}: gave up after {attempts} reconnection attempts; last error: {last}")]
    GaveUp {
        /// The operation.
        op: &'static str,
        /// Attempts made.
        attempts: u32,
        /// The last error.
        last: String,
    },
}

impl ClientError {
    /// A gRPC status as an error of operation `op`.
    pub fn rpc(op: &'static str, status: tonic::Status) -> Self {
        ClientError::Rpc {
            op,
            code: status.code(),
            message: status.message().to_string(),
        }
    }

    /// Whether retrying after a reconnection may help (transport failures, not refusals).
    pub fn is_transient(&self) -> bool {
        match self {
            ClientError::Rpc { code, .. } => matches!(
                code,
                tonic::Code::Unavailable
                    | tonic::Code::Unknown
                    | tonic::Code::Internal
                    | tonic::Code::Cancelled
            ),
            ClientError::Connect { .. }
            | ClientError::Zenoh { .. }
            | ClientError::Timeout { .. } => true,
            _ => false,
        }
    }
}

/// Checks a vehicle id the way the service does: 1–128 characters of `[A-Za-z0-9_.-]` (it is also a
/// Zenoh key chunk).
pub fn check_vehicle_id(id: &str) -> Result<(), ClientError> {
    let bad = |reason| {
        Err(ClientError::InvalidId {
            id: id.to_string(),
            reason,
        })
    };
    if id.is_empty() {
        return bad("empty");
    }
    if id.len() > 128 {
        return bad("longer than 128 characters");
    }
    if !id
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-'))
    {
        return bad("only A-Z a-z 0-9 _ . - are allowed");
    }
    Ok(())
}
