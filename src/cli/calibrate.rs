//! `pipewave calibrate --db DB [--jobs N] [--seed S] [--force] [--model full|seed]
//! [--contact-mode reciprocal|printed|blend] [--method default|paper] [--effects NAME,...]
//! [--segment ID]... [--wait]`.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use clap::builder::PossibleValuesParser;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pipewave::batch::progress::ProgressLines;
use pipewave::batch::{
    self, BatchError, CalibrateOptions, CalibrateSummary, RunObserver, RunPlan, SegmentDone,
};
use pipewave::db::{Database, DbError, FitStatus};
use pipewave::physics::effects::parse_effects;

use super::Outcome;

/// Arguments of `calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The pipewave database (it must exist: `pipewave import` creates it).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    #[command(flatten)]
    run: RunArgs,
    /// Refit every segment, not only those whose inputs or settings changed.
    #[arg(long)]
    force: bool,
    /// Model variant.
    #[arg(long, default_value = "full", value_parser = PossibleValuesParser::new(["full", "seed"]))]
    model: String,
    /// Reading of the contact coefficient.
    #[arg(long, default_value = "reciprocal",
          value_parser = PossibleValuesParser::new(["reciprocal", "printed", "blend"]))]
    contact_mode: String,
    /// Inversion method: `default` (chi-square, SHADE + polish, restarts) or `paper` (the
    /// paper's DE exactly).
    #[arg(long, default_value = "default", value_parser = PossibleValuesParser::new(["default", "paper"]))]
    method: String,
    /// Effects to switch on, comma-separated: soil_damping, air_in_water, wall_thinning,
    /// pipe_loss, full_model, viscoelastic_wall, inventory_error (fits the candidate records
    /// too and stores the one the data choose, named in the fit's message).
    #[arg(long, value_name = "NAME,...")]
    effects: Option<String>,
    /// Fit only this segment (repeat for several); still only if its fit is stale, unless
    /// --force.
    #[arg(long = "segment", value_name = "ID")]
    segments: Vec<String>,
    /// If another calibrate run is using the database, wait for it instead of failing.
    #[arg(long)]
    wait: bool,
}

/// The arguments `calibrate` shares with `run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Worker threads (default: one per core). Range 1 – 512.
    #[arg(long, value_name = "N", value_parser = super::bounds::jobs())]
    pub jobs: Option<u32>,
    /// Run seed: the same inputs and seed give the same fits, whatever --jobs is. Range 0 –
    /// 18446744073709551615 (2^64 − 1).
    #[arg(long, value_name = "S", default_value_t = batch::DEFAULT_SEED)]
    pub seed: u64,
}

impl CalibrateArgs {
    /// Checked options.
    fn options(&self) -> anyhow::Result<CalibrateOptions> {
        let effects = parse_effects(self.effects.as_deref().unwrap_or(""))?;
        if effects.contains(&pipewave::physics::effects::Effect::MeasurementUnits) {
            anyhow::bail!(
                "--effects measurement_units: a unit mix-up is never applied by calibrate; \
                 re-import corrected measurements, or confirm the one diagnose names with \
                 `pipewave diagnose --convert-units ID=MIXUP`"
            );
        }
        Ok(CalibrateOptions {
            jobs: self.run.jobs.map(|j| j as usize),
            seed: self.run.seed,
            force: self.force,
            method: self.method.parse()?,
            model: self.model.parse()?,
            contact_mode: self.contact_mode.parse()?,
            effects,
            segments: (!self.segments.is_empty()).then(|| self.segments.clone()),
            wait_for_lock: self.wait,
            chunk_size: batch::DEFAULT_CHUNK_SIZE,
        })
    }
}

/// Run `calibrate`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<Outcome> {
    let opts = args.options()?;
    let mut database = super::open_database(&args.db)?;
    execute(&mut database, &opts)
}

/// Set by the Ctrl-C handler: stop scheduling segments.
static STOP: AtomicBool = AtomicBool::new(false);

/// First Ctrl-C: stop scheduling, finish the segments in flight. Second: quit at once (what
/// was committed is kept; the lock is left stale and taken over by the next run).
fn install_interrupt_handler() {
    // Once per process: `run --diagnose` calibrates twice.
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(install_interrupt_handler_now);
}

fn install_interrupt_handler_now() {
    let installed = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted again: quitting now (fits already stored are kept)");
            std::process::exit(i32::from(super::EXIT_INTERRUPTED));
        }
        eprintln!(
            "\ninterrupted: finishing the segments in flight, then stopping (Ctrl-C again to \
             quit at once)"
        );
    });
    if let Err(e) = installed {
        eprintln!("note: Ctrl-C will stop the run at once ({e})");
    }
}

/// Calibrate an open database with progress on stderr and the summary line on stdout; the
/// failed segments are listed on stderr, one line each.
pub fn execute(database: &mut Database, opts: &CalibrateOptions) -> anyhow::Result<Outcome> {
    install_interrupt_handler();
    let mut observer = CliObserver::new(std::io::stderr().is_terminal());
    let path = database.path().display().to_string();
    let result = batch::calibrate(database.conn_mut(), opts, &mut observer, &STOP);
    observer.finish();
    let summary = match result {
        Ok(s) => s,
        Err(BatchError::Db(e @ DbError::Locked { .. })) => {
            return Err(anyhow::Error::new(e)).context(format!(
                "calibrate cannot run on {path} (use --wait to wait for the other run)"
            ))
        }
        Err(e) => return Err(e).context(format!("calibrate of {path} failed")),
    };
    report(&summary);
    Ok(outcome(&summary))
}

/// The exit outcome of a run.
pub fn outcome(s: &CalibrateSummary) -> Outcome {
    if s.interrupted {
        Outcome::Interrupted
    } else if s.failed > 0 {
        Outcome::SomeFailed
    } else {
        Outcome::Done
    }
}

/// Print the failures (stderr) and the summary line (stdout).
fn report(s: &CalibrateSummary) {
    for id in &s.without_measurements {
        eprintln!("segment {id}: no measurements, nothing to fit");
    }
    for (id, msg) in &s.failures {
        eprintln!("segment {id}: no fit: {msg}");
    }
    if s.run_id.is_none() {
        eprintln!("interrupted while waiting for the other run; nothing was done");
        return;
    }
    println!("{}", s.line());
    if let Some(z) = s
        .zones
        .as_ref()
        .filter(|z| z.estimated + z.up_to_date + z.too_few > 0)
    {
        println!("{}", z.line());
    }
    if let Some(f) = &s.field {
        println!("{}", f.line());
    }
}

/// Progress on stderr: a bar on a terminal; otherwise (a log) a plain line every 10 s or 5 %
/// of the segments ([`ProgressLines`]). The summary line comes at the end either way.
struct CliObserver {
    terminal: bool,
    bar: Option<ProgressBar>,
    lines: Option<(ProgressLines, Instant)>,
    counts: [usize; 3],
}

impl CliObserver {
    fn new(terminal: bool) -> Self {
        Self {
            terminal,
            bar: None,
            lines: None,
            counts: [0; 3],
        }
    }

    fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

impl RunObserver for CliObserver {
    fn waiting_for_lock(&mut self, pid: i64, started_at: &str) {
        eprintln!(
            "waiting for another calibrate run (pid {pid}, started {started_at}) to finish..."
        );
    }

    fn took_over_stale_lock(&mut self, pid: i64, started_at: &str) {
        eprintln!(
            "note: the calibrate run of pid {pid} (started {started_at}) no longer exists; its \
             lock was taken over and its run marked interrupted (its stored fits are kept)"
        );
    }

    fn inputs_edited(&mut self, segment_ids: &[String]) {
        const SHOWN: usize = 5;
        let shown: Vec<String> = segment_ids
            .iter()
            .take(SHOWN)
            .map(|s| pipewave::units::escape_controls(s).into_owned())
            .collect();
        eprintln!(
            "note: {} segment{} changed in the database since {} last imported or \
             calibrated (edited with another tool): {}{}; {} refitted",
            segment_ids.len(),
            if segment_ids.len() == 1 { "" } else { "s" },
            if segment_ids.len() == 1 {
                "it was"
            } else {
                "they were"
            },
            shown.join(", "),
            if segment_ids.len() > SHOWN {
                ", ..."
            } else {
                ""
            },
            if segment_ids.len() == 1 {
                "it is"
            } else {
                "they are"
            },
        );
    }

    fn started(&mut self, plan: &RunPlan) {
        if plan.to_fit == 0 {
            return;
        }
        if !self.terminal {
            eprintln!(
                "calibrate: fitting {} segments ({} up to date) with {} jobs",
                plan.to_fit, plan.up_to_date, plan.jobs
            );
            self.lines = Some((ProgressLines::new(plan.to_fit), Instant::now()));
            return;
        }
        let bar = ProgressBar::new(plan.to_fit as u64);
        let style = ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} segments, eta {eta}, {msg}",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_message(format!("({} jobs)", plan.jobs));
        self.bar = Some(bar);
    }

    fn segment_done(&mut self, done: &SegmentDone<'_>) {
        let i = match done.status {
            FitStatus::Ok => 0,
            FitStatus::Flagged => 1,
            FitStatus::Failed => 2,
        };
        self.counts[i] += 1;
        if let Some((lines, start)) = &mut self.lines {
            let [ok, flagged, failed] = self.counts;
            let detail = format!("ok {ok} flagged {flagged} failed {failed}");
            if let Some(line) = lines.line(ok + flagged + failed, start.elapsed(), &detail) {
                eprintln!("{line}");
            }
        }
        if let Some(bar) = &self.bar {
            bar.set_message(format!(
                "ok {} flagged {} failed {}",
                self.counts[0], self.counts[1], self.counts[2]
            ));
            bar.inc(1);
        }
    }
}
