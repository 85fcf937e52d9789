//! The calibrate run: choose the segments that need a fit, fit them in parallel, store each one
//! as soon as it is done.
//!
//! Shape (docs/style.md, "Data"): the calling thread holds the database. It takes the run lock,
//! counts the segments to fit, and records the run. Then it reads the segments a page
//! ([`CalibrateOptions::chunk_size`]) at a time, in id order, and hands them one by one to a
//! rayon pool of `jobs` workers, never more than [`IN_FLIGHT_PER_JOB`] per worker ahead of the
//! writes; each worker turns a segment into a fit and its curve and sends it back over a
//! bounded channel. The calling thread is the only writer and commits every segment in its own
//! transaction as it arrives. So a run holds one page of segments and a few fits whatever the
//! size of the network, a run that is killed at any moment loses only the segments in flight,
//! and the next run, which selects the segments whose latest fit is missing or stale, does the
//! rest.
//!
//! Determinism: the seed of a segment is `splitmix64(run_seed ^ fnv1a64(segment_id))`, and a fit
//! depends only on its segment, its settings and that seed, so the stored fits are the same
//! whatever `jobs` is and in whatever order the workers finish.
//!
//! The library prints nothing: progress goes to a [`RunObserver`] the caller supplies, and the
//! outcome is returned as a [`CalibrateSummary`].

mod campaigns;
pub mod progress;
mod summary;

use campaigns::{campaigns_to_test, test_campaigns};
pub use summary::{CalibrateSummary, ChangeCounts};

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::change::CampaignName;
use crate::db::changes::ChangeRecord;
use crate::db::hash::fnv1a64;
use crate::db::inventory::MeasurementRecord;
use crate::db::{
    self, CurvePoint, DbError, FitRow, FitState, FitStatus, NewRun, RunCounts, RunLock, RunStatus,
    SegmentRecord,
};
use crate::invert::{fit_with_effects, FitSettings, Method, Param};
use crate::physics::effects::{effects_text, parse_effects, Effect};
use crate::physics::{ContactMode, Model};
use crate::rows::{self, curve_points, fit_row, segment_data, settings_hash};
use crate::seed::splitmix64;

pub use db::Connection;

/// Seed of a run when none is given (`calibrate --seed`).
pub const DEFAULT_SEED: u64 = 1;

/// Segments a run reads from the database at a time (`CalibrateOptions::chunk_size`): what a
/// run holds is one page of this many segments with their measurements (about 1 kB each) and
/// the fits in flight, so its memory does not grow with the network.
pub const DEFAULT_CHUNK_SIZE: usize = 1024;

/// Segments handed to the workers ahead of the writer, per worker thread: enough that a worker
/// never waits while the writer stores a fit or reads the next page.
pub const IN_FLIGHT_PER_JOB: usize = 2;

/// How often a run started with `wait_for_lock` asks again for the run lock.
pub const LOCK_POLL: Duration = Duration::from_millis(250);

/// What a calibrate run is asked to do (checked values: the CLI parses the arguments into this).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateOptions {
    /// Worker threads; `None`: one per core.
    pub jobs: Option<usize>,
    /// Run seed; each segment's seed derives from it and the segment id.
    pub seed: u64,
    /// Refit every selected segment, even those whose latest fit is current.
    pub force: bool,
    /// Inversion method.
    pub method: Method,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects switched on (sorted, no repeats: as [`crate::physics::effects::parse_effects`]
    /// returns them).
    pub effects: Vec<Effect>,
    /// Only these segments (`None`: every segment with measurements).
    pub segments: Option<Vec<String>>,
    /// When another run holds the lock: wait for it (`true`) or fail at once (`false`).
    pub wait_for_lock: bool,
    /// Segments read from the database at a time (at least 1; [`DEFAULT_CHUNK_SIZE`]). It
    /// bounds the run's memory and changes nothing in the stored fits.
    pub chunk_size: usize,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        Self {
            jobs: None,
            seed: DEFAULT_SEED,
            force: false,
            method: Method::Default,
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            effects: Vec::new(),
            segments: None,
            wait_for_lock: false,
            chunk_size: DEFAULT_CHUNK_SIZE,
        }
    }
}

impl CalibrateOptions {
    /// The fit settings of every segment of the run: the inversion's defaults for the method
    /// (the paper's method runs its DE once, as the paper does).
    pub fn fit_settings(&self) -> FitSettings {
        let base = match self.method {
            Method::Paper => FitSettings::paper(self.model, self.contact_mode),
            Method::Default => FitSettings::default(),
        };
        FitSettings {
            method: self.method,
            model: self.model,
            contact_mode: self.contact_mode,
            effects: self.effects.clone(),
            ..base
        }
    }

    /// The hash stored in `fits.settings_hash`: of the settings that change a fit (method,
    /// model, contact reading, effects), not of the seed or the number of jobs.
    pub fn settings_hash(&self) -> String {
        settings_hash(self.method, self.model, self.contact_mode, &self.effects)
    }

    /// Worker threads this run uses.
    pub fn worker_count(&self) -> usize {
        self.jobs.unwrap_or_else(default_jobs).max(1)
    }
}

/// One worker per core (or 1 when that cannot be told).
pub fn default_jobs() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// The seed of one segment's fit: `splitmix64(run_seed ^ fnv1a64(segment_id))`.
pub fn segment_seed(run_seed: u64, segment_id: &str) -> u64 {
    splitmix64(run_seed ^ fnv1a64(segment_id.as_bytes()))
}

/// What a run found to do, told to the observer before the first fit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunPlan {
    /// The `runs` row.
    pub run_id: i64,
    /// Segments to fit.
    pub to_fit: usize,
    /// Segments in scope whose latest fit is current (not refitted).
    pub up_to_date: usize,
    /// Worker threads.
    pub jobs: usize,
}

/// One segment stored, as told to the observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentDone<'a> {
    /// The segment.
    pub segment_id: &'a str,
    /// Its fit's status.
    pub status: FitStatus,
    /// Comma-separated flag codes (empty: none).
    pub flags: &'a str,
    /// Why the fit failed.
    pub message: Option<&'a str>,
    /// Time its worker spent, ms.
    pub elapsed_ms: f64,
}

/// Watches a run. Every method has an empty default; all are called on the thread that called
/// [`calibrate`].
pub trait RunObserver {
    /// Another run holds the lock and we wait for it (once, when the wait starts).
    fn waiting_for_lock(&mut self, _pid: i64, _started_at: &str) {}
    /// We took over the lock of a run that no longer exists.
    fn took_over_stale_lock(&mut self, _pid: i64, _started_at: &str) {}
    /// Segments whose stored inputs changed since their hash was stored, by another tool than
    /// pipewave's import (their fits are stale), by id; told before the selection.
    fn inputs_edited(&mut self, _segment_ids: &[String]) {}
    /// The run is recorded and the workers start.
    fn started(&mut self, _plan: &RunPlan) {}
    /// One segment's fit was committed.
    fn segment_done(&mut self, _done: &SegmentDone<'_>) {}
}

/// An observer that ignores everything.
impl RunObserver for () {}

/// Why a run could not be done.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The database could not be read or written before the fits started (includes
    /// [`DbError::Locked`]: another run holds the lock).
    #[error(transparent)]
    Db(#[from] DbError),
    /// The worker threads could not be started.
    #[error("cannot start {jobs} worker threads")]
    ThreadPool {
        /// Threads asked for.
        jobs: usize,
        /// What rayon said.
        #[source]
        source: rayon::ThreadPoolBuildError,
    },
    /// A fit could not be stored; the run stopped. The fits stored before are kept.
    #[error(
        "could not store the fit of segment {segment_id}; the run stopped ({stored} fits of \
         run {run_id} were stored and are kept; the next run fits the rest)"
    )]
    Write {
        /// The segment whose fit was being stored.
        segment_id: String,
        /// The run.
        run_id: i64,
        /// Fits this run had stored before.
        stored: usize,
        /// What the database said.
        #[source]
        source: Box<DbError>,
    },
    /// A segment's stored effects (table `segment_effects`) name an unknown effect.
    #[error("segment {segment}: stored effects cannot be read: {message}")]
    StoredEffects {
        /// The segment.
        segment: String,
        /// What is wrong.
        message: String,
    },
}

/// One segment ready for a worker.
struct Job {
    record: SegmentRecord,
    seed: u64,
    /// The run's settings with this segment's own effects added (table `segment_effects`).
    settings: FitSettings,
    /// Hash of `settings`.
    settings_hash: String,
    /// With effects: the fitted values of the segment's stored fit without them, made from
    /// the same inputs (`None`: there is none, the base is fitted first).
    base: Option<Vec<(Param, f64)>>,
    /// The segment's latest campaign (`None`: no measurements).
    latest: Option<CampaignName>,
    /// The campaign before it with its measurements, tested against it (model §7.14).
    earlier: Option<(CampaignName, Vec<MeasurementRecord>)>,
}

/// One segment computed by a worker, ready for the writer.
struct Computed {
    fit: FitRow,
    curve: Vec<CurvePoint>,
    /// The change test and the campaigns' speeds, stored with the fit.
    change: Option<ChangeRecord>,
}

/// Run a calibration on an open, migrated database.
///
/// Takes the run lock (waiting for it if `opts.wait_for_lock`), selects the segments, records a
/// `runs` row, fits the segments on `opts.jobs` threads and stores each fit in its own
/// transaction, then records the run's counts and status and releases the lock.
///
/// `stop` is polled between segments: once it is set no new segment starts, the ones in flight
/// are finished and stored, and the run is recorded as `interrupted`. Also polled while waiting
/// for the lock.
pub fn calibrate(
    conn: &mut Connection,
    opts: &CalibrateOptions,
    observer: &mut dyn RunObserver,
    stop: &AtomicBool,
) -> Result<CalibrateSummary, BatchError> {
    let started = Instant::now();
    let jobs = opts.worker_count();
    let settings_hash = opts.settings_hash();
    let empty = CalibrateSummary {
        run_id: None,
        jobs,
        settings_hash: settings_hash.clone(),
        selected: 0,
        up_to_date: 0,
        algorithm_refits: 0,
        without_measurements: Vec::new(),
        ok: 0,
        flagged: 0,
        failed: 0,
        flag_counts: BTreeMap::new(),
        failures: Vec::new(),
        interrupted: false,
        elapsed_s: 0.0,
        worker_ms: 0.0,
        zones: None,
        field: None,
        changes: ChangeCounts::default(),
    };
    let Some(lock) = acquire_lock(conn, opts.wait_for_lock, observer, stop)? else {
        return Ok(CalibrateSummary {
            interrupted: true,
            elapsed_s: started.elapsed().as_secs_f64(),
            ..empty
        });
    };
    if let Some((pid, at)) = &lock.took_over {
        observer.took_over_stale_lock(*pid, at);
    }
    // The run's time starts once it holds the lock: a wait for another run is not fit time.
    let result = locked_run(conn, opts, observer, stop, empty, Instant::now());
    // Give the lock back whatever happened; a failure to do so is reported only when the run
    // itself succeeded (a stale lock is taken over by the next run anyway).
    let released = db::release_run_lock(conn, &lock);
    let summary = result?;
    released?;
    Ok(summary)
}

/// Take the run lock, waiting for it when asked. `None`: stopped while waiting.
fn acquire_lock(
    conn: &mut Connection,
    wait: bool,
    observer: &mut dyn RunObserver,
    stop: &AtomicBool,
) -> Result<Option<RunLock>, BatchError> {
    let mut told = false;
    loop {
        match db::try_acquire_run_lock(conn) {
            Ok(lock) => return Ok(Some(lock)),
            Err(DbError::Locked { pid, started_at }) if wait => {
                if !told {
                    observer.waiting_for_lock(pid, &started_at);
                    told = true;
                }
                if stop.load(Ordering::SeqCst) {
                    return Ok(None);
                }
                std::thread::sleep(LOCK_POLL);
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// Everything between taking and releasing the lock.
fn locked_run(
    conn: &mut Connection,
    opts: &CalibrateOptions,
    observer: &mut dyn RunObserver,
    stop: &AtomicBool,
    mut summary: CalibrateSummary,
    started: Instant,
) -> Result<CalibrateSummary, BatchError> {
    let jobs = summary.jobs;
    // Staleness from the stored rows themselves: an edit made with any tool since the last
    // import or run makes exactly the edited segments stale.
    let sweep = db::refresh_all_inputs_hashes(conn)?;
    if !sweep.changed.is_empty() {
        observer.inputs_edited(&sweep.changed);
    }
    let selection = Selection::new(conn, opts, &mut summary)?;
    // Count first, a page at a time, for the run's row and the progress bar; the fits then read
    // the inventory again, page by page, as the workers need it.
    let plan = selection.count(conn)?;
    plan.apply(&mut summary);

    let run_id = db::start_run(
        conn,
        &NewRun {
            seed: opts.seed,
            model: opts.model,
            contact_mode: opts.contact_mode,
            method: opts.method.as_str().to_string(),
            effects: effects_text(&opts.effects),
            program_version: env!("CARGO_PKG_VERSION").to_string(),
            jobs: i64::try_from(jobs).ok(),
            n_segments: i64::try_from(plan.to_fit).unwrap_or(i64::MAX),
        },
    )?;
    summary.run_id = Some(run_id);
    if opts.force && plan.to_fit > 0 {
        selection.mark_forced(conn, run_id)?;
    }
    observer.started(&RunPlan {
        run_id,
        to_fit: plan.to_fit,
        up_to_date: summary.up_to_date,
        jobs,
    });

    let written = if plan.to_fit == 0 {
        Ok(true)
    } else {
        let mut feed = Feed::new(&selection);
        fit_and_store(conn, run_id, &mut feed, observer, stop, &mut summary).inspect(|&complete| {
            // What the pages held when they were read is what the run did (the count
            // before differs only if an import ran meanwhile).
            if complete {
                feed.tally.apply(&mut summary);
            }
        })
    };
    summary.interrupted = !matches!(written, Ok(true));
    summary.elapsed_s = started.elapsed().as_secs_f64();
    let status = if summary.interrupted {
        RunStatus::Interrupted
    } else {
        RunStatus::Finished
    };
    let counts = RunCounts {
        n_ok: summary.ok as i64,
        n_flagged: summary.flagged as i64,
        n_failed: summary.failed as i64,
        elapsed_s: Some(summary.elapsed_s),
    };
    let finished = db::finish_run(conn, run_id, &counts, status);
    written?;
    finished?;
    if status == RunStatus::Finished {
        let settings = crate::field::FieldSettings {
            model: opts.model,
            contact_mode: opts.contact_mode,
            jobs,
            force: false,
        };
        let field = crate::field::update_field(conn, Some(run_id), &settings)?;
        summary.zones.clone_from(&field.zones);
        summary.field = Some(field);
    }
    Ok(summary)
}

/// Which segments a run fits, and with what settings: those with measurements whose latest fit
/// is missing or stale under their own settings (the run's, plus the segment's own effects set
/// by `diagnose`), or all of them with `force`; within the named segments, if any.
struct Selection<'a> {
    opts: &'a CalibrateOptions,
    /// The segments named with `opts.segments`.
    named: Option<BTreeSet<&'a str>>,
}

/// What a run does with one segment.
enum Verdict {
    /// No measurements, or not among the named segments.
    OutOfScope,
    /// Its latest fit is current.
    UpToDate,
    /// To fit, with these settings.
    Fit {
        settings: FitSettings,
        settings_hash: String,
        /// Its latest fit was made by another version of the fitting algorithm.
        other_algorithm: bool,
    },
}

/// Segments in scope and to fit, over the pages read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Tally {
    in_scope: usize,
    to_fit: usize,
    algorithm_refits: usize,
}

impl Tally {
    fn add(&mut self, verdict: &Verdict) {
        match verdict {
            Verdict::OutOfScope => {}
            Verdict::UpToDate => self.in_scope += 1,
            Verdict::Fit {
                other_algorithm, ..
            } => {
                self.in_scope += 1;
                self.to_fit += 1;
                self.algorithm_refits += usize::from(*other_algorithm);
            }
        }
    }

    fn apply(&self, summary: &mut CalibrateSummary) {
        summary.selected = self.to_fit;
        summary.algorithm_refits = self.algorithm_refits;
        summary.up_to_date = self.in_scope.saturating_sub(self.to_fit);
    }
}

impl<'a> Selection<'a> {
    /// Check the named segments (an unknown id is an error naming every such id) and note in
    /// `summary` those without measurements. Reads one named segment at a time.
    fn new(
        conn: &Connection,
        opts: &'a CalibrateOptions,
        summary: &mut CalibrateSummary,
    ) -> Result<Selection<'a>, BatchError> {
        let named = opts
            .segments
            .as_ref()
            .map(|ids| ids.iter().map(String::as_str).collect::<BTreeSet<&str>>());
        if let Some(named) = &named {
            let mut missing = Vec::new();
            for &id in named {
                match db::load_segment(conn, id)? {
                    None => missing.push(id),
                    Some(r) if r.measurements.is_empty() => {
                        summary.without_measurements.push(r.segment_id)
                    }
                    Some(_) => {}
                }
            }
            if !missing.is_empty() {
                return Err(DbError::UnknownSegments {
                    ids: missing.join(", "),
                }
                .into());
            }
        }
        Ok(Selection { opts, named })
    }

    /// The verdict on one segment, from its fit state and its own effects (comma-separated).
    fn judge(&self, st: &FitState, own_effects: &str) -> Result<Verdict, BatchError> {
        let named = |id: &str| self.named.as_ref().is_none_or(|n| n.contains(id));
        if !st.has_measurements || !named(&st.segment_id) {
            return Ok(Verdict::OutOfScope);
        }
        let opts = self.opts;
        let mut effects = opts.effects.clone();
        effects.extend(
            parse_effects(own_effects).map_err(|e| BatchError::StoredEffects {
                segment: st.segment_id.clone(),
                message: e.to_string(),
            })?,
        );
        effects.sort();
        effects.dedup();
        let settings_hash = settings_hash(opts.method, opts.model, opts.contact_mode, &effects);
        if !(opts.force || st.is_stale(&settings_hash)) {
            return Ok(Verdict::UpToDate);
        }
        let mut settings = opts.fit_settings();
        settings.effects = effects;
        Ok(Verdict::Fit {
            settings,
            settings_hash,
            other_algorithm: st.made_by_other_algorithm(),
        })
    }

    /// The fitted values of the segment's newest fit under the run's settings without any
    /// effect, made from its current inputs: the base optimum a fit with effects also starts
    /// from (nested fits).
    fn stored_base(
        &self,
        conn: &Connection,
        record: &SegmentRecord,
    ) -> Result<Option<Vec<(Param, f64)>>, BatchError> {
        let opts = self.opts;
        let hash = settings_hash(opts.method, opts.model, opts.contact_mode, &[]);
        let Some(f) = db::fit_with_settings(conn, &record.segment_id, &hash, &record.inputs_hash)?
        else {
            return Ok(None);
        };
        let values = [
            (Param::SoilModulus, f.soil_youngs_modulus_pa),
            (Param::SoilPoisson, f.soil_poisson),
            (Param::Contact, f.contact),
        ];
        Ok(Some(
            values
                .into_iter()
                .filter_map(|(p, v)| Some((p, v?)))
                .collect(),
        ))
    }

    /// Count the segments in scope and to fit, reading the inventory a page at a time.
    fn count(&self, conn: &Connection) -> Result<Tally, BatchError> {
        let mut tally = Tally::default();
        let mut after: Option<String> = None;
        loop {
            let page = db::fit_states_page(conn, after.as_deref(), self.page_size())?;
            for (st, own_effects) in &page {
                tally.add(&self.judge(st, own_effects)?);
            }
            if page.len() < self.page_size() {
                return Ok(tally);
            }
            after = page.last().map(|(st, _)| st.segment_id.clone());
        }
    }

    fn page_size(&self) -> usize {
        self.opts.chunk_size.max(1)
    }

    /// For a forced run: record every segment it is to fit as pending (table `forced_refits`,
    /// a page at a time), so that if the run stops, the next run fits the rest.
    fn mark_forced(&self, conn: &mut Connection, run_id: i64) -> Result<(), BatchError> {
        let mut after: Option<String> = None;
        loop {
            let page = db::fit_states_page(conn, after.as_deref(), self.page_size())?;
            let mut ids = Vec::with_capacity(page.len());
            for (st, own_effects) in &page {
                if let Verdict::Fit { .. } = self.judge(st, own_effects)? {
                    ids.push(st.segment_id.as_str());
                }
            }
            db::mark_forced_refits(conn, run_id, ids)?;
            if page.len() < self.page_size() {
                return Ok(());
            }
            after = page.last().map(|(st, _)| st.segment_id.clone());
        }
    }
}

/// The segments to fit, read from the database a page at a time as the workers need them: a
/// run holds at most one page of segments, whatever the size of the network. A segment is
/// judged when its page is read.
struct Feed<'s> {
    selection: &'s Selection<'s>,
    /// The id the next page starts after (`None`: from the first).
    after: Option<String>,
    /// The last page has been read.
    exhausted: bool,
    /// Jobs of the page read last, not yet handed out.
    ready: VecDeque<Job>,
    /// What the pages read so far held.
    tally: Tally,
}

impl<'s> Feed<'s> {
    fn new(selection: &'s Selection<'s>) -> Self {
        Self {
            selection,
            after: None,
            exhausted: false,
            ready: VecDeque::new(),
            tally: Tally::default(),
        }
    }

    /// The next segment to fit, or `None` when every page has been read and handed out.
    fn next(&mut self, conn: &Connection) -> Result<Option<Job>, BatchError> {
        loop {
            if let Some(job) = self.ready.pop_front() {
                return Ok(Some(job));
            }
            if self.exhausted {
                return Ok(None);
            }
            self.read_page(conn)?;
        }
    }

    /// Every segment was handed out.
    fn is_done(&self) -> bool {
        self.exhausted && self.ready.is_empty()
    }

    fn read_page(&mut self, conn: &Connection) -> Result<(), BatchError> {
        let size = self.selection.page_size();
        let page = db::fit_states_page(conn, self.after.as_deref(), size)?;
        self.exhausted = page.len() < size;
        if let Some((last, _)) = page.last() {
            self.after = Some(last.segment_id.clone());
        }
        let run_seed = self.selection.opts.seed;
        for (st, own_effects) in &page {
            let verdict = self.selection.judge(st, own_effects)?;
            if let Verdict::Fit {
                settings,
                settings_hash,
                ..
            } = &verdict
            {
                // A segment deleted since its state was read is not fitted.
                let Some(record) = db::load_segment(conn, &st.segment_id)? else {
                    continue;
                };
                let base = if settings.effects.is_empty() {
                    None
                } else {
                    self.selection.stored_base(conn, &record)?
                };
                let (latest, earlier) = campaigns_to_test(conn, &record.segment_id)?;
                self.ready.push_back(Job {
                    seed: segment_seed(run_seed, &record.segment_id),
                    record,
                    settings: settings.clone(),
                    settings_hash: settings_hash.clone(),
                    base,
                    latest,
                    earlier,
                });
            }
            self.tally.add(&verdict);
        }
        Ok(())
    }
}

/// The pool, the workers and the writer loop. The calling thread reads the segments from the
/// feed and hands them to the workers one at a time, never more than [`IN_FLIGHT_PER_JOB`] ×
/// `jobs` ahead of the writes, so neither channel nor the feed grows with the network.
/// Returns whether every selected segment was fitted and stored (false: stopped first).
fn fit_and_store(
    conn: &mut Connection,
    run_id: i64,
    feed: &mut Feed<'_>,
    observer: &mut dyn RunObserver,
    stop: &AtomicBool,
    summary: &mut CalibrateSummary,
) -> Result<bool, BatchError> {
    let jobs = summary.jobs;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .thread_name(|i| format!("pipewave-fit-{i}"))
        .build()
        .map_err(|source| BatchError::ThreadPool { jobs, source })?;
    // Set when the writer or the feed fails: the workers stop fitting.
    let abort = AtomicBool::new(false);
    let window = IN_FLIGHT_PER_JOB * jobs;
    // Jobs go out one by one while fewer than `window` are unanswered, and every job is
    // answered once (`None`: skipped because the run is stopping), so neither channel ever
    // holds more than `window` messages.
    let (job_tx, job_rx) = mpsc::channel::<Job>();
    let job_rx = Mutex::new(job_rx);
    let (tx, rx) = mpsc::sync_channel::<Option<Computed>>(window);
    let mut error: Option<BatchError> = None;
    let mut skipped = 0usize;

    std::thread::scope(|scope| {
        let (abort, job_rx, pool) = (&abort, &job_rx, &pool);
        scope.spawn(move || {
            pool.broadcast(|_| {
                let tx = tx.clone();
                loop {
                    // Nothing panics while holding the lock, so it cannot be poisoned.
                    let next = job_rx.lock().unwrap_or_else(PoisonError::into_inner).recv();
                    let Ok(job) = next else { break };
                    let result = (!stop.load(Ordering::SeqCst) && !abort.load(Ordering::SeqCst))
                        .then(|| compute(&job, run_id));
                    // The writer hangs up only when it is gone, when results are dropped anyway.
                    if tx.send(result).is_err() {
                        break;
                    }
                }
            });
        });
        let mut in_flight = 0usize;
        loop {
            while in_flight < window && error.is_none() && !stop.load(Ordering::SeqCst) {
                match feed.next(conn) {
                    Ok(Some(job)) => {
                        if job_tx.send(job).is_err() {
                            break;
                        }
                        in_flight += 1;
                    }
                    Ok(None) => break,
                    Err(e) => {
                        abort.store(true, Ordering::SeqCst);
                        error = Some(e);
                    }
                }
            }
            if in_flight == 0 {
                break;
            }
            let Ok(result) = rx.recv() else { break };
            in_flight -= 1;
            let Some(c) = result else {
                skipped += 1;
                continue;
            };
            if error.is_some() {
                continue; // drain what is in flight; nothing more is stored
            }
            match db::insert_fit_with_change(conn, &c.fit, &c.curve, c.change.as_ref()) {
                Ok(_) => {
                    summary.record(&c.fit);
                    summary.record_change(c.change.as_ref());
                    observer.segment_done(&SegmentDone {
                        segment_id: &c.fit.segment_id,
                        status: c.fit.status,
                        flags: &c.fit.flags,
                        message: c.fit.message.as_deref(),
                        elapsed_ms: c.fit.elapsed_ms.unwrap_or(0.0),
                    });
                }
                Err(source) => {
                    abort.store(true, Ordering::SeqCst);
                    error = Some(BatchError::Write {
                        segment_id: c.fit.segment_id.clone(),
                        run_id,
                        stored: summary.stored(),
                        source: Box::new(source),
                    });
                }
            }
        }
        // The workers end once the job channel is closed and empty.
        drop(job_tx);
    });
    match error {
        Some(e) => Err(e),
        None => Ok(feed.is_done() && skipped == 0),
    }
}

/// A worker's job: inputs, fit, curve. Never panics: an invalid stored input or a panic inside
/// the fit becomes a failed fit with its reason.
fn compute(job: &Job, run_id: i64) -> Computed {
    let (settings, settings_hash) = (&job.settings, job.settings_hash.as_str());
    let t0 = Instant::now();
    let rec = &job.record;
    // An effect the material cannot have (a plastic wall does not thin) is left out, noted.
    let notes: Vec<String> = settings
        .effects
        .iter()
        .filter_map(|e| e.not_applicable_note(rec.material))
        .collect();
    let applicable = FitSettings {
        effects: settings
            .effects
            .iter()
            .copied()
            .filter(|e| e.applies_to(rec.material))
            .collect(),
        ..settings.clone()
    };
    let settings = if notes.is_empty() {
        settings
    } else {
        &applicable
    };
    let outcome = catch_unwind(AssertUnwindSafe(|| {
        segment_data(rec).map(|data| {
            // inventory_error is a choice among records, not a model input (model §8 E8).
            let mut result = if settings.effects.contains(&Effect::InventoryError) {
                crate::diagnose::inventory::fit_with_records(&data, settings, job.seed).fit
            } else {
                // With effects: also from the base optimum (nested fits), one path with the
                // diagnosis's refits.
                fit_with_effects(&data, settings, job.seed, job.base.clone())
            };
            let change = test_campaigns(job, run_id, &data, settings, &mut result);
            if !notes.is_empty() {
                let mut words = notes.join("; ");
                if let Some(m) = result.message.take() {
                    words = format!("{words}; {m}");
                }
                result.message = Some(words);
            }
            let curve = curve_points(&result);
            (result, curve, change)
        })
    }));
    let (mut fit, curve, change) = match outcome {
        Ok(Ok((result, curve, change))) => {
            let mut row = fit_row(rec, run_id, &result);
            if let Some(c) = change.as_ref().filter(|c| c.change.pooled) {
                // The current fit pools the latest campaign with the one before it.
                row.campaigns = format!(
                    "{},{}",
                    c.change.campaign,
                    c.change.since_campaign.as_deref().unwrap_or_default()
                );
            }
            (row, curve, change)
        }
        Ok(Err(e)) => (
            rows::failed_row(rec, run_id, settings, format!("invalid inputs: {e}")),
            Vec::new(),
            None,
        ),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            (
                rows::failed_row(
                    rec,
                    run_id,
                    settings,
                    format!("internal error in the fit (please report it): {what}"),
                ),
                Vec::new(),
                None,
            )
        }
    };
    fit.seed = Some(job.seed);
    fit.inputs_hash = rec.inputs_hash.clone();
    fit.settings_hash = settings_hash.to_string();
    fit.elapsed_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
    Computed { fit, curve, change }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_hash_depends_on_settings_but_not_on_effect_order() {
        let h = |m, md, c, e: &[Effect]| settings_hash(m, md, c, e);
        let base = h(Method::Default, Model::Full, ContactMode::Reciprocal, &[]);
        assert_eq!(base.len(), 16);
        assert_ne!(
            base,
            h(Method::Paper, Model::Full, ContactMode::Reciprocal, &[])
        );
        assert_ne!(
            base,
            h(Method::Default, Model::Seed, ContactMode::Reciprocal, &[])
        );
        assert_ne!(
            base,
            h(Method::Default, Model::Full, ContactMode::Blend, &[])
        );
        let e1 = h(
            Method::Default,
            Model::Full,
            ContactMode::Reciprocal,
            &[Effect::SoilDamping, Effect::PipeLoss],
        );
        let e2 = h(
            Method::Default,
            Model::Full,
            ContactMode::Reciprocal,
            &[Effect::PipeLoss, Effect::SoilDamping],
        );
        assert_eq!(e1, e2);
        assert_ne!(e1, base);
        // The seed and the jobs are not part of it.
        let a = CalibrateOptions {
            seed: 5,
            jobs: Some(1),
            ..Default::default()
        };
        let b = CalibrateOptions {
            seed: 6,
            jobs: Some(7),
            ..Default::default()
        };
        assert_eq!(a.settings_hash(), b.settings_hash());
        assert_eq!(a.settings_hash(), base);
    }

    /// Pinned: a change would refit every segment of every database after an upgrade.
    #[test]
    fn settings_hash_is_pinned() {
        assert_eq!(
            CalibrateOptions::default().settings_hash(),
            settings_hash(Method::Default, Model::Full, ContactMode::Reciprocal, &[])
        );
        assert_eq!(
            CalibrateOptions::default().settings_hash(),
            crate::db::hash::fnv1a64_hex(
                "pipewave-settings-v1=s20:pipewave-settings-v1\nmethod=s7:default\n\
                 model=s4:full\ncontact_mode=s10:reciprocal\neffects=s0:\n"
            )
        );
    }

    #[test]
    fn segment_seeds_differ_between_segments_and_runs() {
        let a = segment_seed(1, "WM10001");
        assert_eq!(a, segment_seed(1, "WM10001"));
        assert_ne!(a, segment_seed(1, "WM10002"));
        assert_ne!(a, segment_seed(2, "WM10001"));
        assert_eq!(a, splitmix64(1 ^ fnv1a64(b"WM10001")));
    }

    #[test]
    fn summary_line_names_counts_flags_and_interruption() {
        let mut s = CalibrateSummary {
            run_id: Some(3),
            jobs: 2,
            settings_hash: String::new(),
            selected: 5,
            up_to_date: 7,
            algorithm_refits: 0,
            without_measurements: Vec::new(),
            ok: 2,
            flagged: 1,
            failed: 1,
            flag_counts: [("at_bound".to_string(), 1)].into_iter().collect(),
            failures: vec![("A".into(), "no".into())],
            interrupted: true,
            elapsed_s: 2.0,
            worker_ms: 0.0,
            zones: None,
            field: None,
            changes: ChangeCounts::default(),
        };
        assert_eq!(
            s.line(),
            "calibrate: 4 fitted (2 ok, 1 flagged: at_bound 1; 1 failed), 7 up to date, in \
             2.0 s (2.0 segments/s, 2 jobs); interrupted: 1 not fitted (the next run fits them)"
        );
        s.interrupted = false;
        s.jobs = 1;
        assert!(
            s.line().ends_with("(2.0 segments/s, 1 job)"),
            "{}",
            s.line()
        );
    }
}
