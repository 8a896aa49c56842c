//! Truncated and corrupted logs: a clear error naming the byte offset, never a panic. Small
//! synthetic logs of both formats are cut at every offset and corrupted at random (proptest); the
//! shared real logs, when present, are cut at a few hundred offsets too.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use proptest::prelude::*;
use uavnav_logs::{ImportOptions, LogError, import};

/// A DataFlash log: FMT of FMT, FMT of IMU, `n` IMU rows (TimeMS + 6 floats). Returns the bytes
/// and the offsets where messages start.
fn dataflash(n: u32) -> (Vec<u8>, Vec<usize>) {
    fn fmt(out: &mut Vec<u8>, id: u8, len: u8, name: &str, format: &str, labels: &str) {
        out.extend([0xA3, 0x95, 128, id, len]);
        let mut field = |s: &str, w: usize| {
            let mut b = s.as_bytes().to_vec();
            b.resize(w, 0);
            out.extend(b);
        };
        field(name, 4);
        field(format, 16);
        field(labels, 64);
    }
    let mut out = Vec::new();
    let mut starts = vec![0];
    fmt(
        &mut out,
        128,
        89,
        "FMT",
        "BBnNZ",
        "Type,Length,Name,Format,Columns",
    );
    starts.push(out.len());
    fmt(
        &mut out,
        100,
        3 + 4 + 24,
        "IMU",
        "Iffffff",
        "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
    );
    for i in 0..n {
        starts.push(out.len());
        out.extend([0xA3, 0x95, 100]);
        out.extend((1000 + 20 * i).to_le_bytes());
        for v in [0.01f32, -0.02, 0.03, 0.1, -0.2, -9.8] {
            out.extend(v.to_le_bytes());
        }
    }
    (out, starts)
}

/// A ULog file: header, flag bits, a `sensor_combined` format with a padding field, its
/// subscription and `n` data messages.
fn ulog(n: u64) -> (Vec<u8>, Vec<usize>) {
    let mut out = b"ULog\x01\x12\x35\x01".to_vec();
    out.extend(0u64.to_le_bytes());
    let mut starts = vec![];
    let mut msg = |out: &mut Vec<u8>, kind: u8, body: &[u8]| {
        starts.push(out.len());
        out.extend((body.len() as u16).to_le_bytes());
        out.push(kind);
        out.extend(body);
    };
    msg(&mut out, b'B', &[0u8; 40]);
    msg(
        &mut out,
        b'F',
        b"sensor_combined:uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;uint8_t[4] _padding0;",
    );
    let mut a = vec![0u8, 7, 0];
    a.extend(b"sensor_combined");
    msg(&mut out, b'A', &a);
    for i in 0..n {
        let mut d = vec![7u8, 0];
        d.extend((1_000_000 + 4000 * i).to_le_bytes());
        for v in [0.01f32, -0.02, 0.03, 0.1, -0.2, -9.8] {
            d.extend(v.to_le_bytes());
        }
        d.extend([0u8; 4]);
        msg(&mut out, b'D', &d);
    }
    (out, starts)
}

/// A cut log (the logger stopped mid-write) imports what came before the cut with a note naming
/// an offset at or before it, or (nothing whole left to import) fails clearly; a cut exactly
/// between messages imports without a note.
fn check_cut(data: &[u8], starts: &[usize], cut: usize) {
    let res = import(&data[..cut], &ImportOptions::default());
    let at_boundary = starts.contains(&cut);
    match res {
        Ok(log) => {
            let cut_note = log
                .notes
                .iter()
                .find(|n| n.contains("ends inside a message"));
            if at_boundary {
                assert!(cut_note.is_none(), "cut at boundary {cut}: {cut_note:?}");
            } else {
                let note = cut_note.unwrap_or_else(|| panic!("cut at {cut}: no note"));
                let off: usize = note
                    .split("byte ")
                    .nth(1)
                    .and_then(|r| r.split(':').next())
                    .and_then(|n| n.parse().ok())
                    .unwrap_or_else(|| panic!("cut at {cut}: no offset in {note}"));
                assert!(off <= cut, "cut at {cut}: note at {off}");
            }
        }
        Err(LogError::Unusable(_) | LogError::UnknownFormat) => {}
        Err(e) => {
            let off = e.offset().expect("offset");
            assert!(off as usize <= cut, "cut at {cut}: error at {off}");
            assert!(e.to_string().contains(&format!("byte {off}")), "{e}");
            // only a cut inside the file header fails with an offset
            assert!(cut < 16, "cut at {cut}: {e}");
        }
    }
}

#[test]
fn every_cut_of_a_small_log_is_a_clear_error() {
    let (df, df_starts) = dataflash(5);
    let (ul, ul_starts) = ulog(5);
    for cut in 1..df.len() {
        check_cut(&df, &df_starts, cut);
    }
    for cut in 1..ul.len() {
        check_cut(&ul, &ul_starts, cut);
    }
    // named cases: mid-header and mid-message keep the rows before the cut, with the offset
    let log = import(&df[..df_starts[3] + 2], &ImportOptions::default()).expect("mid-header");
    assert_eq!(log.imu.len(), 1);
    assert!(
        log.notes
            .iter()
            .any(|n| n.contains(&format!("byte {}", df_starts[3])) && n.contains("message header")),
        "{:?}",
        log.notes
    );
    let log = import(&ul[..ul_starts[4] + 10], &ImportOptions::default()).expect("mid-message");
    assert_eq!(log.imu.len(), 1);
    assert!(
        log.notes
            .iter()
            .any(|n| n.contains(&format!("byte {}", ul_starts[4] + 3))),
        "{:?}",
        log.notes
    );
    // with stop_at_damage the rows before the cut are kept
    let opts = ImportOptions {
        stop_at_damage: true,
        ..ImportOptions::default()
    };
    let log = import(&df[..df_starts[5] + 7], &opts).expect("partial");
    assert_eq!(log.imu.len(), 3);
    assert!(
        log.notes
            .iter()
            .any(|n| n.contains(&format!("byte {}", df_starts[5])))
    );
}

#[test]
fn corrupted_header_byte_names_its_offset() {
    let (mut df, starts) = dataflash(5);
    df[starts[4]] = 0x00;
    let e = import(&df, &ImportOptions::default()).expect_err("corrupt");
    assert_eq!(e.offset(), Some(starts[4] as u64));
    assert!(e.to_string().contains("A3 95"), "{e}");
    let (mut df, starts) = dataflash(5);
    df[starts[4] + 2] = 55; // an undeclared message type
    let e = import(&df, &ImportOptions::default()).expect_err("corrupt");
    assert!(e.to_string().contains("not declared"), "{e}");
}

proptest! {
    #[test]
    fn random_corruption_never_panics(pos in 0usize..4096, byte in any::<u8>(), which in 0u8..2, cut in 0usize..4096) {
        let (mut data, _) = if which == 0 { dataflash(20) } else { ulog(20) };
        let pos = pos % data.len();
        data[pos] = byte;
        let cut = cut % (data.len() + 1);
        match import(&data[..cut], &ImportOptions::default()) {
            Ok(_) | Err(LogError::Unusable(_) | LogError::UnknownFormat) => {}
            Err(e) => prop_assert!(e.offset().is_some_and(|o| o as usize <= cut), "{e}"),
        }
    }
}

#[test]
fn cuts_of_the_shared_logs_are_clear_errors() {
    let Some(root) = uavnav_testdata::shared_data("") else {
        return;
    };
    for f in [
        "real_flights/raw/erle_copter_218.BIN",
        "public_flight_logs/sample_log_small.ulg",
    ] {
        let data = std::fs::read(root.join(f)).expect(f);
        for k in 1..200usize {
            let cut = data.len() * k / 200 + k % 7;
            match import(&data[..cut], &ImportOptions::default()) {
                Ok(_) | Err(LogError::Unusable(_)) => {}
                Err(e) => assert!(
                    e.offset().is_some_and(|o| o as usize <= cut),
                    "{f} cut {cut}: {e}"
                ),
            }
        }
    }
}

/// An FMT whose stated length disagrees with its own format string (ArduPilot builds on
/// Erle-Brain declare EKF5 as 28 bytes for a 40-byte format): its messages are framed by the
/// stated length and skipped, with a note, and the rest of the log imports.
#[test]
fn an_fmt_whose_length_contradicts_its_format_is_skipped_with_a_note() {
    let (mut df, _) = dataflash(0);
    let mut ekf5 = vec![0xA3, 0x95, 128, 164, 28];
    for (s, w) in [
        ("EKF5", 4),
        ("QBhhhcccCCfff", 16),
        (
            "TimeUS,NI,FIX,FIY,AFI,HAGL,offset,RI,meaRng,errHAGL,angErr,beaconPosX",
            64,
        ),
    ] {
        let mut b = s.as_bytes().to_vec();
        b.resize(w, 0);
        ekf5.extend(b);
    }
    df.extend(&ekf5);
    for i in 0..4u32 {
        df.extend([0xA3, 0x95, 164]);
        df.extend([0x5Au8; 25]);
        df.extend([0xA3, 0x95, 100]);
        df.extend((1000 + 20 * i).to_le_bytes());
        for v in [0.01f32, -0.02, 0.03, 0.1, -0.2, -9.8] {
            df.extend(v.to_le_bytes());
        }
    }
    let log = import(&df, &ImportOptions::default()).expect("imports");
    assert_eq!(log.imu.len(), 4);
    assert!(
        log.notes
            .iter()
            .any(|n| n.contains("EKF5") && n.contains("28") && n.contains("skipped")),
        "{:?}",
        log.notes
    );
}
