//! Running the `pipewave` binary from the integration tests.

use std::process::{Command, Output};

/// The `pipewave` binary of this build.
pub fn pipewave() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

/// Run `pipewave args…`, asserting that it succeeds (its output in the failure message).
pub fn ok(args: &[&str]) -> Output {
    let out = pipewave().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "pipewave {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
