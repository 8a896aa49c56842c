//! The ASL/EuRoC folder format extended with `gnss0` (layout in [`layout`]).

pub mod conversion;
pub mod layout;
pub mod reader;
pub mod sensor_yaml;
pub mod writer;

pub use reader::{AslDataset, DEFAULT_VEHICLE_ID, MissingImages};
pub use writer::AslWriter;
