//! Running the real binary from integration tests, as a user would.

use std::process::Command;

/// Run `pipewave ARGS`, fail the test with both streams unless it succeeds, return its stdout.
pub fn run_ok(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(args)
        .output()
        .expect("run pipewave");
    assert!(
        out.status.success(),
        "pipewave {args:?} failed ({:?}):\n{}\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
