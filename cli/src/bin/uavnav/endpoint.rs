//! What the online subcommands share: the service URL argument, the security options (TLS,
//! token), the async runtime, connecting, and mapping client errors onto exit codes.

use std::future::Future;
use std::path::{Path, PathBuf};

use anyhow::Context;
use uavnav_client::{Client, ClientError, ConnectOptions, Endpoint, TlsOptions};

use crate::common::{CliError, CliResult};

/// Default service URL of `--from` / `--to`.
pub const DEFAULT_URL: &str = "grpc://127.0.0.1:50051";

/// Runs an async command on a fresh multi-threaded runtime.
pub fn block_on<F: Future<Output = CliResult>>(f: F) -> CliResult {
    block_on_threads(0, f)
}

/// Like [`block_on`] on `threads` worker threads: 0 = one per core, 1 = a single-threaded
/// runtime (no cross-thread wake-ups).
pub fn block_on_threads<F: Future<Output = CliResult>>(threads: usize, f: F) -> CliResult {
    let rt = match threads {
        0 => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build(),
        1 => tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build(),
        n => tokio::runtime::Builder::new_multi_thread()
            .worker_threads(n)
            .enable_all()
            .build(),
    }
    .map_err(|e| CliError::runtime(anyhow::anyhow!("cannot start the async runtime: {e}")))?;
    rt.block_on(f)
}

/// Parses a service URL (bad URL = exit 2).
pub fn parse(url: &str) -> Result<Endpoint, CliError> {
    url.parse::<Endpoint>().map_err(CliError::input)
}

/// Environment variable holding the bearer token (`--token-file` wins).
pub const TOKEN_ENV: &str = "UAVNAV_TOKEN";

/// The help heading of the security options.
const SECURITY: &str = "Security (TLS, token)";

/// How an online subcommand secures its connection (flattened into each one's arguments).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SecurityArgs {
    /// PEM file of the CA that signed the service certificate; needed by grpcs://HOST:PORT and by
    /// zenoh/tls/HOST:PORT locators.
    #[arg(long, help_heading = SECURITY, env = "UAVNAV_TLS_CA", value_name = "FILE")]
    pub tls_ca: Option<PathBuf>,
    /// PEM file of this ground station's certificate (mutual TLS; with --tls-key). Made by
    /// `uavnav certs init --client NAME`.
    #[arg(
        long,
        help_heading = SECURITY,
        env = "UAVNAV_TLS_CERT",
        value_name = "FILE",
        requires = "tls_key"
    )]
    pub tls_cert: Option<PathBuf>,
    /// PEM file of this ground station's private key (with --tls-cert).
    #[arg(
        long,
        help_heading = SECURITY,
        env = "UAVNAV_TLS_KEY",
        value_name = "FILE",
        requires = "tls_cert"
    )]
    pub tls_key: Option<PathBuf>,
    /// Name expected in the service certificate (default: the URL's host; gRPC only).
    #[arg(long, help_heading = SECURITY, value_name = "NAME", requires = "tls_ca")]
    pub tls_domain: Option<String>,
    /// File holding the bearer token sent on every gRPC request (trimmed; made by `uavnav certs
    /// token`). Else the environment variable UAVNAV_TOKEN. There is no option taking the token
    /// itself: a command line is visible to every user in `ps`.
    #[arg(long, help_heading = SECURITY, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// Send the token over plaintext grpc:// to a non-loopback host anyway (refused otherwise:
    /// anyone on the path could read and replay it).
    #[arg(long, help_heading = SECURITY)]
    pub allow_insecure_token: bool,
}

impl SecurityArgs {
    /// The connection options these arguments describe (a token file that cannot be read or is
    /// empty = exit 2).
    pub fn options(&self) -> Result<ConnectOptions, CliError> {
        let token = match &self.token_file {
            Some(path) => Some(read_token(path).map_err(CliError::input)?),
            None => std::env::var(TOKEN_ENV)
                .ok()
                .map(|t| t.trim().to_string())
                .filter(|t| !t.is_empty()),
        };
        let tls = self.tls_ca.as_ref().map(|ca| TlsOptions {
            ca_pem: ca.clone(),
            cert_pem: self.tls_cert.clone(),
            key_pem: self.tls_key.clone(),
            domain: self.tls_domain.clone(),
        });
        if tls.is_none() && self.tls_cert.is_some() {
            return Err(CliError::input(anyhow::anyhow!(
                "--tls-cert needs --tls-ca (the CA that signed the service certificate)"
            )));
        }
        Ok(ConnectOptions {
            tls,
            token,
            allow_insecure_token: self.allow_insecure_token,
            ..ConnectOptions::default()
        })
    }
}

/// Reads a token file: the token is its content without surrounding white space.
fn read_token(path: &Path) -> anyhow::Result<String> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the token file {}", path.display()))?;
    let token = text.trim();
    anyhow::ensure!(
        !token.is_empty(),
        "the token file {} is empty",
        path.display()
    );
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Ok(m) = std::fs::metadata(path)
            && m.permissions().mode() & 0o077 != 0
        {
            eprintln!(
                "uavnav: warning: the token file {} is readable by other users (chmod 600 it)",
                path.display()
            );
        }
    }
    Ok(token.to_string())
}

/// Parses and connects with the security options (unreachable = exit 1; bad TLS or token
/// settings, or a refusal by the service = exit 2).
pub async fn connect(url: &str, security: &SecurityArgs) -> Result<Client, CliError> {
    let ep = parse(url)?;
    Client::connect(&ep, security.options()?)
        .await
        .map_err(client_err)
}

/// Maps a client error to its exit code: the caller's fault (bad id, unknown vehicle, refused
/// argument, unusable TLS or token settings, credentials or grants refused by the service) = 2,
/// anything else = 1.
pub fn client_err(e: ClientError) -> CliError {
    let input = match &e {
        ClientError::Endpoint { .. }
        | ClientError::InvalidId { .. }
        | ClientError::NotFound(_)
        | ClientError::Unsupported { .. }
        | ClientError::Tls { .. }
        | ClientError::Token { .. }
        | ClientError::InsecureToken { .. }
        | ClientError::Unauthenticated { .. }
        | ClientError::PermissionDenied { .. } => true,
        ClientError::Rpc { code, .. } => matches!(
            code,
            tonic::Code::InvalidArgument
                | tonic::Code::NotFound
                | tonic::Code::FailedPrecondition
                | tonic::Code::OutOfRange
        ),
        _ => false,
    };
    if input {
        CliError::input(e)
    } else {
        CliError::runtime(e)
    }
}

/// Mode name as in the `estimate` CSV.
pub fn mode_name(m: i32) -> &'static str {
    use uavnav_client::pb::EstimatorMode;
    match EstimatorMode::try_from(m).unwrap_or(EstimatorMode::Unspecified) {
        EstimatorMode::Unspecified => "unknown",
        EstimatorMode::Initialising => "initialising",
        EstimatorMode::Nominal => "nominal",
        EstimatorMode::GnssDeniedVision => "gnss_denied_vision",
        EstimatorMode::InertialOnly => "inertial_only",
        EstimatorMode::Diverged => "diverged",
        EstimatorMode::AttitudeOnly => "attitude_only",
    }
}
