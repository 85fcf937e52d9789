//! `pipewave forward --input cases.csv --out results.csv` (`--output` is accepted too).

use std::path::PathBuf;

use clap::Args;

use super::Outcome;

/// Arguments of `forward`.
#[derive(Debug, Args)]
pub struct ForwardArgs {
    /// Cases to evaluate (columns of docs/interface.md, "forward input").
    #[arg(long, value_name = "FILE")]
    input: PathBuf,
    /// Where to write the results (one row per input row), named as in every other command;
    /// `--output`, its older name, is the same option.
    #[arg(long = "out", value_name = "FILE", visible_alias = "output")]
    output: PathBuf,
}

/// Evaluate the cases. Malformed rows are listed on stderr (file:line:col) and get the status
/// `invalid_input`; a root that was not found gets its reason. Exit 1 if any row failed.
pub fn run(args: &ForwardArgs) -> anyhow::Result<Outcome> {
    super::guard_outputs(
        None,
        &[&args.input],
        &[(&args.output, pipewave::outfile::Contents::Plain)],
    )?;
    let report = pipewave::forward::run(&args.input, &args.output)?;
    for m in &report.messages {
        eprintln!("{m}");
    }
    println!(
        "forward: {} rows, {} solved, {} not solved, {} invalid -> {}",
        report.rows,
        report.solved,
        report.failed,
        report.invalid,
        args.output.display()
    );
    Ok(if report.failed + report.invalid > 0 {
        Outcome::SomeFailed
    } else {
        Outcome::Done
    })
}
