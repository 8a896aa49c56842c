//! The wire contract: descriptor set contents, Foxglove schema drift, and message round trips.

#![allow(clippy::unwrap_used)] // tests may unwrap

use prost::Message;
use prost_types::FileDescriptorSet;
use uavnav_proto::{FILE_DESCRIPTOR_SET, names, v1};

fn descriptor_set() -> FileDescriptorSet {
    FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap()
}

#[test]
fn descriptor_set_holds_every_schema() {
    let fds = descriptor_set();
    let mut full_names = Vec::new();
    for f in &fds.file {
        for m in &f.message_type {
            full_names.push(format!("{}.{}", f.package(), m.name()));
        }
    }
    for name in [
        names::IMU_BATCH,
        names::GNSS_FIX,
        names::CAMERA_FRAME,
        names::VEHICLE_CONFIG,
        names::POSE_ESTIMATE,
        names::VEHICLE_HEALTH,
        names::TRUTH_SAMPLE,
        names::DATASET_INFO,
        names::FOXGLOVE_COMPRESSED_IMAGE,
        names::FOXGLOVE_LOCATION_FIX,
        names::FOXGLOVE_POSE_IN_FRAME,
        "uavnav.v1.SensorEnvelope",
    ] {
        assert!(
            full_names.iter().any(|n| n == name),
            "{name} missing from FILE_DESCRIPTOR_SET"
        );
    }
    let service = fds
        .file
        .iter()
        .flat_map(|f| &f.service)
        .find(|s| s.name() == "UavNav")
        .unwrap();
    let rpcs: Vec<_> = service.method.iter().map(|m| m.name().to_owned()).collect();
    assert_eq!(
        rpcs,
        [
            "Ingest",
            "WatchPoses",
            "WatchHealth",
            "GetPose",
            "ListVehicles",
            "ConfigureVehicle",
            "ResetVehicle"
        ]
    );
}

#[test]
fn every_uavnav_field_is_documented() {
    // Source info is kept, so every field of ours must carry a leading comment (unit and frame).
    let fds = descriptor_set();
    for f in fds.file.iter().filter(|f| f.package() == "uavnav.v1") {
        let info = f.source_code_info.as_ref().unwrap();
        for (mi, m) in f.message_type.iter().enumerate() {
            for (fi, field) in m.field.iter().enumerate() {
                let path = [4, mi as i32, 2, fi as i32];
                let loc = info.location.iter().find(|l| l.path == path);
                let doc = loc
                    .and_then(|l| l.leading_comments.clone())
                    .unwrap_or_default();
                assert!(
                    !doc.trim().is_empty(),
                    "{}.{} in {} has no comment",
                    m.name(),
                    field.name(),
                    f.name()
                );
            }
        }
    }
}

#[test]
fn foxglove_descriptors_match_crate() {
    use foxglove::Encode;
    use foxglove::messages::{CompressedImage, LocationFix, PoseInFrame};
    let vendored: [(&[u8], Option<foxglove::Schema>); 3] = [
        (
            include_bytes!("../foxglove/CompressedImage.bin"),
            CompressedImage::get_schema(),
        ),
        (
            include_bytes!("../foxglove/LocationFix.bin"),
            LocationFix::get_schema(),
        ),
        (
            include_bytes!("../foxglove/PoseInFrame.bin"),
            PoseInFrame::get_schema(),
        ),
    ];
    for (bytes, schema) in vendored {
        let schema = schema.unwrap();
        assert_eq!(
            schema.data.as_ref(),
            bytes,
            "vendored {} differs from the foxglove crate",
            schema.name
        );
    }
}

#[test]
fn envelope_round_trips_through_bytes() {
    let env = v1::SensorEnvelope {
        vehicle_id: "uav-7".into(),
        sequence: 42,
        payload: Some(v1::sensor_envelope::Payload::Imu(v1::ImuBatch {
            samples: vec![v1::ImuSample {
                t_ns: 5,
                gyro_x_radps: 0.25,
                accel_z_mps2: -9.81,
                ..Default::default()
            }],
        })),
    };
    let back = v1::SensorEnvelope::decode(env.encode_to_vec().as_slice()).unwrap();
    assert_eq!(back, env);
}
