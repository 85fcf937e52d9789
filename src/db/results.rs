//! Calibration results: runs, fits and curves, as plain data mirroring the tables of
//! `migrations/`, and the query that decides which segments need a (re)fit.
//!
//! Seeds are `u64` in Rust and SQLite INTEGER (`i64`) in the database: they are stored bit for
//! bit (a seed above `i64::MAX` reads back negative in SQL, and exactly in Rust).

use std::fmt;
use std::str::FromStr;

use rusqlite::{params, Connection, OptionalExtension, Row, TransactionBehavior};

use super::DbError;
use crate::physics::{ContactMode, Model};

/// Outcome of one segment's fit (`fits.status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FitStatus {
    /// A good fit.
    Ok,
    /// A fit was produced but is poor or suspicious (see `flags`).
    Flagged,
    /// No fit could be produced (see `message`).
    Failed,
}

impl FitStatus {
    /// The text stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            FitStatus::Ok => "ok",
            FitStatus::Flagged => "flagged",
            FitStatus::Failed => "failed",
        }
    }
}

impl fmt::Display for FitStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for FitStatus {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ok" => Ok(FitStatus::Ok),
            "flagged" => Ok(FitStatus::Flagged),
            "failed" => Ok(FitStatus::Failed),
            _ => Err(format!("unknown fit status '{s}'")),
        }
    }
}

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
            misfit: None,
            chi2_per_dof: None,
            n_measurements: None,
            condition_number: None,
            correlations: None,
            flags: String::new(),
            flag_reasons: String::new(),
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
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    tx.prepare_cached(
        "INSERT INTO fits (segment_id, run_id, status, model, contact_mode, method, effects, \
         soil_youngs_modulus_pa, soil_poisson, contact, soil_youngs_modulus_std_pa, \
         soil_poisson_std, contact_std, soil_loss_factor, soil_loss_factor_std, air_fraction, \
         air_fraction_std, wall_thickness_ratio, wall_thickness_ratio_std, pipe_loss_factor, \
         pipe_loss_factor_std, misfit, chi2_per_dof, n_measurements, condition_number, \
         correlations, flags, flag_reasons, evaluations, seed, inputs_hash, settings_hash, \
         elapsed_ms, message) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, \
         ?18, ?19, ?20, ?21, ?22, ?23, ?24, ?25, ?26, ?27, ?28, ?29, ?30, ?31, ?32, ?33, ?34)",
    )?
    .execute(params![
        fit.segment_id,
        fit.run_id,
        fit.status.as_str(),
        fit.model.as_str(),
        fit.contact_mode.as_str(),
        fit.method,
        fit.effects,
        fit.soil_youngs_modulus_pa,
        fit.soil_poisson,
        fit.contact,
        fit.soil_youngs_modulus_std_pa,
        fit.soil_poisson_std,
        fit.contact_std,
        fit.soil_loss_factor,
        fit.soil_loss_factor_std,
        fit.air_fraction,
        fit.air_fraction_std,
        fit.wall_thickness_ratio,
        fit.wall_thickness_ratio_std,
        fit.pipe_loss_factor,
        fit.pipe_loss_factor_std,
        fit.misfit,
        fit.chi2_per_dof,
        fit.n_measurements,
        fit.condition_number,
        fit.correlations,
        fit.flags,
        fit.flag_reasons,
        fit.evaluations,
        fit.seed.map(seed_to_sql),
        fit.inputs_hash,
        fit.settings_hash,
        fit.elapsed_ms,
        fit.message,
    ])?;
    let fit_id = tx.last_insert_rowid();
    {
        let mut ins = tx.prepare_cached(
            "INSERT INTO curves (segment_id, run_id, frequency_hz, phase_speed_m_per_s, \
             attenuation_db_per_m) VALUES (?1, ?2, ?3, ?4, ?5)",
        )?;
        for p in curve {
            ins.execute(params![
                fit.segment_id,
                fit.run_id,
                p.frequency_hz,
                p.phase_speed_m_per_s,
                p.attenuation_db_per_m,
            ])?;
        }
    }
    tx.commit()?;
    Ok(fit_id)
}

const FIT_COLUMNS: &str = "id, segment_id, run_id, status, model, contact_mode, method, effects, \
    soil_youngs_modulus_pa, soil_poisson, contact, soil_youngs_modulus_std_pa, soil_poisson_std, \
    contact_std, soil_loss_factor, soil_loss_factor_std, air_fraction, air_fraction_std, \
    wall_thickness_ratio, wall_thickness_ratio_std, pipe_loss_factor, pipe_loss_factor_std, \
    misfit, chi2_per_dof, n_measurements, condition_number, correlations, flags, flag_reasons, \
    evaluations, seed, inputs_hash, settings_hash, elapsed_ms, message, created_at";

/// A fit row with status, model and contact mode still as text (checked by [`finish_fit`]).
type RawFit = (FitRow, String, String, String);

fn fit_from_row(r: &Row<'_>) -> rusqlite::Result<RawFit> {
    let mut f = FitRow::new(
        r.get::<_, String>(1)?,
        r.get(2)?,
        FitStatus::Failed,
        Model::default(),
        ContactMode::default(),
    );
    f.id = Some(r.get(0)?);
    f.method = r.get(6)?;
    f.effects = r.get(7)?;
    f.soil_youngs_modulus_pa = r.get(8)?;
    f.soil_poisson = r.get(9)?;
    f.contact = r.get(10)?;
    f.soil_youngs_modulus_std_pa = r.get(11)?;
    f.soil_poisson_std = r.get(12)?;
    f.contact_std = r.get(13)?;
    f.soil_loss_factor = r.get(14)?;
    f.soil_loss_factor_std = r.get(15)?;
    f.air_fraction = r.get(16)?;
    f.air_fraction_std = r.get(17)?;
    f.wall_thickness_ratio = r.get(18)?;
    f.wall_thickness_ratio_std = r.get(19)?;
    f.pipe_loss_factor = r.get(20)?;
    f.pipe_loss_factor_std = r.get(21)?;
    f.misfit = r.get(22)?;
    f.chi2_per_dof = r.get(23)?;
    f.n_measurements = r.get(24)?;
    f.condition_number = r.get(25)?;
    f.correlations = r.get(26)?;
    f.flags = r.get(27)?;
    f.flag_reasons = r.get(28)?;
    f.evaluations = r.get(29)?;
    f.seed = r.get::<_, Option<i64>>(30)?.map(seed_from_sql);
    f.inputs_hash = r.get(31)?;
    f.settings_hash = r.get(32)?;
    f.elapsed_ms = r.get(33)?;
    f.message = r.get(34)?;
    f.created_at = Some(r.get(35)?);
    Ok((f, r.get(3)?, r.get(4)?, r.get(5)?))
}

fn finish_fit((mut f, status, model, contact_mode): RawFit) -> Result<FitRow, DbError> {
    f.status = parse_stored("fit status", &status)?;
    f.model = parse_stored("model", &model)?;
    f.contact_mode = parse_stored("contact mode", &contact_mode)?;
    Ok(f)
}

/// The newest fit of each segment (view `latest_fits`), sorted by segment id: of every segment
/// (`ids = None`) or of those listed (segments without a fit are simply absent).
pub fn latest_fits(conn: &Connection, ids: Option<&[String]>) -> Result<Vec<FitRow>, DbError> {
    let mut out = Vec::new();
    match ids {
        None => {
            let mut stmt = conn.prepare(&format!(
                "SELECT {FIT_COLUMNS} FROM latest_fits ORDER BY segment_id"
            ))?;
            for raw in stmt.query_map([], fit_from_row)? {
                out.push(finish_fit(raw?)?);
            }
        }
        Some(ids) => {
            let mut ids: Vec<&String> = ids.iter().collect();
            ids.sort();
            ids.dedup();
            let mut stmt = conn.prepare_cached(&format!(
                "SELECT {FIT_COLUMNS} FROM fits WHERE segment_id = ?1 ORDER BY id DESC LIMIT 1"
            ))?;
            for id in ids {
                if let Some(raw) = stmt.query_row([id], fit_from_row).optional()? {
                    out.push(finish_fit(raw)?);
                }
            }
        }
    }
    Ok(out)
}

/// The curve of one segment's fit in one run, by increasing frequency.
pub fn curves_for(
    conn: &Connection,
    segment_id: &str,
    run_id: i64,
) -> Result<Vec<CurvePoint>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT frequency_hz, phase_speed_m_per_s, attenuation_db_per_m FROM curves \
         WHERE segment_id = ?1 AND run_id = ?2 ORDER BY frequency_hz",
    )?;
    let rows = stmt.query_map(params![segment_id, run_id], |r| {
        Ok(CurvePoint {
            frequency_hz: r.get(0)?,
            phase_speed_m_per_s: r.get(1)?,
            attenuation_db_per_m: r.get(2)?,
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
