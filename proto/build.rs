//! Compiles `uavnav/v1/*.proto` with `protox` (pure Rust, no system `protoc`), writes the encoded
//! `FileDescriptorSet` to `OUT_DIR` (for gRPC reflection and MCAP schemas), and generates the prost
//! messages and tonic client/server from it with `tonic-prost-build`.
//!
//! The Foxglove schemas are resolved from the vendored descriptor sets in `foxglove/` (see its
//! README), and the generated code refers to the `foxglove` crate's types for them.

use std::path::{Path, PathBuf};

use prost::Message;
use protox::file::{ChainFileResolver, DescriptorSetFileResolver, IncludeFileResolver};

/// Our schema files, compiled in this order.
const PROTOS: &[&str] = &[
    "uavnav/v1/common.proto",
    "uavnav/v1/sensors.proto",
    "uavnav/v1/config.proto",
    "uavnav/v1/outputs.proto",
    "uavnav/v1/service.proto",
    // Not imported by our files, but recordings log them on display channels, so their schemas must
    // be in FILE_DESCRIPTOR_SET too.
    "foxglove/LocationFix.proto",
    "foxglove/PoseInFrame.proto",
];

/// Vendored Foxglove descriptor sets.
const FOXGLOVE_SETS: &[&str] = &["CompressedImage.bin", "LocationFix.bin", "PoseInFrame.bin"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    println!("cargo:rerun-if-changed=uavnav");
    println!("cargo:rerun-if-changed=foxglove");

    let mut resolver = ChainFileResolver::new();
    resolver.add(IncludeFileResolver::new(root.clone()));
    resolver.add(DescriptorSetFileResolver::new(foxglove_set(
        &root.join("foxglove"),
    )?));

    let mut compiler = protox::Compiler::with_file_resolver(resolver);
    compiler.include_imports(true).include_source_info(true);
    compiler.open_files(PROTOS)?;

    let fds = compiler.file_descriptor_set();
    std::fs::write(out_dir.join("uavnav_descriptor.bin"), fds.encode_to_vec())?;

    tonic_prost_build::configure()
        .extern_path(".foxglove", "::foxglove::messages")
        // prost encoding; decoding with size limits checked on the wire first (src/codec.rs)
        .codec_path("crate::codec::BoundedCodec")
        .compile_fds(fds)?;
    Ok(())
}

/// Merges the vendored Foxglove descriptor sets into one, each file once.
fn foxglove_set(dir: &Path) -> Result<prost_types::FileDescriptorSet, Box<dyn std::error::Error>> {
    let mut merged = prost_types::FileDescriptorSet::default();
    for name in FOXGLOVE_SETS {
        let bytes = std::fs::read(dir.join(name))?;
        let set = prost_types::FileDescriptorSet::decode(bytes.as_slice())?;
        for file in set.file {
            if !merged.file.iter().any(|f| f.name == file.name) {
                merged.file.push(file);
            }
        }
    }
    Ok(merged)
}
