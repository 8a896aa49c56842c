//! Certificates made at test time (the security tests give them real names): a private CA, the
//! service's certificate for `localhost` / `127.0.0.1`, ground stations' client certificates,
//! an expired one, and one from a stranger's CA — each written as PEM files in a directory.

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose, date_time_ymd,
};

/// A certificate and its key, as PEM files.
#[derive(Debug, Clone)]
pub struct Pem {
    /// Certificate file.
    pub cert: PathBuf,
    /// Private key file.
    pub key: PathBuf,
}

impl Pem {
    /// The certificate's PEM text.
    pub fn cert_pem(&self) -> String {
        std::fs::read_to_string(&self.cert).expect("test certificate readable")
    }
    /// The key's PEM text.
    pub fn key_pem(&self) -> String {
        std::fs::read_to_string(&self.key).expect("test key readable")
    }
}

/// A test CA that issues certificates into `dir`.
#[allow(missing_debug_implementations)] // rcgen's issuer (it holds the CA key) has no Debug
pub struct Pki {
    dir: PathBuf,
    issuer: Issuer<'static, KeyPair>,
    /// The CA certificate file.
    pub ca: PathBuf,
}

impl Pki {
    /// A new CA named `name`, its certificate written to `dir/{name}-ca.pem`.
    pub fn new(dir: &Path, name: &str) -> Self {
        let key = KeyPair::generate().expect("CA key");
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params
            .distinguished_name
            .push(DnType::CommonName, format!("{name} test CA"));
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        let cert = params.self_signed(&key).expect("CA self-signed");
        let ca = dir.join(format!("{name}-ca.pem"));
        std::fs::write(&ca, cert.pem()).expect("write CA");
        Self {
            dir: dir.to_path_buf(),
            issuer: Issuer::new(params, key),
            ca,
        }
    }

    fn issue(
        &self,
        file: &str,
        cn: &str,
        sans: &[&str],
        eku: &[ExtendedKeyUsagePurpose],
        expired: bool,
    ) -> Pem {
        let key = KeyPair::generate().expect("leaf key");
        let sans: Vec<String> = sans.iter().map(|s| s.to_string()).collect();
        let mut params = CertificateParams::new(sans).expect("leaf params");
        params.distinguished_name.push(DnType::CommonName, cn);
        params.extended_key_usages = eku.to_vec();
        if expired {
            params.not_before = date_time_ymd(2020, 1, 1);
            params.not_after = date_time_ymd(2021, 1, 1);
        }
        let cert = params.signed_by(&key, &self.issuer).expect("signed leaf");
        let out = Pem {
            cert: self.dir.join(format!("{file}.pem")),
            key: self.dir.join(format!("{file}.key")),
        };
        std::fs::write(&out.cert, cert.pem()).expect("write certificate");
        std::fs::write(&out.key, key.serialize_pem()).expect("write key");
        out
    }

    /// The service's certificate: CN `name`, names `localhost` and `127.0.0.1`; server and client
    /// use (it also connects out as a Zenoh peer).
    pub fn service(&self, name: &str) -> Pem {
        self.issue(
            name,
            name,
            &[name, "localhost", "127.0.0.1"],
            &[
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ],
            false,
        )
    }

    /// A ground station's client certificate: CN and DNS name `name`.
    pub fn client(&self, name: &str) -> Pem {
        self.issue(
            name,
            name,
            &[name],
            &[ExtendedKeyUsagePurpose::ClientAuth],
            false,
        )
    }

    /// A client certificate that expired in 2021.
    pub fn expired_client(&self, name: &str) -> Pem {
        self.issue(
            &format!("{name}-expired"),
            name,
            &[name],
            &[ExtendedKeyUsagePurpose::ClientAuth],
            true,
        )
    }
}
