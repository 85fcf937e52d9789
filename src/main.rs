//! The `pipewave` binary: parse the command line, run the command, print the error chain once,
//! and exit with the code of docs/interface.md (0 done, 1 some segments failed, 2 could not run).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
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
