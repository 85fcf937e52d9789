//! `diagnose` over a database: diagnose the latest fit of each segment, store the extended fit
//! of every segment whose missing effect was named (step 3, "Add"), and write the report
//! (step 4, "Show").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use rusqlite::Connection;

use super::group::{
    group_key, member_gains_and_refits, rank_twins, test_groups, DiagnosedMembers, GroupBy,
    GroupTest,
};
use super::inventory::{InventoryPipe, InventoryProfile};
use super::report::{evidence, write_csv, write_groups_csv, write_html, GroupRow};
use super::units::{convert_measurements, UnitMixUp};
use super::{diagnose_segment, extended_fit, DiagnoseSettings, Diagnosis};
use crate::db::{self, DbError, NewRun, RunCounts, RunStatus, SegmentRecord};
use crate::invert::{fit_segment, FitSettings, Method};
use crate::physics::effects::{effects_text, parse_effects, Effect};
use crate::physics::{ContactMode, Model};
use crate::rows::{curve_points, fit_row, segment_data, settings_hash};
use crate::types::FitStatus;

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
    /// How segments are grouped for the pooled test.
    pub group_by: GroupBy,
    /// Unit mix-ups the user confirms (`--convert-units ID=MIXUP`): each segment's stored
    /// measurements are converted when, and only when, its diagnosis names that mix-up.
    pub convert_units: Vec<(String, UnitMixUp)>,
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
    /// No segment asked for has a fit to diagnose.
    #[error(
        "nothing to diagnose: none of the {segments} segment(s) has a usable fit ({unfitted} \
         never fitted, {failed} whose fit failed); run `pipewave calibrate` on this database first"
    )]
    NothingFitted {
        /// Segments asked for (all of the inventory without `--segment`).
        segments: usize,
        /// Of them, never fitted.
        unfitted: usize,
        /// Of them, whose latest fit failed.
        failed: usize,
    },
    /// The group column is not in the database's inventory.
    #[error("--group-by soil_zone: the inventory in this database has no soil_zone column (import a segments.csv with soil_zone)")]
    NoZones,
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
    /// Groups in which the pooled test detected an effect.
    pub groups_detected: usize,
    /// Confirmed unit conversions: the segment and what was done (or why it was not).
    pub conversions: Vec<(String, String)>,
}

impl DiagnoseSummary {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let named: Vec<String> = self.named.iter().map(|(e, n)| format!("{e} {n}")).collect();
        format!(
            "diagnose: {} segments, {} with misfit far above the noise; named: {}; {} groups with a pooled effect; {} extended fits stored; {} skipped",
            self.diagnosed,
            self.structured,
            if named.is_empty() { "none".to_string() } else { named.join(", ") },
            self.groups_detected,
            self.stored,
            self.skipped.len()
        )
    }
}

/// The soil zone of every segment, when the inventory has a `soil_zone` column.
fn soil_zones(conn: &Connection) -> Result<Option<BTreeMap<String, String>>, DiagnoseError> {
    let has: bool = conn
        .prepare("SELECT 1 FROM pragma_table_info('segments') WHERE name = 'soil_zone'")
        .and_then(|mut st| st.exists([]))
        .map_err(|e| DiagnoseError::Db(DbError::from(e)))?;
    if !has {
        return Ok(None);
    }
    let mut st = conn
        .prepare("SELECT segment_id, soil_zone FROM segments WHERE soil_zone IS NOT NULL")
        .map_err(|e| DiagnoseError::Db(DbError::from(e)))?;
    let rows = st
        .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
        .and_then(|it| it.collect::<Result<BTreeMap<_, _>, _>>())
        .map_err(|e| DiagnoseError::Db(DbError::from(e)))?;
    Ok(Some(rows))
}

/// The inventory as the record check sees it: every segment's material, size and year.
pub fn inventory_profile(conn: &Connection) -> Result<InventoryProfile, DiagnoseError> {
    let db = |e: rusqlite::Error| DiagnoseError::Db(DbError::from(e));
    let mut st = conn
        .prepare(
            "SELECT material, outer_diameter_mm, wall_thickness_mm, install_year FROM segments \
             ORDER BY segment_id",
        )
        .map_err(db)?;
    let rows = st
        .query_map([], |r| {
            Ok((
                r.get::<_, String>(0)?,
                r.get::<_, f64>(1)?,
                r.get::<_, f64>(2)?,
                r.get::<_, Option<i64>>(3)?,
            ))
        })
        .and_then(|it| it.collect::<Result<Vec<_>, _>>())
        .map_err(db)?;
    Ok(InventoryProfile {
        pipes: rows
            .into_iter()
            .filter_map(|(m, od_mm, wall_mm, install_year)| {
                Some(InventoryPipe {
                    material: m.parse().ok()?,
                    od_mm,
                    wall_mm,
                    install_year,
                })
            })
            .collect(),
    })
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
    let profile = std::sync::Arc::new(inventory_profile(conn)?);
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
                    inventory: Some(profile.clone()),
                    install_year: rec.install_year,
                };
                // The stored fit's method, so that its refit below reproduces it ("diagnose"
                // rows were made by the default method).
                let method: Method = f.method.parse().unwrap_or(Method::Default);
                // A current fit that pools the latest campaign with the one before it (model
                // §7.14) is diagnosed on both campaigns pooled.
                let earlier = match f.campaigns.split(',').nth(1) {
                    Some(c) => Some(db::inventory::load_campaign(conn, &rec.segment_id, c)?),
                    None => None,
                };
                todo.push((rec, settings, method, earlier));
            }
        }
    }
    if todo.is_empty() {
        let unfitted = summary
            .skipped
            .iter()
            .filter(|(id, _)| !fits.contains_key(id))
            .count();
        return Err(DiagnoseError::NothingFitted {
            segments: summary.skipped.len(),
            unfitted,
            failed: summary.skipped.len() - unfitted,
        });
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|_| DiagnoseError::Threads(opts.jobs))?;
    let done: Vec<Result<Done, (String, String)>> = pool.install(|| {
        todo.into_par_iter()
            .map(|(record, settings, method, earlier)| {
                // A panic inside one segment's diagnosis skips that segment with its reason
                // instead of ending the run.
                let id = record.segment_id.clone();
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    let invalid = |e| (record.segment_id.clone(), format!("invalid inputs: {e}"));
                    let mut data = segment_data(&record).map_err(invalid)?;
                    if let Some(rows) = earlier {
                        let mut rec_a = record.clone();
                        rec_a.measurements = rows;
                        let data_a = segment_data(&rec_a).map_err(invalid)?;
                        if let Some(p) = crate::invert::problem::pool(&data_a, &data) {
                            data = p.data;
                        }
                    }
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
    // Group detection: the pooled gain test over each group, and the members of a detected
    // group refitted with its effect.
    let zones = if opts.group_by == GroupBy::SoilZone {
        Some(soil_zones(conn)?.ok_or(DiagnoseError::NoZones)?)
    } else {
        None
    };
    let keys: Vec<Option<String>> = diags
        .iter()
        .map(|d| {
            let r = &d.record;
            group_key(
                opts.group_by,
                r.material.code(),
                r.install_year,
                r.soil_type.as_deref(),
                zones
                    .as_ref()
                    .and_then(|z| z.get(&r.segment_id))
                    .map(String::as_str),
            )
        })
        .collect();
    // Each member's gains, with the twin of a refitted compliance effect refitted too.
    let (scores, twin_refits): (Vec<Vec<(Effect, f64)>>, Vec<_>) = pool.install(|| {
        diags
            .par_iter()
            .map(|d| member_gains_and_refits(&d.diagnosis, &d.settings))
            .unzip()
    });
    let mut groups = test_groups(&keys, &scores);
    // Detected twins ranked by a refit of the group with one common magnitude.
    let members = DiagnosedMembers(
        diags.iter().map(|d| (&d.diagnosis, &d.settings)).collect(),
        twin_refits,
    );
    pool.install(|| rank_twins(&mut groups, &scores, &members));
    let rows = pool.install(|| refit_groups(&diags, &mut groups));
    summary.groups_detected = groups.iter().filter(|g| g.effect.is_some()).count();
    if opts.apply {
        store(conn, &diags, opts, &mut summary)?;
    }
    convert(conn, &diags, opts, &mut summary)?;
    report(&diags, &groups, &rows, &opts.out_dir)?;
    Ok(summary)
}

/// The unit conversions the user confirmed: done only where the diagnosis names that very
/// mix-up (so that a repeated command never converts twice); otherwise the reason.
fn convert(
    conn: &mut Connection,
    diags: &[Done],
    opts: &DiagnoseOptions,
    summary: &mut DiagnoseSummary,
) -> Result<(), DiagnoseError> {
    for (id, mix) in &opts.convert_units {
        let d = diags.iter().find(|d| &d.record.segment_id == id);
        let named = d
            .filter(|d| d.diagnosis.named == Some(Effect::MeasurementUnits))
            .and_then(|d| d.diagnosis.units.as_ref().map(|u| u.0));
        let what = match (d, named) {
            (None, _) => "not converted: the segment was not diagnosed".to_string(),
            (Some(_), Some(u)) if u == *mix => {
                let n = convert_measurements(conn, id, *mix)?;
                format!(
                    "converted {n} measurements: {} divided by {} ({}); run calibrate to refit",
                    mix.column(),
                    crate::units::sig(mix.factor(), 4),
                    mix.describe()
                )
            }
            (Some(_), Some(u)) => format!(
                "not converted: the diagnosis names {} ({}), not {}",
                u.code(),
                u.describe(),
                mix.code()
            ),
            (Some(_), None) => format!(
                "not converted: the diagnosis does not name a unit mix-up ({}) for this segment",
                mix.code()
            ),
        };
        summary.conversions.push((id.clone(), what));
    }
    Ok(())
}

/// Refit the members of every detected group with the group's effect (those whose own
/// diagnosis did not already add it), and give each segment its row of the pooled test.
fn refit_groups(diags: &[Done], groups: &mut [GroupTest]) -> Vec<GroupRow> {
    let mut rows = vec![GroupRow::default(); diags.len()];
    for g in groups.iter_mut() {
        let Some(e) = g.effect else { continue };
        let refits: Vec<(usize, Option<f64>)> = g
            .members
            .par_iter()
            .map(|&i| {
                let d = &diags[i];
                if d.diagnosis.named == Some(e) {
                    return (i, Some(d.diagnosis.chi2_per_dof_after()));
                }
                if d.diagnosis.base_failed() || !e.applies_to(d.record.material) {
                    return (i, None);
                }
                let mut effects = d.settings.base_effects.clone();
                effects.push(e);
                effects.sort();
                effects.dedup();
                let fit = extended_fit(&d.diagnosis.data, &d.settings, effects, &d.diagnosis.base);
                (i, fit.chi2_per_dof)
            })
            .collect();
        g.n_refitted = refits.iter().filter(|r| r.1.is_some()).count();
        for (i, chi2) in refits {
            rows[i] = GroupRow {
                key: g.group.clone(),
                effect: Some(e),
                chi2_per_dof_after: chi2,
            };
        }
    }
    rows
}

/// Step 3: a new fit row per named effect, and the segment's effects for the next calibrate.
fn store(
    conn: &mut Connection,
    diags: &[Done],
    opts: &DiagnoseOptions,
    summary: &mut DiagnoseSummary,
) -> Result<(), DiagnoseError> {
    // An inventory error or a unit mix-up is reported, not stored: its fit belongs to another
    // record or to converted measurements, which a person must check and correct.
    let named: Vec<&Done> = diags
        .iter()
        .filter(|d| d.diagnosis.named.is_some_and(|e| !e.is_discrete()))
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
        let value = d
            .diagnosis
            .named
            .and_then(|e| super::effect_value(fit, e))
            .map(|(v, _)| format!(" = {}", crate::units::sig(v, 4)))
            .unwrap_or_default();
        row.message = Some(format!(
            "diagnose: added {}{value}{}: {ev}",
            d.diagnosis.named.map(|e| e.name()).unwrap_or(""),
            if d.diagnosis.assumed_noise {
                " (noise assumed: 1 % Re k, 10 % attenuation)"
            } else {
                ""
            }
        ));
        let curve = curve_points(fit);
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

/// Step 4: `diagnosis.csv`, `groups.csv` and `diagnosis.html` in `dir`.
fn report(
    diags: &[Done],
    groups: &[GroupTest],
    rows: &[GroupRow],
    dir: &Path,
) -> Result<(), DiagnoseError> {
    let err = |m: String| DiagnoseError::Report {
        dir: dir.to_path_buf(),
        message: m,
    };
    std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    let ids: Vec<String> = diags.iter().map(|d| d.record.segment_id.clone()).collect();
    let ds: Vec<Diagnosis> = diags.iter().map(|d| d.diagnosis.clone()).collect();
    write_csv(&dir.join("diagnosis.csv"), &ids, &ds, rows).map_err(|e| err(e.to_string()))?;
    write_groups_csv(&dir.join("groups.csv"), &ids, groups).map_err(|e| err(e.to_string()))?;
    write_html(&dir.join("diagnosis.html"), &ids, &ds, groups, &[])
        .map_err(|e| err(e.to_string()))?;
    Ok(())
}
