//! The `pipewave` binary: parse the command line, run the command, print the error chain once,
//! and exit with the code of docs/interface.md (0 done, 1 some segments failed, 2 could not run).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    restore_sigpipe();
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(outcome) => outcome.exit_code(),
        Err(e) => {
            // The chain may quote input text: control characters are escaped.
            eprintln!(
                "error: {}",
                pipewave::units::escape_controls(&format!("{e:#}"))
            );
            ExitCode::from(cli::EXIT_CANNOT_RUN)
        }
    }
}

/// Give SIGPIPE back its default action, which Rust's runtime sets to "ignore" before `main`.
///
/// A reader that stops early (`pipewave run net | head -1`) then ends the process as it ends
/// `cat` or `grep`: quietly, with the status of a process killed by SIGPIPE (141 in a shell),
/// at the first write after the reader left. Ignored, the write fails with EPIPE and every
/// `println!` panics (exit 101). Handling `BrokenPipe` at each of the commands' many printing
/// sites instead would be easy to miss at one of them, and would change nothing a user can
/// see. Being killed at a write to stdout keeps what was done before it whole: SQLite's
/// transactions are atomic, a calibrate run's lock is taken over once its process is gone, and
/// the commands print a file's line after writing it.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: `signal` only changes this process's disposition of SIGPIPE; no handler runs,
    // and no other thread exists yet.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
