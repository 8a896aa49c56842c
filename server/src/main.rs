//! `uavnavd`: see the library's `run`.

use std::process::ExitCode;

fn main() -> ExitCode {
    uavnavd::run()
}
