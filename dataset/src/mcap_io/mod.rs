//! MCAP recordings with protobuf schemas, one channel per vehicle and stream.
//!
//! ## Topics
//!
//! The topics (`/uavnav/{vehicle}/{stream}`, one channel per vehicle and stream) are those of
//! [`uavnav_proto::topics`], re-exported here: [`Stream`], [`topic`], [`parse_topic`] (the table is there).
//!
//! ## Times
//!
//! *Publish time* is the sensor time of validity (`t_ns`, the vehicle's sensor clock). *Log time*
//! is when the recorder received or wrote the message: a live recorder passes its wall clock (its
//! inputs go through [`writer::McapWriter::write_input`], the one statement of that layout). For
//! converted or simulated data there is no receive time, so the converters set log time = publish
//! time = `t_ns` (the Foxglove timeline then shows sensor time); configuration and info messages get
//! the time of the first sensor event. MCAP times are unsigned: negative `t_ns` cannot be recorded.
//! Chunks are zstd-compressed by default.

pub mod reader;
pub mod writer;

use std::collections::BTreeSet;

use prost::Message;
use prost_types::FileDescriptorSet;
use uavnav_proto::FILE_DESCRIPTOR_SET;
pub use uavnav_proto::topics::{REFERENCE_METADATA_KEY, Stream, TOPIC_PREFIX, parse_topic, topic};

/// The MCAP `protobuf` schema data for a message: a `FileDescriptorSet` holding the file that
/// defines it and everything it imports (source info stripped to keep recordings small).
pub fn schema_data(message: &str) -> Option<Vec<u8>> {
    let all = FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).ok()?;
    let (package, name) = message.rsplit_once('.')?;
    let root = all
        .file
        .iter()
        .find(|f| f.package() == package && f.message_type.iter().any(|m| m.name() == name))?;
    let mut wanted = BTreeSet::new();
    let mut stack = vec![root.name().to_owned()];
    while let Some(file) = stack.pop() {
        if !wanted.insert(file.clone()) {
            continue;
        }
        if let Some(f) = all.file.iter().find(|f| f.name() == file) {
            stack.extend(f.dependency.iter().cloned());
        }
    }
    // Dependencies first, as protoc orders them.
    let mut out = FileDescriptorSet::default();
    for f in &all.file {
        if wanted.contains(f.name()) {
            let mut f = f.clone();
            f.source_code_info = None;
            out.file.push(f);
        }
    }
    Some(out.encode_to_vec())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn schemas_exist_and_are_self_contained() {
        for s in Stream::ALL {
            let data = schema_data(s.schema()).unwrap();
            let fds = FileDescriptorSet::decode(data.as_slice()).unwrap();
            let names: Vec<_> = fds.file.iter().map(|f| f.name().to_owned()).collect();
            for f in &fds.file {
                for d in &f.dependency {
                    assert!(names.contains(d), "{} needs {d}", s.schema());
                }
            }
        }
    }
}
