//! Reading back a CA certificate for `uavnav certs issue`: PEM to DER, the certificate's subject
//! name and public key, and the subject as rcgen's `DistinguishedName`.
//!
//! Why by hand: rcgen builds an issuer from parameters, and reads a certificate back only with
//! its `x509-parser` feature, which this workspace does not enable. The subset of DER needed here
//! (definite lengths, the first fields of `TBSCertificate`, string attributes of a name) is small.

use rcgen::string::{Ia5String, PrintableString};
use rcgen::{DistinguishedName, DnType, DnValue};

/// The parts of a certificate `issue` needs, as complete DER elements (tag, length and value).
#[derive(Debug)]
pub struct CertParts<'a> {
    /// The subject `Name`.
    pub subject: &'a [u8],
    /// The `SubjectPublicKeyInfo`.
    pub spki: &'a [u8],
}

/// The DER of the first PEM block labelled `label` in `text`.
pub fn pem_to_der(text: &str, label: &str) -> Result<Vec<u8>, String> {
    let begin = format!("-----BEGIN {label}-----");
    let end = format!("-----END {label}-----");
    let start = text
        .find(&begin)
        .ok_or_else(|| format!("no {label} PEM block"))?
        + begin.len();
    let len = text[start..]
        .find(&end)
        .ok_or_else(|| format!("the {label} PEM block is not terminated"))?;
    base64_decode(&text[start..start + len])
}

/// Standard base64 with padding, white space ignored.
fn base64_decode(s: &str) -> Result<Vec<u8>, String> {
    let value = |c: u8| -> Result<u32, String> {
        Ok(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return Err(format!("bad base64 character {:?}", c as char)),
        } as u32)
    };
    let chars: Vec<u8> = s.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !chars.len().is_multiple_of(4) {
        return Err("truncated base64".into());
    }
    let mut out = Vec::with_capacity(chars.len() / 4 * 3);
    for quad in chars.chunks(4) {
        let pad = quad.iter().rev().take_while(|&&c| c == b'=').count();
        if pad > 2 {
            return Err("bad base64 padding".into());
        }
        let mut n = 0u32;
        for &c in &quad[..4 - pad] {
            n = (n << 6) | value(c)?;
        }
        n <<= 6 * pad as u32;
        let bytes = n.to_be_bytes();
        out.extend_from_slice(&bytes[1..4 - pad]);
    }
    Ok(out)
}

/// One DER element: its tag, its value and the whole element; plus what follows it.
struct Tlv<'a> {
    tag: u8,
    value: &'a [u8],
    whole: &'a [u8],
    rest: &'a [u8],
}

fn tlv(input: &[u8]) -> Result<Tlv<'_>, String> {
    let short = || "truncated DER".to_string();
    let (&tag, after) = input.split_first().ok_or_else(short)?;
    let (&first, after) = after.split_first().ok_or_else(short)?;
    let (len, after) = if first < 0x80 {
        (first as usize, after)
    } else {
        let n = (first & 0x7f) as usize;
        if n == 0 || n > 4 || after.len() < n {
            return Err("unsupported DER length".into());
        }
        let len = after[..n]
            .iter()
            .fold(0usize, |acc, &b| (acc << 8) | b as usize);
        (len, &after[n..])
    };
    if after.len() < len {
        return Err(short());
    }
    let header = input.len() - after.len();
    Ok(Tlv {
        tag,
        value: &after[..len],
        whole: &input[..header + len],
        rest: &after[len..],
    })
}

fn expect<'a>(input: &'a [u8], tag: u8, what: &str) -> Result<Tlv<'a>, String> {
    let t = tlv(input)?;
    if t.tag != tag {
        return Err(format!(
            "malformed certificate: {what} has tag 0x{:02x}",
            t.tag
        ));
    }
    Ok(t)
}

const SEQUENCE: u8 = 0x30;
const SET: u8 = 0x31;

/// The subject and public key of a DER certificate.
pub fn parse_certificate(der: &[u8]) -> Result<CertParts<'_>, String> {
    let cert = expect(der, SEQUENCE, "Certificate")?;
    let tbs = expect(cert.value, SEQUENCE, "TBSCertificate")?;
    let mut cur = tbs.value;
    // [0] EXPLICIT version, absent in v1 certificates.
    let first = tlv(cur)?;
    if first.tag == 0xa0 {
        cur = first.rest;
    }
    cur = expect(cur, 0x02, "serialNumber")?.rest;
    cur = expect(cur, SEQUENCE, "signature")?.rest;
    cur = expect(cur, SEQUENCE, "issuer")?.rest;
    cur = expect(cur, SEQUENCE, "validity")?.rest;
    let subject = expect(cur, SEQUENCE, "subject")?;
    let spki = expect(subject.rest, SEQUENCE, "subjectPublicKeyInfo")?;
    Ok(CertParts {
        subject: subject.whole,
        spki: spki.whole,
    })
}

/// The arcs of a DER object identifier.
fn oid_arcs(v: &[u8]) -> Result<Vec<u64>, String> {
    let mut arcs = Vec::new();
    let mut n = 0u64;
    for (i, &b) in v.iter().enumerate() {
        if n >> 57 != 0 {
            return Err("OID arc too large".into());
        }
        n = (n << 7) | u64::from(b & 0x7f);
        if b & 0x80 == 0 {
            if arcs.is_empty() {
                let first = (n / 40).min(2);
                arcs.push(first);
                arcs.push(n - first * 40);
            } else {
                arcs.push(n);
            }
            n = 0;
        } else if i + 1 == v.len() {
            return Err("truncated OID".into());
        }
    }
    Ok(arcs)
}

/// A DER `Name` as rcgen's `DistinguishedName` (string attributes, one per RDN).
pub fn distinguished_name(name: &[u8]) -> Result<DistinguishedName, String> {
    let seq = expect(name, SEQUENCE, "Name")?;
    let mut dn = DistinguishedName::new();
    let mut rdns = seq.value;
    while !rdns.is_empty() {
        let set = expect(rdns, SET, "RelativeDistinguishedName")?;
        let atv = expect(set.value, SEQUENCE, "AttributeTypeAndValue")?;
        if !atv.rest.is_empty() {
            return Err("multi-valued name attributes are not supported".into());
        }
        let oid = expect(atv.value, 0x06, "attribute type")?;
        let value = tlv(oid.rest)?;
        let text = std::str::from_utf8(value.value)
            .map_err(|_| "a name attribute is not text".to_string())?
            .to_string();
        let value = match value.tag {
            0x0c => DnValue::Utf8String(text),
            0x13 => DnValue::PrintableString(
                PrintableString::try_from(text).map_err(|e| e.to_string())?,
            ),
            0x16 => DnValue::Ia5String(Ia5String::try_from(text).map_err(|e| e.to_string())?),
            t => return Err(format!("unsupported name string type 0x{t:02x}")),
        };
        let arcs = oid_arcs(oid.value)?;
        let ty = match arcs.as_slice() {
            [2, 5, 4, 3] => DnType::CommonName,
            [2, 5, 4, 6] => DnType::CountryName,
            [2, 5, 4, 7] => DnType::LocalityName,
            [2, 5, 4, 8] => DnType::StateOrProvinceName,
            [2, 5, 4, 10] => DnType::OrganizationName,
            [2, 5, 4, 11] => DnType::OrganizationalUnitName,
            _ => DnType::CustomDnType(arcs),
        };
        dn.push(ty, value);
        rdns = set.rest;
    }
    Ok(dn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_vectors() {
        assert_eq!(base64_decode("TWFu").unwrap(), b"Man");
        assert_eq!(base64_decode("TWE=").unwrap(), b"Ma");
        assert_eq!(base64_decode("TQ==\n").unwrap(), b"M");
        assert!(base64_decode("TQ=").is_err());
        assert!(base64_decode("T!==").is_err());
    }

    #[test]
    fn oids_decode() {
        // 2.5.4.3 and 1.2.840.113549
        assert_eq!(oid_arcs(&[0x55, 0x04, 0x03]).unwrap(), vec![2, 5, 4, 3]);
        assert_eq!(
            oid_arcs(&[0x2a, 0x86, 0x48, 0x86, 0xf7, 0x0d]).unwrap(),
            vec![1, 2, 840, 113549]
        );
    }

    #[test]
    fn a_generated_ca_reads_back_with_the_same_subject_and_key() {
        let key = rcgen::KeyPair::generate().unwrap();
        let mut p = rcgen::CertificateParams::default();
        p.distinguished_name
            .push(DnType::CommonName, "uavnav deployment CA");
        p.distinguished_name
            .push(DnType::OrganizationName, "uavnav");
        let cert = p.self_signed(&key).unwrap();
        let der = pem_to_der(&cert.pem(), "CERTIFICATE").unwrap();
        assert_eq!(der, cert.der().to_vec());
        let parts = parse_certificate(&der).unwrap();
        assert_eq!(
            parts.spki,
            rcgen::PublicKeyData::subject_public_key_info(&key)
        );
        let mut q = rcgen::CertificateParams::default();
        q.distinguished_name = distinguished_name(parts.subject).unwrap();
        let again = q.self_signed(&key).unwrap();
        assert_eq!(
            parse_certificate(again.der()).unwrap().subject,
            parts.subject
        );
    }
}
