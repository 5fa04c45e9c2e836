//! Running the `prism` binary.

use std::process::{Command, Output};

/// The `prism` binary of this build.
pub fn prism() -> Command {
    Command::new(env!("CARGO_BIN_EXE_prism"))
}

/// Asserts a failure that is neither a panic (exit code 101, or a panic
/// message) nor a signal; returns the standard error.
pub fn assert_failed_without_panic(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let code = out.status.code();
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr: {stderr}"
    );
    assert_ne!(code, Some(101), "prism panicked: {stderr}");
    assert!(code.is_some(), "killed by a signal: {stderr}");
    assert!(
        !stderr.contains("panicked"),
        "panic message in stderr: {stderr}"
    );
    stderr
}

/// Asserts success, showing the standard error otherwise.
pub fn assert_success(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
