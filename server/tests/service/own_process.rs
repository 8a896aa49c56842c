//! Tests that change the whole process (its open-file limit: `fd_exhaustion`) or measure it (its
//! peak resident memory: `amplification`) run in a child process of this test binary, alone, so
//! that the other tests neither disturb them nor are disturbed. They used to be test binaries of
//! their own, and each linked the whole service once more.

use std::process::Command;

/// Set in the child's environment: there the test runs its body.
const CHILD: &str = "UAVNAV_TEST_IN_OWN_PROCESS";

/// In the parent: runs the test `name` (its full path in this binary, e.g.
/// `fd_exhaustion::accept_errors_back_off_instead_of_spinning`) in a child process of this
/// binary, passes its output on, fails when it fails or ran no test, and returns `true`: the
/// caller returns at once. In the child: returns `false`, and the caller runs the test's body.
pub fn ran_in_own_process(name: &str) -> bool {
    if std::env::var_os(CHILD).is_some() {
        return false;
    }
    let exe = std::env::current_exe().expect("the test binary's own path");
    let out = Command::new(exe)
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .output()
        .expect("the test binary runs as a child");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    print!("{stdout}");
    eprint!("{stderr}");
    assert!(out.status.success(), "{name} failed in its own process");
    // A name that matches no test runs nothing, and that passes: make it fail instead.
    assert!(
        stdout.contains("1 passed"),
        "{name}: not exactly one test ran in the child process"
    );
    true
}
