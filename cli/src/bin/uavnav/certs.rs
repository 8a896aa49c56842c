//! `uavnav certs`: a private certificate authority and bearer tokens for a deployment.
//!
//! - `init --dir DIR --service NAME [--san HOST_OR_IP]… [--client NAME]… [--days N]`: a CA
//!   (`ca.pem`, `ca.key`), the service certificate `NAME.pem`/`NAME.key` (CN and a DNS SAN =
//!   NAME, plus each `--san` and `localhost`, `127.0.0.1`; server-auth and client-auth: the
//!   service is also a Zenoh peer) and one client certificate per `--client NAME` (CN and a DNS
//!   SAN = NAME, client-auth: the name the service's grants refer to).
//! - `issue --dir DIR (--client NAME | --service NAME [--san …])`: one more certificate from the
//!   CA in DIR.
//! - `token --name NAME`: a fresh bearer token on stdout, the service's config lines (its SHA-256)
//!   on stderr. `hash-token`: the SHA-256 of a token read from stdin.
//!
//! Private keys are written with mode 0600; nothing is overwritten without `--force`; `init
//! --exist-ok` keeps what DIR holds and issues only what is missing (a restarted deployment). Keys are
//! ECDSA P-256; the CA key never leaves DIR (keep it offline once the deployment is issued).
//! Certificate handling is in `certs_der` (reading back the CA for `issue`).

use std::collections::BTreeSet;
use std::fs::OpenOptions;
use std::io::{Read, Write};
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use anyhow::{Context, anyhow};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose, SanType, SerialNumber,
};
use sha2::{Digest, Sha256};

use crate::certs_der;
use crate::common::{CliError, CliResult};

/// Common name of the CA `init` creates, followed by a random id: two deployments' CAs must not
/// share a name, or a verifier matches the other one by name and reports a bad signature instead
/// of an unknown issuer.
const CA_NAME: &str = "uavnav deployment CA";

/// Arguments of `uavnav certs`.
#[derive(Debug, clap::Args)]
#[command(after_help = CERTS_HELP)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

const CERTS_HELP: &str = "Files: DIR/ca.pem (give it to every service and ground station), \
DIR/ca.key (the CA's key: keep it private), DIR/NAME.pem and DIR/NAME.key per certificate (keys \
mode 0600). The service's [security.tls] takes NAME.pem, NAME.key and ca.pem (client_ca); ground \
stations take --tls-ca ca.pem --tls-cert NAME.pem --tls-key NAME.key, and a client NAME is the \
name its [[security.principals]] entry lists in certificate_names.\n\n\
Exit codes: 0 success; 1 run-time failure (I/O); 2 bad usage or bad input (an existing file \
without --force, a bad name, a CA that cannot be read).";

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Create a CA, the service certificate and client certificates in DIR.
    Init(InitArgs),
    /// Issue one more certificate from the CA in DIR.
    Issue(IssueArgs),
    /// Print a fresh bearer token (stdout) and the service's config lines for it (stderr).
    Token(TokenArgs),
    /// Print the SHA-256 (hex) of a token read from stdin, for the service's token_sha256.
    HashToken,
}

/// Validity of the certificates made.
#[derive(Debug, Clone, clap::Args)]
struct Validity {
    /// Validity in days from now.
    #[arg(long, default_value_t = 365, value_parser = clap::value_parser!(u32).range(1..=36500))]
    days: u32,
    /// Make certificates that expired yesterday (tests of the refusal of expired certificates).
    #[arg(long, hide = true)]
    expired: bool,
    /// Replace existing files.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, clap::Args)]
struct InitArgs {
    /// Directory of the files (created if missing).
    #[arg(long, value_name = "DIR")]
    dir: PathBuf,
    /// The service's name: certificate CN and DNS SAN, files NAME.pem/NAME.key.
    #[arg(long, value_name = "NAME")]
    service: String,
    /// More names or IP addresses the service is reached at (repeatable; localhost and
    /// 127.0.0.1 are always included).
    #[arg(long, value_name = "HOST_OR_IP")]
    san: Vec<String>,
    /// A ground station's name: a client certificate NAME.pem/NAME.key (repeatable).
    #[arg(long, value_name = "NAME")]
    client: Vec<String>,
    /// Keep the files DIR already holds and issue only the missing certificates from its CA
    /// (exit 0 when nothing is missing): for a deployment started again on the same volume.
    #[arg(long, conflicts_with = "force")]
    exist_ok: bool,
    #[command(flatten)]
    validity: Validity,
}

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("kind").required(true).args(["client", "service"])))]
struct IssueArgs {
    /// Directory holding ca.pem and ca.key; the new files go there too.
    #[arg(long, value_name = "DIR")]
    dir: PathBuf,
    /// A client certificate for this ground station.
    #[arg(long, value_name = "NAME")]
    client: Option<String>,
    /// A service certificate for this name.
    #[arg(long, value_name = "NAME")]
    service: Option<String>,
    /// More service names or IP addresses (with --service).
    #[arg(long, value_name = "HOST_OR_IP", requires = "service")]
    san: Vec<String>,
    #[command(flatten)]
    validity: Validity,
}

#[derive(Debug, clap::Args)]
struct TokenArgs {
    /// The principal (ground station) the token is for, named in the printed config lines.
    #[arg(long, value_name = "NAME")]
    name: String,
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    match args.command {
        Command::Init(a) => init(&a),
        Command::Issue(a) => issue(&a),
        Command::Token(a) => token(&a),
        Command::HashToken => hash_token(),
    }
}

/// What kind of certificate, which decides its names and extended key usages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Service,
    Client,
}

/// A certificate to make: its name (CN, file stem) and extra SANs.
#[derive(Debug)]
struct Leaf {
    kind: Kind,
    name: String,
    sans: Vec<String>,
}

fn init(a: &InitArgs) -> CliResult {
    let mut leaves = vec![Leaf {
        kind: Kind::Service,
        name: a.service.clone(),
        sans: a.san.clone(),
    }];
    leaves.extend(a.client.iter().map(|c| Leaf {
        kind: Kind::Client,
        name: c.clone(),
        sans: Vec::new(),
    }));
    let mut names = BTreeSet::new();
    for l in &leaves {
        check_name(&l.name)?;
        if !names.insert(l.name.as_str()) {
            return Err(input(anyhow!("the name '{}' is given twice", l.name)));
        }
    }
    let ca_files = [a.dir.join("ca.pem"), a.dir.join("ca.key")];
    let mut files = ca_files.to_vec();
    for l in &leaves {
        files.extend(leaf_files(&a.dir, &l.name));
    }
    if a.exist_ok {
        return init_missing(a, &leaves, &ca_files);
    }
    // Every file is checked before any is written: a refusal leaves DIR as it was.
    refuse_existing(&files, a.validity.force)?;
    std::fs::create_dir_all(&a.dir)
        .with_context(|| format!("cannot create {}", a.dir.display()))?;

    let ca_key = KeyPair::generate().context("cannot generate the CA key")?;
    let ca_params = ca_params(&a.validity)?;
    let ca_cert = ca_params
        .self_signed(&ca_key)
        .context("cannot sign the CA certificate")?;
    write_file(&a.dir.join("ca.key"), &ca_key.serialize_pem(), true)?;
    write_file(&a.dir.join("ca.pem"), &ca_cert.pem(), false)?;
    let issuer = Issuer::new(ca_params, ca_key);
    for l in &leaves {
        write_leaf(&a.dir, l, &issuer, &a.validity)?;
    }
    eprintln!(
        "uavnav: wrote {} files in {} (CA, service '{}', {} client certificate(s))",
        files.len(),
        a.dir.display(),
        a.service,
        a.client.len()
    );
    for f in &files {
        println!("{}", f.display());
    }
    Ok(())
}

/// `init --exist-ok`: keeps what DIR holds and issues only the missing certificates, from the
/// existing CA (a deployment restarted on the same volume keeps its identities). Certificates
/// without their CA are refused: nothing could issue their missing siblings.
fn init_missing(a: &InitArgs, leaves: &[Leaf], ca_files: &[PathBuf; 2]) -> CliResult {
    let ca_present = ca_files.iter().filter(|f| f.exists()).count();
    let missing: Vec<&Leaf> = leaves
        .iter()
        .filter(|l| leaf_files(&a.dir, &l.name).iter().any(|f| !f.exists()))
        .collect();
    if ca_present == 0 && missing.len() == leaves.len() {
        // Nothing there yet: a fresh deployment.
        let fresh = InitArgs {
            exist_ok: false,
            dir: a.dir.clone(),
            service: a.service.clone(),
            san: a.san.clone(),
            client: a.client.clone(),
            validity: a.validity.clone(),
        };
        return init(&fresh);
    }
    if ca_present < 2 {
        return Err(input(anyhow!(
            "{} holds certificates but not both ca.pem and ca.key: cannot complete it",
            a.dir.display()
        )));
    }
    if missing.is_empty() {
        eprintln!("uavnav: {} is complete; nothing written", a.dir.display());
        return Ok(());
    }
    let issuer = load_issuer(&a.dir)?;
    let forced = Validity {
        force: true,
        ..a.validity.clone()
    };
    for l in missing {
        // A half-written pair (a key without its certificate) is replaced as a whole.
        write_leaf(&a.dir, l, &issuer, &forced)?;
        for f in leaf_files(&a.dir, &l.name) {
            println!("{}", f.display());
        }
    }
    Ok(())
}

fn issue(a: &IssueArgs) -> CliResult {
    let (kind, name) = match (&a.client, &a.service) {
        (Some(c), None) => (Kind::Client, c.clone()),
        (None, Some(s)) => (Kind::Service, s.clone()),
        _ => {
            return Err(input(anyhow!(
                "give one of --client NAME or --service NAME"
            )));
        }
    };
    check_name(&name)?;
    let files = leaf_files(&a.dir, &name);
    refuse_existing(&files, a.validity.force)?;
    let issuer = load_issuer(&a.dir)?;
    let leaf = Leaf {
        kind,
        name,
        sans: a.san.clone(),
    };
    write_leaf(&a.dir, &leaf, &issuer, &a.validity)?;
    for f in &files {
        println!("{}", f.display());
    }
    Ok(())
}

/// The CA of `dir` as an issuer: its key, and its name read back from ca.pem (rcgen builds the
/// issuer from parameters, so the subject is rebuilt and checked byte for byte against ca.pem,
/// and the key against the certificate's public key: a leaf must chain to the CA on disk).
fn load_issuer(dir: &Path) -> Result<Issuer<'static, KeyPair>, CliError> {
    let (cert_path, key_path) = (dir.join("ca.pem"), dir.join("ca.key"));
    let read = |p: &Path| {
        std::fs::read_to_string(p)
            .with_context(|| format!("cannot read {}", p.display()))
            .map_err(input)
    };
    let key = KeyPair::from_pem(&read(&key_path)?)
        .map_err(|e| input(anyhow!("{}: not a private key: {e}", key_path.display())))?;
    let der = certs_der::pem_to_der(&read(&cert_path)?, "CERTIFICATE")
        .map_err(|e| input(anyhow!("{}: {e}", cert_path.display())))?;
    let ca = certs_der::parse_certificate(&der)
        .map_err(|e| input(anyhow!("{}: {e}", cert_path.display())))?;
    if ca.spki != rcgen::PublicKeyData::subject_public_key_info(&key) {
        return Err(input(anyhow!(
            "{} is not the key of {}",
            key_path.display(),
            cert_path.display()
        )));
    }
    let mut params = CertificateParams::default();
    params.distinguished_name = certs_der::distinguished_name(ca.subject)
        .map_err(|e| input(anyhow!("{}: {e}", cert_path.display())))?;
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.key_usages = ca_key_usages();
    let rebuilt = params
        .self_signed(&key)
        .context("cannot rebuild the CA's issuer")?;
    let rebuilt = certs_der::parse_certificate(rebuilt.der())
        .map_err(|e| CliError::runtime(anyhow!("rebuilt CA: {e}")))?;
    if rebuilt.subject != ca.subject {
        return Err(input(anyhow!(
            "{}: its subject name cannot be reproduced (was it made by `uavnav certs init`?)",
            cert_path.display()
        )));
    }
    Ok(Issuer::new(params, key))
}

fn ca_key_usages() -> Vec<KeyUsagePurpose> {
    vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ]
}

fn ca_params(v: &Validity) -> Result<CertificateParams, CliError> {
    let mut p = CertificateParams::default();
    let mut id = [0u8; 6];
    getrandom::fill(&mut id).map_err(|e| CliError::runtime(anyhow!("no random CA id: {e}")))?;
    p.distinguished_name
        .push(DnType::CommonName, format!("{CA_NAME} {}", hex::encode(id)));
    p.distinguished_name
        .push(DnType::OrganizationName, "uavnav");
    p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    p.key_usages = ca_key_usages();
    set_validity(&mut p, v)?;
    Ok(p)
}

fn set_validity(p: &mut CertificateParams, v: &Validity) -> Result<(), CliError> {
    const DAY: Duration = Duration::from_secs(86_400);
    let now = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_err(|e| CliError::runtime(anyhow!("the clock is before 1970: {e}")))?;
    let (from, to) = if v.expired {
        (now.saturating_sub(DAY * 30), now.saturating_sub(DAY))
    } else {
        // An hour of slack for clocks slightly behind ours.
        (
            now.saturating_sub(Duration::from_secs(3600)),
            now + DAY * v.days,
        )
    };
    // From the epoch: rcgen's time type adds a std Duration without needing `time`'s std feature.
    let epoch = rcgen::date_time_ymd(1970, 1, 1);
    p.not_before = epoch + from;
    p.not_after = epoch + to;
    let mut serial = [0u8; 16];
    getrandom::fill(&mut serial)
        .map_err(|e| CliError::runtime(anyhow!("no random serial number: {e}")))?;
    // Positive and without a leading zero byte once DER-encoded.
    serial[0] = (serial[0] & 0x7f) | 0x40;
    p.serial_number = Some(SerialNumber::from_slice(&serial));
    Ok(())
}

/// The parameters of a service or client certificate.
fn leaf_params(l: &Leaf, v: &Validity) -> Result<CertificateParams, CliError> {
    let mut names = vec![l.name.clone()];
    if l.kind == Kind::Service {
        names.extend(l.sans.iter().cloned());
        names.extend(["localhost".to_string(), "127.0.0.1".to_string()]);
    }
    let mut sans = Vec::new();
    let mut seen = BTreeSet::new();
    for n in names {
        if !seen.insert(n.to_ascii_lowercase()) {
            continue;
        }
        let san = match n.parse::<IpAddr>() {
            Ok(ip) => SanType::IpAddress(ip),
            Err(_) => {
                check_dns(&n)?;
                SanType::DnsName(
                    n.clone()
                        .try_into()
                        .map_err(|e| input(anyhow!("'{n}' is not a DNS name: {e}")))?,
                )
            }
        };
        sans.push(san);
    }
    let mut p = CertificateParams::default();
    p.distinguished_name
        .push(DnType::CommonName, l.name.as_str());
    p.subject_alt_names = sans;
    p.is_ca = IsCa::ExplicitNoCa;
    p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    p.extended_key_usages = match l.kind {
        // The service also dials other Zenoh peers with its certificate.
        Kind::Service => vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ],
        Kind::Client => vec![ExtendedKeyUsagePurpose::ClientAuth],
    };
    p.use_authority_key_identifier_extension = true;
    set_validity(&mut p, v)?;
    Ok(p)
}

fn write_leaf(dir: &Path, l: &Leaf, issuer: &Issuer<'_, KeyPair>, v: &Validity) -> CliResult {
    let key = KeyPair::generate().context("cannot generate a key")?;
    let cert = leaf_params(l, v)?
        .signed_by(&key, issuer)
        .with_context(|| format!("cannot sign the certificate of '{}'", l.name))?;
    let [pem, key_file] = leaf_files(dir, &l.name);
    write_file(&key_file, &key.serialize_pem(), true)?;
    write_file(&pem, &cert.pem(), false)?;
    Ok(())
}

fn leaf_files(dir: &Path, name: &str) -> [PathBuf; 2] {
    [
        dir.join(format!("{name}.pem")),
        dir.join(format!("{name}.key")),
    ]
}

/// A certificate name is also a file stem and a DNS SAN: `[A-Za-z0-9.-]`, not `ca`.
fn check_name(name: &str) -> CliResult {
    check_dns(name)?;
    if name.eq_ignore_ascii_case("ca") {
        return Err(input(anyhow!("'ca' is the CA's own file name")));
    }
    Ok(())
}

fn check_dns(name: &str) -> CliResult {
    let ok = !name.is_empty()
        && name.len() <= 253
        && name
            .split('.')
            .all(|l| !l.is_empty() && l.len() <= 63 && !l.starts_with('-') && !l.ends_with('-'))
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'.');
    if ok {
        Ok(())
    } else {
        Err(input(anyhow!(
            "'{name}' is not a usable name (DNS labels of A-Z a-z 0-9 -, separated by dots)"
        )))
    }
}

fn refuse_existing(files: &[PathBuf], force: bool) -> CliResult {
    if force {
        return Ok(());
    }
    let existing: Vec<String> = files
        .iter()
        .filter(|f| f.exists())
        .map(|f| f.display().to_string())
        .collect();
    if existing.is_empty() {
        Ok(())
    } else {
        Err(input(anyhow!(
            "refusing to overwrite {} (--force replaces them)",
            existing.join(", ")
        )))
    }
}

/// Writes `text` to `path`; private keys get mode 0600 from creation on (never readable by
/// others, not even for a moment).
fn write_file(path: &Path, text: &str, private: bool) -> CliResult {
    let mut o = OpenOptions::new();
    o.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.mode(if private { 0o600 } else { 0o644 });
    }
    let mut f = o
        .open(path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    // `mode` applies to new files only: an existing key replaced with --force is tightened too.
    #[cfg(unix)]
    if private {
        use std::os::unix::fs::PermissionsExt;
        f.set_permissions(std::fs::Permissions::from_mode(0o600))
            .with_context(|| format!("cannot restrict {}", path.display()))?;
    }
    f.write_all(text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

fn token(a: &TokenArgs) -> CliResult {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes)
        .map_err(|e| CliError::runtime(anyhow!("no random bytes for the token: {e}")))?;
    let token = hex::encode(bytes);
    println!("{token}");
    eprintln!(
        "# uavnavd config, in the [[security.principals]] entry of '{}':",
        a.name
    );
    eprintln!("name = \"{}\"", a.name);
    eprintln!("token_sha256 = [\"{}\"]", sha256_hex(&token));
    Ok(())
}

fn hash_token() -> CliResult {
    let mut text = String::new();
    std::io::stdin()
        .read_to_string(&mut text)
        .context("cannot read the token from stdin")?;
    let t = text.trim();
    if t.is_empty() {
        return Err(input(anyhow!("no token on stdin")));
    }
    println!("{}", sha256_hex(t));
    Ok(())
}

/// SHA-256 of a token's UTF-8 bytes, lower-case hex (what the service stores and compares).
fn sha256_hex(token: &str) -> String {
    hex::encode(Sha256::digest(token.as_bytes()))
}

fn input(e: impl Into<anyhow::Error>) -> CliError {
    CliError::input(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked() {
        for ok in ["uavnavd", "gs-alpha", "uavnavd.fleet.example"] {
            assert!(check_name(ok).is_ok(), "{ok}");
        }
        for bad in ["", "ca", "a/b", "-x", "a..b", "gs alpha", "../x"] {
            assert!(check_name(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_token_hash_is_sha256_of_the_text() {
        // echo -n abc | sha256sum
        assert_eq!(
            sha256_hex("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
