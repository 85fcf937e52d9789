//! Defects of issue 62 (see main.rs).

use crate::common::cli::pipewave;

#[test]
fn the_binary_runs() {
    assert!(pipewave()
        .arg("--version")
        .output()
        .unwrap()
        .status
        .success());
}
