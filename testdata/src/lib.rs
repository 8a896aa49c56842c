//! Where the tests find the shared real data (`<workspace>/../shared/data`), or why they skip.
//!
//! A crate of its own, with no dependencies, so that the pure crates' real-data tests (dataset,
//! logs, estimator) need nothing else: the test kit `uavnav-tests`, which re-exports
//! [`shared_data`], depends on the service, and every test binary that used it for this one
//! function linked zenoh and tonic and waited for them to build.

use std::path::PathBuf;

/// `<workspace>/../shared/data/<sub>`, when present. A user's clone has no `../shared`: the
/// caller's test then skips, and this says so on stderr with the path it looked for.
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data"));
    let p = root.join(sub);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "skipping: {} not found (the shared real data sits beside the repository; a user's \
             clone has none)",
            p.display()
        );
        None
    }
}
