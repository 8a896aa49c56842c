//! [`ClientError`]: every failure names the operation, the target and the transport's reason.

/// What went wrong in a client operation.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The endpoint URL could not be parsed.
    #[error(
        "bad endpoint '{url}': {reason} (expected grpc://HOST:PORT, grpcs://HOST:PORT, zenoh[/ENDPOINT] or discard)"
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
    /// The TLS settings are unusable (a file missing or not PEM, a certificate without its key,
    /// TLS options for a plaintext endpoint or a TLS endpoint without them).
    #[error("TLS: {reason}")]
    Tls {
        /// What is wrong.
        reason: String,
    },
    /// The bearer token cannot be sent as given.
    #[error("token: {reason}")]
    Token {
        /// What is wrong.
        reason: String,
    },
    /// A token would cross the network in clear.
    #[error(
        "refusing to send a token in clear to {endpoint}: use grpcs:// (TLS), or allow_insecure_token if the network is trusted"
    )]
    InsecureToken {
        /// The plaintext endpoint.
        endpoint: String,
    },
    /// The service does not know who is calling (no, wrong or expired token or certificate).
    #[error("{op}: not authenticated: {reason}")]
    Unauthenticated {
        /// The operation.
        op: &'static str,
        /// The service's reason.
        reason: String,
    },
    /// The service knows the caller, whose grants do not cover this operation or vehicle.
    #[error("{op}: permission denied: {reason}")]
    PermissionDenied {
        /// The operation.
        op: &'static str,
        /// The service's reason.
        reason: String,
    },
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

/// A transport failure that retrying cannot fix: a TLS handshake the service refused (no, expired
/// or untrusted client certificate) or plaintext HTTP/2 spoken to a TLS port. Found in the
/// status's error chain (tonic reports both as a generic transport error).
fn tls_mismatch(status: &tonic::Status) -> Option<String> {
    if !matches!(
        status.code(),
        tonic::Code::Unavailable | tonic::Code::Unknown | tonic::Code::Internal
    ) {
        return None;
    }
    let mut chain = vec![status.message().to_string()];
    let mut cur = std::error::Error::source(status);
    while let Some(e) = cur {
        chain.push(e.to_string());
        cur = e.source();
    }
    let text = chain.join(": ");
    let lower = text.to_ascii_lowercase();
    if lower.contains("h2 protocol error") || lower.contains("frame with invalid size") {
        Some(format!(
            "{text} (the service may speak TLS: use grpcs:// with --tls-ca)"
        ))
    } else if lower.contains("received fatal alert")
        || lower.contains("invalid peer certificate")
        || lower.contains("certificate required")
    {
        Some(format!("TLS handshake refused: {text}"))
    } else {
        None
    }
}

impl ClientError {
    /// A gRPC status as an error of operation `op` (the service's refusals get their own
    /// variants: they are never retried).
    pub fn rpc(op: &'static str, status: tonic::Status) -> Self {
        let reason = status.message().to_string();
        if let Some(tls) = tls_mismatch(&status) {
            return ClientError::Tls { reason: tls };
        }
        match status.code() {
            tonic::Code::Unauthenticated => ClientError::Unauthenticated { op, reason },
            tonic::Code::PermissionDenied => ClientError::PermissionDenied { op, reason },
            code => ClientError::Rpc {
                op,
                code,
                message: reason,
            },
        }
    }

    /// Whether the service refused the caller (authentication or authorization): retrying with
    /// the same credentials gets the same answer.
    pub fn is_refusal(&self) -> bool {
        matches!(
            self,
            ClientError::Unauthenticated { .. } | ClientError::PermissionDenied { .. }
        )
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
