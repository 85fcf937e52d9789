//! Calibration results: runs, fits and curves, as plain data mirroring the tables of
//! `migrations/`, and the query that decides which segments need a (re)fit.
//!
//! Seeds are `u64` in Rust and SQLite INTEGER (`i64`) in the database: they are stored bit for
//! bit (a seed above `i64::MAX` reads back negative in SQL, and exactly in Rust).

use std::str::FromStr;

use rusqlite::{params, Connection, OptionalExtension, Row, TransactionBehavior};

use super::DbError;
use crate::physics::{ContactMode, Model};

pub use crate::types::FitStatus;

/// State of a calibrate run (`runs.status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RunStatus {
    /// In progress (or killed before it could say otherwise).
    Running,
    /// Every scheduled segment was attempted.
    Finished,
    /// Stopped early (interrupted, or found stale by the next run).
    Interrupted,
}

impl RunStatus {
    /// The text stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            RunStatus::Running => "running",
            RunStatus::Finished => "finished",
            RunStatus::Interrupted => "interrupted",
        }
    }
}

impl FromStr for RunStatus {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "running" => Ok(RunStatus::Running),
            "finished" => Ok(RunStatus::Finished),
            "interrupted" => Ok(RunStatus::Interrupted),
            _ => Err(format!("unknown run status '{s}'")),
        }
    }
}

/// The settings of a run being started.
#[derive(Debug, Clone, PartialEq)]
pub struct NewRun {
    /// Run seed.
    pub seed: u64,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Inversion method (`default`, `paper`).
    pub method: String,
    /// Comma-separated effect names.
    pub effects: String,
    /// Program version (`CARGO_PKG_VERSION`).
    pub program_version: String,
    /// Worker threads.
    pub jobs: Option<i64>,
    /// Segments scheduled.
    pub n_segments: i64,
}

/// The counts of a run, written when it ends.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunCounts {
    /// Fits with status ok.
    pub n_ok: i64,
    /// Fits with status flagged.
    pub n_flagged: i64,
    /// Fits with status failed.
    pub n_failed: i64,
    /// Wall-clock time, s.
    pub elapsed_s: Option<f64>,
}

/// One row of `runs`.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRow {
    /// Run id.
    pub id: i64,
    /// Start, UTC ISO 8601.
    pub started_at: String,
    /// End, UTC ISO 8601.
    pub finished_at: Option<String>,
    /// State.
    pub status: RunStatus,
    /// Settings, as started.
    pub settings: NewRun,
    /// Counts, as finished.
    pub counts: RunCounts,
}

/// One row of `fits`: every column.
#[derive(Debug, Clone, PartialEq)]
pub struct FitRow {
    /// Row id (`None` before insertion).
    pub id: Option<i64>,
    /// Segment.
    pub segment_id: String,
    /// Run.
    pub run_id: i64,
    /// Outcome.
    pub status: FitStatus,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Inversion method.
    pub method: String,
    /// Comma-separated names of the effects switched on (empty: none).
    pub effects: String,
    /// Soil Young's modulus E_m, Pa.
    pub soil_youngs_modulus_pa: Option<f64>,
    /// Soil Poisson's ratio ν_m.
    pub soil_poisson: Option<f64>,
    /// Contact coefficient ξ.
    pub contact: Option<f64>,
    /// One-sigma error of E_m, Pa (None: not identifiable).
    pub soil_youngs_modulus_std_pa: Option<f64>,
    /// One-sigma error of ν_m.
    pub soil_poisson_std: Option<f64>,
    /// One-sigma error of ξ.
    pub contact_std: Option<f64>,
    /// Soil loss factor η_m (effect `soil_damping`).
    pub soil_loss_factor: Option<f64>,
    /// Its one-sigma error.
    pub soil_loss_factor_std: Option<f64>,
    /// Air volume fraction (effect `air_in_water`).
    pub air_fraction: Option<f64>,
    /// Its one-sigma error.
    pub air_fraction_std: Option<f64>,
    /// Effective / nominal wall thickness (effect `wall_thinning`).
    pub wall_thickness_ratio: Option<f64>,
    /// Its one-sigma error.
    pub wall_thickness_ratio_std: Option<f64>,
    /// Pipe loss factor η_p (effect `pipe_loss`).
    pub pipe_loss_factor: Option<f64>,
    /// Its one-sigma error.
    pub pipe_loss_factor_std: Option<f64>,
    /// Exponent n of the viscoelastic wall (effect `viscoelastic_wall`, physics P70).
    pub viscoelastic_exponent: Option<f64>,
    /// Its one-sigma error.
    pub viscoelastic_exponent_std: Option<f64>,
    /// The soil's compressional speed c_P, m/s (physics P63).
    pub soil_p_wave_speed_m_per_s: Option<f64>,
    /// Its one-sigma error (P65).
    pub soil_p_wave_speed_std_m_per_s: Option<f64>,
    /// The soil's shear speed c_S, m/s (P64).
    pub soil_s_wave_speed_m_per_s: Option<f64>,
    /// Its one-sigma error (P65).
    pub soil_s_wave_speed_std_m_per_s: Option<f64>,
    /// 95 % interval of E_m, Pa: lower end.
    pub soil_youngs_modulus_lo_pa: Option<f64>,
    /// 95 % interval of E_m, Pa: upper end.
    pub soil_youngs_modulus_hi_pa: Option<f64>,
    /// 95 % interval of ν_m: lower end.
    pub soil_poisson_lo: Option<f64>,
    /// 95 % interval of ν_m: upper end.
    pub soil_poisson_hi: Option<f64>,
    /// 95 % interval of ξ: lower end.
    pub contact_lo: Option<f64>,
    /// 95 % interval of ξ: upper end.
    pub contact_hi: Option<f64>,
    /// Mean predicted phase speed over the leak band, m/s.
    pub leak_band_speed_m_per_s: Option<f64>,
    /// Its one-sigma error, m/s.
    pub leak_band_speed_std_m_per_s: Option<f64>,
    /// The fit's information about ln c_P, with ξ and the effects profiled out and divided by
    /// the misfit's variance factor (physics P79, P88): what the soil field learns from it.
    pub soil_information_pp: Option<f64>,
    /// Its cross term between ln c_P and ln c_S.
    pub soil_information_ps: Option<f64>,
    /// Its information about ln c_S.
    pub soil_information_ss: Option<f64>,
    /// `model`, or `model+discrepancy` where the misfit is significant and the curve and the
    /// leak-band speed are corrected by a fitted discrepancy (model §7.13).
    pub curve_source: String,
    /// The measurement campaigns the fit was made from, comma-separated, the latest first
    /// (empty: a fit made before campaigns were kept).
    pub campaigns: String,
    /// How far the leak band reaches beyond the measured frequencies, octaves.
    pub leak_band_extrapolation_octaves: Option<f64>,
    /// Objective value at the optimum.
    pub misfit: Option<f64>,
    /// χ² per degree of freedom, when measurement standard deviations are known.
    pub chi2_per_dof: Option<f64>,
    /// Measurements used.
    pub n_measurements: Option<i64>,
    /// Condition number of the fit's Jacobian.
    pub condition_number: Option<f64>,
    /// JSON correlation matrix over the fitted parameters.
    pub correlations: Option<String>,
    /// Comma-separated flag codes.
    pub flags: String,
    /// One line per flag.
    pub flag_reasons: String,
    /// Comma-separated note codes: what the data leave undetermined.
    pub notes: String,
    /// One line per note.
    pub note_reasons: String,
    /// The fitting algorithm's version (`types::FIT_ALGORITHM_VERSION`; None: before it was
    /// recorded).
    pub algorithm_version: Option<i64>,
    /// Forward-model evaluations.
    pub evaluations: Option<i64>,
    /// The segment's seed.
    pub seed: Option<u64>,
    /// `inputs_hash` of the segment as fitted.
    pub inputs_hash: String,
    /// Hash of the run settings that affect this fit.
    pub settings_hash: String,
    /// Time spent, ms.
    pub elapsed_ms: Option<f64>,
    /// Why a fit failed.
    pub message: Option<String>,
    /// Set by the database on insertion.
    pub created_at: Option<String>,
}

impl FitRow {
    /// A row with the identifying columns set and every result empty.
    pub fn new(
        segment_id: impl Into<String>,
        run_id: i64,
        status: FitStatus,
        model: Model,
        contact_mode: ContactMode,
    ) -> FitRow {
        FitRow {
            id: None,
            segment_id: segment_id.into(),
            run_id,
            status,
            model,
            contact_mode,
            method: "default".into(),
            effects: String::new(),
            soil_youngs_modulus_pa: None,
            soil_poisson: None,
            contact: None,
            soil_youngs_modulus_std_pa: None,
            soil_poisson_std: None,
            contact_std: None,
            soil_loss_factor: None,
            soil_loss_factor_std: None,
            air_fraction: None,
            air_fraction_std: None,
            wall_thickness_ratio: None,
            wall_thickness_ratio_std: None,
            pipe_loss_factor: None,
            pipe_loss_factor_std: None,
            viscoelastic_exponent: None,
            viscoelastic_exponent_std: None,
            soil_p_wave_speed_m_per_s: None,
            soil_p_wave_speed_std_m_per_s: None,
            soil_s_wave_speed_m_per_s: None,
            soil_s_wave_speed_std_m_per_s: None,
            soil_youngs_modulus_lo_pa: None,
            soil_youngs_modulus_hi_pa: None,
            soil_poisson_lo: None,
            soil_poisson_hi: None,
            contact_lo: None,
            contact_hi: None,
            leak_band_speed_m_per_s: None,
            leak_band_speed_std_m_per_s: None,
            soil_information_pp: None,
            soil_information_ps: None,
            soil_information_ss: None,
            curve_source: "model".into(),
            campaigns: String::new(),
            leak_band_extrapolation_octaves: None,
            misfit: None,
            chi2_per_dof: None,
            n_measurements: None,
            condition_number: None,
            correlations: None,
            flags: String::new(),
            flag_reasons: String::new(),
            notes: String::new(),
            note_reasons: String::new(),
            algorithm_version: None,
            evaluations: None,
            seed: None,
            inputs_hash: String::new(),
            settings_hash: String::new(),
            elapsed_ms: None,
            message: None,
            created_at: None,
        }
    }
}

/// One point of a fitted curve (`curves`; segment and run are those of the fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Phase speed, m/s (None where the root was not found).
    pub phase_speed_m_per_s: Option<f64>,
    /// Attenuation, dB/m.
    pub attenuation_db_per_m: Option<f64>,
    /// One-sigma error of the phase speed, m/s.
    pub phase_speed_std_m_per_s: Option<f64>,
    /// One-sigma error of the attenuation, dB/m.
    pub attenuation_std_db_per_m: Option<f64>,
    /// The model's phase speed, m/s: `phase_speed_m_per_s` unless the fit's curve is corrected
    /// by a discrepancy (`fits.curve_source`).
    pub model_phase_speed_m_per_s: Option<f64>,
    /// The model's attenuation, dB/m.
    pub model_attenuation_db_per_m: Option<f64>,
}

fn seed_to_sql(seed: u64) -> i64 {
    i64::from_ne_bytes(seed.to_ne_bytes())
}

fn seed_from_sql(seed: i64) -> u64 {
    u64::from_ne_bytes(seed.to_ne_bytes())
}

fn parse_stored<T: FromStr>(what: &str, text: &str) -> Result<T, DbError> {
    text.parse().map_err(|_| DbError::BadStoredValue {
        what: format!("{what} '{text}'"),
    })
}

/// Record the start of a run; returns its id.
pub fn start_run(conn: &Connection, run: &NewRun) -> Result<i64, DbError> {
    conn.execute(
        "INSERT INTO runs (started_at, status, seed, model, contact_mode, method, effects, \
         program_version, jobs, n_segments) \
         VALUES (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), 'running', ?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
        params![
            seed_to_sql(run.seed),
            run.model.as_str(),
            run.contact_mode.as_str(),
            run.method,
            run.effects,
            run.program_version,
            run.jobs,
            run.n_segments,
        ],
    )?;
    Ok(conn.last_insert_rowid())
}

/// Record the end of a run: its counts, status and finish time.
pub fn finish_run(
    conn: &Connection,
    run_id: i64,
    counts: &RunCounts,
    status: RunStatus,
) -> Result<(), DbError> {
    conn.execute(
        "UPDATE runs SET finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), status = ?2, \
         n_ok = ?3, n_flagged = ?4, n_failed = ?5, elapsed_s = ?6 WHERE id = ?1",
        params![
            run_id,
            status.as_str(),
            counts.n_ok,
            counts.n_flagged,
            counts.n_failed,
            counts.elapsed_s,
        ],
    )?;
    Ok(())
}

/// One run, or `None`.
pub fn load_run(conn: &Connection, run_id: i64) -> Result<Option<RunRow>, DbError> {
    let raw = conn
        .query_row(
            "SELECT id, started_at, finished_at, status, seed, model, contact_mode, method, \
             effects, program_version, jobs, n_segments, n_ok, n_flagged, n_failed, elapsed_s \
             FROM runs WHERE id = ?1",
            [run_id],
            |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, String>(1)?,
                    r.get::<_, Option<String>>(2)?,
                    r.get::<_, String>(3)?,
                    r.get::<_, i64>(4)?,
                    r.get::<_, String>(5)?,
                    r.get::<_, String>(6)?,
                    (r.get::<_, String>(7)?, r.get::<_, String>(8)?),
                    (r.get::<_, String>(9)?, r.get::<_, Option<i64>>(10)?),
                    r.get::<_, i64>(11)?,
                    RunCounts {
                        n_ok: r.get(12)?,
                        n_flagged: r.get(13)?,
                        n_failed: r.get(14)?,
                        elapsed_s: r.get(15)?,
                    },
                ))
            },
        )
        .optional()?;
    let Some((
        id,
        started_at,
        finished_at,
        status,
        seed,
        model,
        contact_mode,
        (method, effects),
        (program_version, jobs),
        n_segments,
        counts,
    )) = raw
    else {
        return Ok(None);
    };
    Ok(Some(RunRow {
        id,
        started_at,
        finished_at,
        status: parse_stored("run status", &status)?,
        settings: NewRun {
            seed: seed_from_sql(seed),
            model: parse_stored("model", &model)?,
            contact_mode: parse_stored("contact mode", &contact_mode)?,
            method,
            effects,
            program_version,
            jobs,
            n_segments,
        },
        counts,
    }))
}

/// Store one segment's fit and its curve in one transaction: either both are stored or neither.
/// Returns the fit's row id.
pub fn insert_fit_with_curves(
    conn: &mut Connection,
    fit: &FitRow,
    curve: &[CurvePoint],
) -> Result<i64, DbError> {
    insert_fit_with_change(conn, fit, curve, None)
}

/// [`insert_fit_with_curves`], with the fit's change test and its campaigns' speeds
/// ([`super::changes`]) in the same transaction: a killed run stores all of them or none.
pub fn insert_fit_with_change(
    conn: &mut Connection,
    fit: &FitRow,
    curve: &[CurvePoint],
    change: Option<&super::changes::ChangeRecord>,
) -> Result<i64, DbError> {
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    let values = fit_values(fit);
    let names: Vec<&str> = values.iter().map(|(n, _)| *n).collect();
    let marks: Vec<String> = (1..=values.len()).map(|i| format!("?{i}")).collect();
    tx.prepare_cached(&format!(
        "INSERT INTO fits ({}) VALUES ({})",
        names.join(", "),
        marks.join(", ")
    ))?
    .execute(rusqlite::params_from_iter(values.iter().map(|(_, v)| v)))?;
    let fit_id = tx.last_insert_rowid();
    // A new fit answers any forced refit still pending for the segment.
    tx.prepare_cached("DELETE FROM forced_refits WHERE segment_id = ?1")?
        .execute([&fit.segment_id])?;
    {
        let mut ins = tx.prepare_cached(
            "INSERT INTO curves (segment_id, run_id, frequency_hz, phase_speed_m_per_s, \
             attenuation_db_per_m, phase_speed_std_m_per_s, attenuation_std_db_per_m, \
             model_phase_speed_m_per_s, model_attenuation_db_per_m) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
        )?;
        for p in curve {
            ins.execute(params![
                fit.segment_id,
                fit.run_id,
                p.frequency_hz,
                p.phase_speed_m_per_s,
                p.attenuation_db_per_m,
                p.phase_speed_std_m_per_s,
                p.attenuation_std_db_per_m,
                p.model_phase_speed_m_per_s,
                p.model_attenuation_db_per_m,
            ])?;
        }
    }
    if let Some(rec) = change {
        super::changes::insert(&tx, fit_id, rec)?;
    }
    tx.commit()?;
    Ok(fit_id)
}

/// The stored columns of a fit, by name (everything but `id` and `created_at`, which the
/// database sets). The one list both the insert and the read follow.
fn fit_values(f: &FitRow) -> Vec<(&'static str, rusqlite::types::Value)> {
    use rusqlite::types::Value as V;
    let real = |v: Option<f64>| v.map_or(V::Null, V::Real);
    let int = |v: Option<i64>| v.map_or(V::Null, V::Integer);
    let text = |v: &str| V::Text(v.to_string());
    vec![
        ("segment_id", text(&f.segment_id)),
        ("run_id", V::Integer(f.run_id)),
        ("status", text(f.status.as_str())),
        ("model", text(f.model.as_str())),
        ("contact_mode", text(f.contact_mode.as_str())),
        ("method", text(&f.method)),
        ("effects", text(&f.effects)),
        ("soil_youngs_modulus_pa", real(f.soil_youngs_modulus_pa)),
        ("soil_poisson", real(f.soil_poisson)),
        ("contact", real(f.contact)),
        (
            "soil_youngs_modulus_std_pa",
            real(f.soil_youngs_modulus_std_pa),
        ),
        ("soil_poisson_std", real(f.soil_poisson_std)),
        ("contact_std", real(f.contact_std)),
        ("soil_loss_factor", real(f.soil_loss_factor)),
        ("soil_loss_factor_std", real(f.soil_loss_factor_std)),
        ("air_fraction", real(f.air_fraction)),
        ("air_fraction_std", real(f.air_fraction_std)),
        ("wall_thickness_ratio", real(f.wall_thickness_ratio)),
        ("wall_thickness_ratio_std", real(f.wall_thickness_ratio_std)),
        ("pipe_loss_factor", real(f.pipe_loss_factor)),
        ("pipe_loss_factor_std", real(f.pipe_loss_factor_std)),
        ("viscoelastic_exponent", real(f.viscoelastic_exponent)),
        (
            "viscoelastic_exponent_std",
            real(f.viscoelastic_exponent_std),
        ),
        (
            "soil_p_wave_speed_m_per_s",
            real(f.soil_p_wave_speed_m_per_s),
        ),
        (
            "soil_p_wave_speed_std_m_per_s",
            real(f.soil_p_wave_speed_std_m_per_s),
        ),
        (
            "soil_s_wave_speed_m_per_s",
            real(f.soil_s_wave_speed_m_per_s),
        ),
        (
            "soil_s_wave_speed_std_m_per_s",
            real(f.soil_s_wave_speed_std_m_per_s),
        ),
        (
            "soil_youngs_modulus_lo_pa",
            real(f.soil_youngs_modulus_lo_pa),
        ),
        (
            "soil_youngs_modulus_hi_pa",
            real(f.soil_youngs_modulus_hi_pa),
        ),
        ("soil_poisson_lo", real(f.soil_poisson_lo)),
        ("soil_poisson_hi", real(f.soil_poisson_hi)),
        ("contact_lo", real(f.contact_lo)),
        ("contact_hi", real(f.contact_hi)),
        ("leak_band_speed_m_per_s", real(f.leak_band_speed_m_per_s)),
        (
            "leak_band_speed_std_m_per_s",
            real(f.leak_band_speed_std_m_per_s),
        ),
        ("soil_information_pp", real(f.soil_information_pp)),
        ("soil_information_ps", real(f.soil_information_ps)),
        ("soil_information_ss", real(f.soil_information_ss)),
        ("curve_source", text(&f.curve_source)),
        ("campaigns", text(&f.campaigns)),
        (
            "leak_band_extrapolation_octaves",
            real(f.leak_band_extrapolation_octaves),
        ),
        ("misfit", real(f.misfit)),
        ("chi2_per_dof", real(f.chi2_per_dof)),
        ("n_measurements", int(f.n_measurements)),
        ("condition_number", real(f.condition_number)),
        (
            "correlations",
            f.correlations.as_deref().map_or(V::Null, text),
        ),
        ("flags", text(&f.flags)),
        ("flag_reasons", text(&f.flag_reasons)),
        ("notes", text(&f.notes)),
        ("note_reasons", text(&f.note_reasons)),
        ("algorithm_version", int(f.algorithm_version)),
        ("evaluations", int(f.evaluations)),
        ("seed", int(f.seed.map(seed_to_sql))),
        ("inputs_hash", text(&f.inputs_hash)),
        ("settings_hash", text(&f.settings_hash)),
        ("elapsed_ms", real(f.elapsed_ms)),
        ("message", f.message.as_deref().map_or(V::Null, text)),
    ]
}

/// A fit row read by column name, status, model and contact mode checked.
fn fit_from_row(r: &Row<'_>) -> Result<FitRow, DbError> {
    let get_text = |name: &str| -> Result<String, DbError> { Ok(r.get::<_, String>(name)?) };
    let mut f = FitRow::new(
        get_text("segment_id")?,
        r.get("run_id")?,
        parse_stored("fit status", &get_text("status")?)?,
        parse_stored("model", &get_text("model")?)?,
        parse_stored("contact mode", &get_text("contact_mode")?)?,
    );
    f.id = Some(r.get("id")?);
    f.method = r.get("method")?;
    f.effects = r.get("effects")?;
    f.soil_youngs_modulus_pa = r.get("soil_youngs_modulus_pa")?;
    f.soil_poisson = r.get("soil_poisson")?;
    f.contact = r.get("contact")?;
    f.soil_youngs_modulus_std_pa = r.get("soil_youngs_modulus_std_pa")?;
    f.soil_poisson_std = r.get("soil_poisson_std")?;
    f.contact_std = r.get("contact_std")?;
    f.soil_loss_factor = r.get("soil_loss_factor")?;
    f.soil_loss_factor_std = r.get("soil_loss_factor_std")?;
    f.air_fraction = r.get("air_fraction")?;
    f.air_fraction_std = r.get("air_fraction_std")?;
    f.wall_thickness_ratio = r.get("wall_thickness_ratio")?;
    f.wall_thickness_ratio_std = r.get("wall_thickness_ratio_std")?;
    f.pipe_loss_factor = r.get("pipe_loss_factor")?;
    f.pipe_loss_factor_std = r.get("pipe_loss_factor_std")?;
    f.viscoelastic_exponent = r.get("viscoelastic_exponent")?;
    f.viscoelastic_exponent_std = r.get("viscoelastic_exponent_std")?;
    f.soil_p_wave_speed_m_per_s = r.get("soil_p_wave_speed_m_per_s")?;
    f.soil_p_wave_speed_std_m_per_s = r.get("soil_p_wave_speed_std_m_per_s")?;
    f.soil_s_wave_speed_m_per_s = r.get("soil_s_wave_speed_m_per_s")?;
    f.soil_s_wave_speed_std_m_per_s = r.get("soil_s_wave_speed_std_m_per_s")?;
    f.soil_youngs_modulus_lo_pa = r.get("soil_youngs_modulus_lo_pa")?;
    f.soil_youngs_modulus_hi_pa = r.get("soil_youngs_modulus_hi_pa")?;
    f.soil_poisson_lo = r.get("soil_poisson_lo")?;
    f.soil_poisson_hi = r.get("soil_poisson_hi")?;
    f.contact_lo = r.get("contact_lo")?;
    f.contact_hi = r.get("contact_hi")?;
    f.leak_band_speed_m_per_s = r.get("leak_band_speed_m_per_s")?;
    f.leak_band_speed_std_m_per_s = r.get("leak_band_speed_std_m_per_s")?;
    f.soil_information_pp = r.get("soil_information_pp")?;
    f.soil_information_ps = r.get("soil_information_ps")?;
    f.soil_information_ss = r.get("soil_information_ss")?;
    f.curve_source = r.get("curve_source")?;
    f.campaigns = r.get("campaigns")?;
    f.leak_band_extrapolation_octaves = r.get("leak_band_extrapolation_octaves")?;
    f.misfit = r.get("misfit")?;
    f.chi2_per_dof = r.get("chi2_per_dof")?;
    f.n_measurements = r.get("n_measurements")?;
    f.condition_number = r.get("condition_number")?;
    f.correlations = r.get("correlations")?;
    f.flags = r.get("flags")?;
    f.flag_reasons = r.get("flag_reasons")?;
    f.notes = r.get("notes")?;
    f.note_reasons = r.get("note_reasons")?;
    f.algorithm_version = r.get("algorithm_version")?;
    f.evaluations = r.get("evaluations")?;
    f.seed = r.get::<_, Option<i64>>("seed")?.map(seed_from_sql);
    f.inputs_hash = r.get("inputs_hash")?;
    f.settings_hash = r.get("settings_hash")?;
    f.elapsed_ms = r.get("elapsed_ms")?;
    f.message = r.get("message")?;
    f.created_at = Some(r.get("created_at")?);
    Ok(f)
}

/// The newest fit of each segment (view `latest_fits`), sorted by segment id: of every segment
/// (`ids = None`) or of those listed (segments without a fit are simply absent).
pub fn latest_fits(conn: &Connection, ids: Option<&[String]>) -> Result<Vec<FitRow>, DbError> {
    let mut out = Vec::new();
    match ids {
        None => {
            let mut stmt = conn.prepare("SELECT * FROM latest_fits ORDER BY segment_id")?;
            let mut rows = stmt.query([])?;
            while let Some(r) = rows.next()? {
                out.push(fit_from_row(r)?);
            }
        }
        Some(ids) => {
            let mut ids: Vec<&String> = ids.iter().collect();
            ids.sort();
            ids.dedup();
            let mut stmt = conn.prepare_cached(
                "SELECT * FROM fits WHERE segment_id = ?1 ORDER BY id DESC LIMIT 1",
            )?;
            for id in ids {
                let mut rows = stmt.query([id])?;
                if let Some(r) = rows.next()? {
                    out.push(fit_from_row(r)?);
                }
            }
        }
    }
    Ok(out)
}

/// The newest fit of a segment made with `settings_hash` from the inputs `inputs_hash` that
/// did not fail, if any: the base a fit with effects starts from.
pub fn fit_with_settings(
    conn: &Connection,
    segment_id: &str,
    settings_hash: &str,
    inputs_hash: &str,
) -> Result<Option<FitRow>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT * FROM fits WHERE segment_id = ?1 AND settings_hash = ?2 AND inputs_hash = ?3 \
         AND status != 'failed' ORDER BY id DESC LIMIT 1",
    )?;
    let mut rows = stmt.query(params![segment_id, settings_hash, inputs_hash])?;
    match rows.next()? {
        Some(r) => Ok(Some(fit_from_row(r)?)),
        None => Ok(None),
    }
}

/// The curve of one segment's fit in one run, by increasing frequency.
pub fn curves_for(
    conn: &Connection,
    segment_id: &str,
    run_id: i64,
) -> Result<Vec<CurvePoint>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT frequency_hz, phase_speed_m_per_s, attenuation_db_per_m, \
         phase_speed_std_m_per_s, attenuation_std_db_per_m, model_phase_speed_m_per_s, \
         model_attenuation_db_per_m FROM curves \
         WHERE segment_id = ?1 AND run_id = ?2 ORDER BY frequency_hz",
    )?;
    let rows = stmt.query_map(params![segment_id, run_id], |r| {
        Ok(CurvePoint {
            frequency_hz: r.get("frequency_hz")?,
            phase_speed_m_per_s: r.get("phase_speed_m_per_s")?,
            attenuation_db_per_m: r.get("attenuation_db_per_m")?,
            phase_speed_std_m_per_s: r.get("phase_speed_std_m_per_s")?,
            attenuation_std_db_per_m: r.get("attenuation_std_db_per_m")?,
            model_phase_speed_m_per_s: r.get("model_phase_speed_m_per_s")?,
            model_attenuation_db_per_m: r.get("model_attenuation_db_per_m")?,
        })
    })?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// The segments to fit under one settings hash for all, sorted by id: those with at least one
/// measurement whose latest fit is missing, or was made from other inputs (`inputs_hash`) or
/// other settings (`settings_hash`); with `force`, every segment with measurements. The rule is
/// [`super::FitState::is_stale`], which `calibrate` applies with each segment's own settings
/// hash (the run's effects plus the segment's, table `segment_effects`).
pub fn segments_needing_fit(
    conn: &Connection,
    settings_hash: &str,
    force: bool,
) -> Result<Vec<String>, DbError> {
    Ok(super::effects::fit_states(conn)?
        .into_iter()
        .filter(|st| st.has_measurements && (force || st.is_stale(settings_hash)))
        .map(|st| st.segment_id)
        .collect())
}

/// One page of [`super::FitState`]s in id order, with each segment's own effects (table
/// `segment_effects`, empty when none): the segments whose id sorts after `after` (from the first
/// when `None`), at most `limit` of them. A calibrate run reads the inventory page by page
/// (keyset paging on the primary key), so what it holds does not grow with the network, and a
/// fit stored meanwhile for a segment of an earlier page does not move the later pages.
pub fn fit_states_page(
    conn: &Connection,
    after: Option<&str>,
    limit: usize,
) -> Result<Vec<(super::FitState, String)>, DbError> {
    use super::effects::{FIT_STATE_COLUMNS, FIT_STATE_FROM};
    let select = format!(
        "SELECT {FIT_STATE_COLUMNS}, COALESCE(e.effects, '') FROM {FIT_STATE_FROM} \
         LEFT JOIN segment_effects e ON e.segment_id = s.segment_id"
    );
    let limit = i64::try_from(limit.max(1)).unwrap_or(i64::MAX);
    let row = |r: &Row<'_>| {
        Ok((
            super::FitState::from_row(r)?,
            r.get(super::effects::FIT_STATE_WIDTH)?,
        ))
    };
    let rows = match after {
        None => conn
            .prepare_cached(&format!("{select} ORDER BY s.segment_id LIMIT ?1"))?
            .query_map([limit], row)?
            .collect::<Result<Vec<_>, _>>()?,
        Some(after) => conn
            .prepare_cached(&format!(
                "{select} WHERE s.segment_id > ?1 ORDER BY s.segment_id LIMIT ?2"
            ))?
            .query_map(params![after, limit], row)?
            .collect::<Result<Vec<_>, _>>()?,
    };
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_round_trip_bit_for_bit() {
        for s in [0, 1, u64::from(u32::MAX), i64::MAX as u64, u64::MAX] {
            assert_eq!(seed_from_sql(seed_to_sql(s)), s);
        }
    }

    #[test]
    fn status_texts_round_trip() {
        for s in [FitStatus::Ok, FitStatus::Flagged, FitStatus::Failed] {
            assert_eq!(s.as_str().parse::<FitStatus>().unwrap(), s);
        }
        for s in [
            RunStatus::Running,
            RunStatus::Finished,
            RunStatus::Interrupted,
        ] {
            assert_eq!(s.as_str().parse::<RunStatus>().unwrap(), s);
        }
        assert!("OK".parse::<FitStatus>().is_err());
    }
}
