//! `uavnavd`: see the library's `run`.

use std::process::ExitCode;

/// mimalloc instead of the system allocator: at fleet scale the service allocates and frees a few
/// small buffers per message (decoded envelopes, acks, pose batches), and glibc's malloc/free took
/// about 9 % of its CPU (perf, 1500 vehicles).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    // The allocator options of a long-running service (see `allocator`): re-executes once.
    uavnavd::allocator::apply_service_options();
    uavnavd::run()
}
