//! `diagnose` over a database: diagnose the latest fit of each segment, store the extended fit
//! of every segment whose missing effect was named (step 3, "Add"), and write the report
//! (step 4, "Show").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use rusqlite::Connection;

use super::report::{evidence, write_csv, write_html};
use super::{diagnose_segment, pool, DiagnoseSettings, Diagnosis};
use crate::batch::{curve_points, fit_row, segment_data, settings_hash};
use crate::db::{self, DbError, NewRun, RunCounts, RunStatus, SegmentRecord};
use crate::invert::{fit_segment, FitSettings, FitStatus, Method};
use crate::physics::effects::{effects_text, parse_effects, Effect};
use crate::physics::{ContactMode, Model};

/// Options of a diagnosis run.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseOptions {
    /// Only these segments (None: every segment with a fit).
    pub segments: Option<Vec<String>>,
    /// Worker threads.
    pub jobs: usize,
    /// Store the extended fits and the segments' effects (step 3).
    pub apply: bool,
    /// Candidate effects.
    pub candidates: Vec<Effect>,
    /// Report directory.
    pub out_dir: PathBuf,
}

/// Errors of a diagnosis run.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// The database.
    #[error(transparent)]
    Db(#[from] DbError),
    /// The report could not be written.
    #[error("cannot write the report in {dir}: {message}")]
    Report {
        /// The directory.
        dir: PathBuf,
        /// Why.
        message: String,
    },
    /// The worker threads could not be started.
    #[error("cannot start {0} worker threads")]
    Threads(usize),
}

/// What a diagnosis run did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DiagnoseSummary {
    /// Segments diagnosed.
    pub diagnosed: usize,
    /// Segments with misfit far above the noise.
    pub structured: usize,
    /// Named effects and how often.
    pub named: BTreeMap<String, usize>,
    /// Segments skipped, with the reason.
    pub skipped: Vec<(String, String)>,
    /// The run that stored the extended fits, if any.
    pub run_id: Option<i64>,
    /// Extended fits stored.
    pub stored: usize,
}

impl DiagnoseSummary {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let named: Vec<String> = self.named.iter().map(|(e, n)| format!("{e} {n}")).collect();
        format!(
            "diagnose: {} segments, {} with misfit far above the noise; named: {}; {} extended fits stored; {} skipped",
            self.diagnosed,
            self.structured,
            if named.is_empty() { "none".to_string() } else { named.join(", ") },
            self.stored,
            self.skipped.len()
        )
    }
}

/// The groups a segment is pooled in: its material, diameter class and soil type.
pub fn groups_of(rec: &SegmentRecord) -> Vec<String> {
    let od = rec.outer_diameter_mm;
    let class = if od < 100.0 {
        "<100 mm"
    } else if od < 200.0 {
        "100-200 mm"
    } else if od < 300.0 {
        "200-300 mm"
    } else {
        ">=300 mm"
    };
    let mut g = vec![
        format!("material={}", rec.material.code()),
        format!("diameter={class}"),
    ];
    if let Some(s) = rec.soil_type.as_deref().filter(|s| !s.is_empty()) {
        g.push(format!("soil={s}"));
    }
    g
}

/// One diagnosed segment.
struct Done {
    record: SegmentRecord,
    settings: DiagnoseSettings,
    diagnosis: Diagnosis,
}

/// Diagnose, store, report.
pub fn diagnose_database(
    conn: &mut Connection,
    opts: &DiagnoseOptions,
) -> Result<DiagnoseSummary, DiagnoseError> {
    let lock = db::try_acquire_run_lock(conn)?;
    let result = locked(conn, opts);
    let released = db::release_run_lock(conn, &lock);
    let s = result?;
    released?;
    Ok(s)
}

fn locked(conn: &mut Connection, opts: &DiagnoseOptions) -> Result<DiagnoseSummary, DiagnoseError> {
    let mut summary = DiagnoseSummary::default();
    let records = db::load_segments(conn, opts.segments.as_deref())?;
    let fits: BTreeMap<String, db::FitRow> = db::latest_fits(conn, opts.segments.as_deref())?
        .into_iter()
        .map(|f| (f.segment_id.clone(), f))
        .collect();
    let mut todo = Vec::new();
    for rec in records {
        match fits.get(&rec.segment_id) {
            None => summary.skipped.push((
                rec.segment_id.clone(),
                "no fit yet (run calibrate first)".into(),
            )),
            Some(f) if f.status == db::FitStatus::Failed => summary
                .skipped
                .push((rec.segment_id.clone(), "its fit failed".into())),
            Some(f) => {
                let base_effects = parse_effects(&f.effects).unwrap_or_default();
                let settings = DiagnoseSettings {
                    model: f.model,
                    contact_mode: f.contact_mode,
                    base_effects,
                    candidates: opts.candidates.clone(),
                    seed: f.seed.unwrap_or(1),
                };
                // The stored fit's method, so that its refit below reproduces it ("diagnose"
                // rows were made by the default method).
                let method: Method = f.method.parse().unwrap_or(Method::Default);
                todo.push((rec, settings, method));
            }
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|_| DiagnoseError::Threads(opts.jobs))?;
    let done: Vec<Result<Done, (String, String)>> = pool.install(|| {
        todo.into_par_iter()
            .map(|(record, settings, method)| {
                // A panic inside one segment's diagnosis skips that segment with its reason
                // instead of ending the run.
                let id = record.segment_id.clone();
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    let data = segment_data(&record)
                        .map_err(|e| (record.segment_id.clone(), format!("invalid inputs: {e}")))?;
                    // The current fit, reproduced: same settings and seed give the stored fit
                    // bit for bit. Without stated stds the diagnosis refits with assumed noise.
                    let has_stds = data
                        .measurements
                        .iter()
                        .all(|m| m.k_re_std.is_some() && m.attenuation_std.is_some());
                    let base = has_stds.then(|| {
                        fit_segment(
                            &data,
                            &FitSettings {
                                method,
                                model: settings.model,
                                contact_mode: settings.contact_mode,
                                effects: settings.base_effects.clone(),
                                ..FitSettings::default()
                            },
                            settings.seed,
                        )
                    });
                    let diagnosis = diagnose_segment(&data, base, &settings);
                    Ok::<_, (String, String)>(Done {
                        record,
                        settings,
                        diagnosis,
                    })
                }))
                .unwrap_or_else(|_| {
                    Err((
                        id,
                        "internal error in the diagnosis (please report it)".into(),
                    ))
                })
            })
            .collect()
    });
    let mut diags = Vec::new();
    for d in done {
        match d {
            Ok(d) => diags.push(d),
            Err(skip) => summary.skipped.push(skip),
        }
    }
    summary.diagnosed = diags.len();
    summary.structured = diags
        .iter()
        .filter(|d| d.diagnosis.structure.structured)
        .count();
    for d in &diags {
        if let Some(e) = d.diagnosis.named {
            *summary.named.entry(e.name().to_string()).or_default() += 1;
        }
    }
    if opts.apply {
        store(conn, &diags, opts, &mut summary)?;
    }
    report(&diags, &opts.out_dir)?;
    Ok(summary)
}

/// Step 3: a new fit row per named effect, and the segment's effects for the next calibrate.
fn store(
    conn: &mut Connection,
    diags: &[Done],
    opts: &DiagnoseOptions,
    summary: &mut DiagnoseSummary,
) -> Result<(), DiagnoseError> {
    let named: Vec<&Done> = diags
        .iter()
        .filter(|d| d.diagnosis.named.is_some())
        .collect();
    if named.is_empty() {
        return Ok(());
    }
    let t0 = std::time::Instant::now();
    let run_id = db::start_run(
        conn,
        &NewRun {
            seed: 0,
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            method: "diagnose".into(),
            effects: String::new(),
            program_version: env!("CARGO_PKG_VERSION").into(),
            jobs: i64::try_from(opts.jobs).ok(),
            n_segments: named.len() as i64,
        },
    )?;
    let mut counts = RunCounts::default();
    for d in named {
        let Some(refit) = d.diagnosis.chosen() else {
            continue;
        };
        let fit = &refit.fit;
        let mut row = fit_row(&d.record, run_id, fit);
        let effects = fit.effects.clone();
        row.seed = Some(d.settings.seed);
        row.inputs_hash = d.record.inputs_hash.clone();
        row.settings_hash = settings_hash(
            Method::Default,
            d.settings.model,
            d.settings.contact_mode,
            &effects,
        );
        let ev = evidence(&d.diagnosis);
        row.message = Some(format!(
            "diagnose: added {}{}: {ev}",
            d.diagnosis.named.map(|e| e.name()).unwrap_or(""),
            if d.diagnosis.assumed_noise {
                " (noise assumed: 1 % Re k, 10 % attenuation)"
            } else {
                ""
            }
        ));
        let curve = curve_points(&fit);
        db::insert_fit_with_curves(conn, &row, &curve)?;
        db::set_segment_effects(
            conn,
            &d.record.segment_id,
            &effects_text(&effects),
            "diagnose",
            &ev,
        )?;
        match fit.status {
            FitStatus::Ok => counts.n_ok += 1,
            FitStatus::Flagged => counts.n_flagged += 1,
            FitStatus::Failed => counts.n_failed += 1,
        }
        summary.stored += 1;
    }
    counts.elapsed_s = Some(t0.elapsed().as_secs_f64());
    db::finish_run(conn, run_id, &counts, RunStatus::Finished)?;
    summary.run_id = Some(run_id);
    Ok(())
}

/// Step 4: `diagnosis.csv` and `diagnosis.html` in `dir`.
fn report(diags: &[Done], dir: &Path) -> Result<(), DiagnoseError> {
    let err = |m: String| DiagnoseError::Report {
        dir: dir.to_path_buf(),
        message: m,
    };
    std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    let ids: Vec<String> = diags.iter().map(|d| d.record.segment_id.clone()).collect();
    let all_groups: Vec<Vec<String>> = diags.iter().map(|d| groups_of(&d.record)).collect();
    let ds: Vec<Diagnosis> = diags.iter().map(|d| d.diagnosis.clone()).collect();
    let findings = pool(&ds, &all_groups);
    // The group column: the pooled groups of the segment in which its named effect is also
    // the group's most named one.
    let group_col: Vec<String> = ds
        .iter()
        .zip(&all_groups)
        .map(|(d, gs)| {
            gs.iter()
                .filter(|g| {
                    findings.iter().any(|f| {
                        &f.group == *g && f.effect.is_some() && f.effect == d.named && f.named >= 2
                    })
                })
                .cloned()
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect();
    write_csv(&dir.join("diagnosis.csv"), &ids, &ds, &group_col).map_err(|e| err(e.to_string()))?;
    write_html(&dir.join("diagnosis.html"), &ids, &ds, &findings)
        .map_err(|e| err(e.to_string()))?;
    Ok(())
}
