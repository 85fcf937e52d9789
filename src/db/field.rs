//! The soil field's tables (model §7.12): `field_runs`, `field_classes`, `field_segments`,
//! `predictions` with `prediction_curves`, and `plan_picks`. Each field update replaces the
//! per-segment rows (only the latest are kept, naming the run that made them).

use rusqlite::{params, Connection, OptionalExtension, Row, TransactionBehavior};

use super::results::CurvePoint;
use super::DbError;

/// What the field needs of one segment: its inventory labels and geometry and its latest
/// fit's soil speeds, information and leak-band speed.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldInput {
    /// The segment.
    pub segment_id: String,
    /// Geometry as stored (WKT) and its EPSG code.
    pub geometry_wkt: Option<String>,
    /// EPSG code.
    pub srid: Option<i64>,
    /// `soil_type`.
    pub soil_type: Option<String>,
    /// Material code.
    pub material: String,
    /// `soil_zone`.
    pub soil_zone: Option<String>,
    /// `length_m`.
    pub length_m: Option<f64>,
    /// `risk_weight`: the segment's weight in `plan` (P83) where given.
    pub risk_weight: Option<f64>,
    /// `soil_class_override`: the class the engineer has checked for the segment.
    pub soil_class_override: Option<String>,
    /// The inventory row's hash (what a fit depends on).
    pub inputs_hash: String,
    /// Latest fit's row id (None: never fitted).
    pub fit_id: Option<i64>,
    /// Latest fit's status.
    pub fit_status: Option<String>,
    /// Latest fit's c_P and c_S, m/s.
    pub speeds: Option<(f64, f64)>,
    /// Latest fit's information (I_PP, I_PS, I_SS).
    pub information: Option<[f64; 3]>,
    /// Latest fit's leak-band speed and its error, m/s.
    pub leak_band_speed: Option<(f64, f64)>,
    /// `soil_density_kg_m3`: maps a zone's soil to the segment's speeds (P63–P64).
    pub soil_density: Option<f64>,
    /// Latest fit's flag and note codes, comma-separated (empty without a fit).
    pub fit_findings: String,
}

/// Every segment's [`FieldInput`], in id order.
pub fn field_inputs(conn: &Connection) -> Result<Vec<FieldInput>, DbError> {
    let mut out = Vec::new();
    for_each_field_input(conn, |i| {
        out.push(i);
        Ok(())
    })?;
    Ok(out)
}

/// Segments in the inventory (to size the lists read from it).
pub fn count_segments(conn: &Connection) -> Result<i64, DbError> {
    Ok(conn.query_row("SELECT COUNT(*) FROM segments", [], |r| r.get(0))?)
}

/// Every segment's [`FieldInput`] in id order, one at a time (flat memory: no row is kept).
pub fn for_each_field_input(
    conn: &Connection,
    mut f: impl FnMut(FieldInput) -> Result<(), DbError>,
) -> Result<(), DbError> {
    let mut stmt = conn.prepare(
        "SELECT s.segment_id, s.geometry_wkt, s.srid, s.soil_type, s.soil_zone, s.length_m, \
         s.inputs_hash, f.id, f.status, f.soil_p_wave_speed_m_per_s, \
         f.soil_s_wave_speed_m_per_s, f.soil_information_pp, f.soil_information_ps, \
         f.soil_information_ss, f.leak_band_speed_m_per_s, f.leak_band_speed_std_m_per_s, s.material, \
         s.risk_weight, s.soil_class_override, s.soil_density_kg_m3, \
         coalesce(f.flags, '') || ',' || coalesce(f.notes, '') \
         FROM segments s LEFT JOIN latest_fits f ON f.segment_id = s.segment_id \
         ORDER BY s.segment_id",
    )?;
    let rows = stmt.query_map([], |r| {
        let pair = |a: Option<f64>, b: Option<f64>| a.zip(b);
        let info = match (
            r.get::<_, Option<f64>>(11)?,
            r.get::<_, Option<f64>>(12)?,
            r.get::<_, Option<f64>>(13)?,
        ) {
            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
            _ => None,
        };
        Ok(FieldInput {
            segment_id: r.get(0)?,
            geometry_wkt: r.get(1)?,
            srid: r.get(2)?,
            soil_type: r.get(3)?,
            soil_zone: r.get(4)?,
            length_m: r.get(5)?,
            inputs_hash: r.get(6)?,
            fit_id: r.get(7)?,
            fit_status: r.get(8)?,
            speeds: pair(r.get(9)?, r.get(10)?),
            information: info,
            leak_band_speed: pair(r.get(14)?, r.get(15)?),
            material: r.get(16)?,
            risk_weight: r.get(17)?,
            soil_class_override: r.get(18)?,
            soil_density: r.get(19)?,
            fit_findings: r.get(20)?,
        })
    })?;
    for row in rows {
        f(row?)?;
    }
    Ok(())
}

/// One row of `field_runs`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FieldRunRow {
    /// Row id (None before insertion).
    pub id: Option<i64>,
    /// The calibrate run that updated the field.
    pub run_id: Option<i64>,
    /// Fingerprint of the inputs.
    pub fingerprint: String,
    /// Segments in the inventory.
    pub n_segments: i64,
    /// Measured segments the field learned from.
    pub n_measured: i64,
    /// Soil classes.
    pub n_classes: i64,
    /// Segments given a prediction.
    pub n_predicted: i64,
    /// Of those, predicted from their class mean alone (no geometry).
    pub n_class_mean_only: i64,
    /// Segments left without a speed.
    pub n_without_speed: i64,
    /// m of the conditioning.
    pub neighbours: i64,
    /// ℓ, m.
    pub correlation_length_m: Option<f64>,
    /// ℓ's search range, m.
    pub correlation_length_lo_m: Option<f64>,
    /// ℓ's search range, m.
    pub correlation_length_hi_m: Option<f64>,
    /// B (PP, PS, SS).
    pub field_cov: [Option<f64>; 3],
    /// T (PP, SS).
    pub scatter_var: [Option<f64>; 2],
    /// ln p(û | θ).
    pub log_likelihood: Option<f64>,
    /// `marginal_likelihood` or `defaults`.
    pub hyper_source: String,
    /// Standard deviation of the leave-one-out z of the measured segments that are not
    /// `field_outlier`s (P82).
    pub loo_z_std: Option<f64>,
    /// Segments flagged `field_outlier`.
    pub n_field_outliers: i64,
    /// Segments whose label the neighbourhood rejects.
    pub n_labels_rejected: i64,
    /// Time taken, s.
    pub elapsed_s: Option<f64>,
    /// Set by the database.
    pub created_at: Option<String>,
}

/// One row of `field_classes`.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldClassRow {
    /// The class (a `soil_zone` or `soil_type`, or the one class of an unlabelled network).
    pub soil_class: String,
    /// Segments in it.
    pub n_segments: i64,
    /// Measured segments in it.
    pub n_measured: i64,
    /// Its mean (ln c_P, ln c_S) and their posterior standard deviations.
    pub mean: [f64; 2],
    /// Standard deviations of the mean.
    pub std: [f64; 2],
    /// Its multipliers of the field covariance B and of the per-pipe scatter T.
    pub scale: [f64; 2],
}

/// One row of `field_segments`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FieldSegmentRow {
    /// The segment.
    pub segment_id: String,
    /// Its label as given.
    pub label: Option<String>,
    /// The class it was given.
    pub soil_class: Option<String>,
    /// Its neighbourhood rejects its label.
    pub label_rejected: bool,
    /// Its class is the inventory's `soil_class_override` (never rejected).
    pub class_overridden: bool,
    /// It has a fit the field learned from.
    pub measured: bool,
    /// Its leave-one-out prediction (measured segments), m/s.
    pub field_leak_band_speed_m_per_s: Option<f64>,
    /// Its error, m/s.
    pub field_leak_band_speed_std_m_per_s: Option<f64>,
    /// z of P82.
    pub loo_z: Option<f64>,
    /// |z| beyond the outlier threshold.
    pub field_outlier: bool,
    /// Why, in words.
    pub note: String,
    /// The factor the field multiplied its fit's information by (measured segments: 1 unless
    /// the field could not explain its fit).
    pub information_scale: Option<f64>,
    /// χ² of its fitted soil against its leave-one-out prediction (measured segments).
    pub screen_chi2: Option<f64>,
}

/// One row of `predictions`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PredictionRow {
    /// The segment.
    pub segment_id: String,
    /// The calibrate run that made it.
    pub run_id: Option<i64>,
    /// c_P and its error, m/s.
    pub soil_p_wave_speed: Option<(f64, f64)>,
    /// c_S and its error, m/s.
    pub soil_s_wave_speed: Option<(f64, f64)>,
    /// E_m, Pa, with its 95 % interval.
    pub soil_youngs_modulus: Option<(f64, f64, f64)>,
    /// ν_m with its 95 % interval.
    pub soil_poisson: Option<(f64, f64, f64)>,
    /// Leak-band speed and its error, m/s.
    pub leak_band_speed: Option<(f64, f64)>,
    /// ∂(leak-band speed)/∂(ln c_P, ln c_S), m/s.
    pub leak_band_speed_gradient: Option<[f64; 2]>,
    /// The class it was predicted in.
    pub soil_class: Option<String>,
    /// Measured segments it was conditioned on.
    pub n_neighbours: i64,
    /// What it rests on.
    pub note: String,
}

/// A prediction with its curve.
pub type Prediction = (PredictionRow, Vec<CurvePoint>);

/// The newest field update, if any.
pub fn latest_field_run(conn: &Connection) -> Result<Option<FieldRunRow>, DbError> {
    Ok(conn
        .query_row(
            "SELECT * FROM field_runs ORDER BY id DESC LIMIT 1",
            [],
            field_run_from_row,
        )
        .optional()?)
}

fn field_run_from_row(r: &Row<'_>) -> rusqlite::Result<FieldRunRow> {
    Ok(FieldRunRow {
        id: r.get("id")?,
        run_id: r.get("run_id")?,
        fingerprint: r.get("fingerprint")?,
        n_segments: r.get("n_segments")?,
        n_measured: r.get("n_measured")?,
        n_classes: r.get("n_classes")?,
        n_predicted: r.get("n_predicted")?,
        n_class_mean_only: r.get("n_class_mean_only")?,
        n_without_speed: r.get("n_without_speed")?,
        neighbours: r.get("neighbours")?,
        correlation_length_m: r.get("correlation_length_m")?,
        correlation_length_lo_m: r.get("correlation_length_lo_m")?,
        correlation_length_hi_m: r.get("correlation_length_hi_m")?,
        field_cov: [
            r.get("field_var_ln_cp")?,
            r.get("field_cov_ln_cp_ln_cs")?,
            r.get("field_var_ln_cs")?,
        ],
        scatter_var: [r.get("scatter_var_ln_cp")?, r.get("scatter_var_ln_cs")?],
        log_likelihood: r.get("log_likelihood")?,
        hyper_source: r.get("hyper_source")?,
        loo_z_std: r.get("loo_z_std")?,
        n_field_outliers: r.get("n_field_outliers")?,
        n_labels_rejected: r.get("n_labels_rejected")?,
        elapsed_s: r.get("elapsed_s")?,
        created_at: r.get("created_at")?,
    })
}

/// Start storing a field update inside the caller's transaction `tx`: insert its run row
/// (counts completed by [`finish_field`]) and clear the previous update's classes and segment
/// rows. Every prediction of the update has its curve at the frequencies `grid`: its points
/// overwrite the stored ones in place, and if any stored point lies off `grid` (a curve of
/// another grid) the previous predictions are cleared first. Returns the field run's id.
pub fn start_field(tx: &Connection, run: &FieldRunRow, grid: &[f64]) -> Result<i64, DbError> {
    tx.execute(
        "INSERT INTO field_runs (run_id, fingerprint, n_segments, n_measured, n_classes, \
         n_predicted, n_class_mean_only, n_without_speed, neighbours, hyper_source) \
         VALUES (?1, ?2, 0, 0, 0, 0, 0, 0, 0, ?3)",
        params![run.run_id, run.fingerprint, run.hyper_source],
    )?;
    let id = tx.last_insert_rowid();
    // Only the latest update's classes, segments and predictions are kept. Predictions are
    // overwritten in place as they come ([`insert_field_rows`]) and the ones this update did
    // not write are deleted by [`finish_field`]: deleting all of them here would write and
    // delete every curve point twice, and emptying the curves in one statement makes SQLite
    // hold a record of every row it deletes (146 MB, not 77 MB, on 100,000 segments).
    tx.execute("DELETE FROM field_classes", [])?;
    tx.execute("DELETE FROM field_segments", [])?;
    let marks: Vec<String> = (1..=grid.len()).map(|i| format!("?{i}")).collect();
    let off_grid: bool = tx.query_row(
        &format!(
            "SELECT EXISTS (SELECT 1 FROM prediction_curves WHERE frequency_hz NOT IN ({}))",
            marks.join(", ")
        ),
        rusqlite::params_from_iter(grid),
        |r| r.get(0),
    )?;
    if off_grid {
        tx.execute("DELETE FROM predictions", [])?;
    }
    Ok(id)
}

/// Complete the run row `field_run_id`, store its classes and delete the predictions it did
/// not write (with their curves).
pub fn finish_field(
    tx: &Connection,
    field_run_id: i64,
    run: &FieldRunRow,
    classes: &[FieldClassRow],
) -> Result<(), DbError> {
    tx.execute(
        "UPDATE field_runs SET n_segments = ?2, n_measured = ?3, n_classes = ?4, \
         n_predicted = ?5, n_class_mean_only = ?6, n_without_speed = ?7, neighbours = ?8, \
         correlation_length_m = ?9, correlation_length_lo_m = ?10, \
         correlation_length_hi_m = ?11, field_var_ln_cp = ?12, field_cov_ln_cp_ln_cs = ?13, \
         field_var_ln_cs = ?14, scatter_var_ln_cp = ?15, scatter_var_ln_cs = ?16, \
         log_likelihood = ?17, hyper_source = ?18, loo_z_std = ?19, n_field_outliers = ?20, \
         n_labels_rejected = ?21, elapsed_s = ?22 WHERE id = ?1",
        params![
            field_run_id,
            run.n_segments,
            run.n_measured,
            run.n_classes,
            run.n_predicted,
            run.n_class_mean_only,
            run.n_without_speed,
            run.neighbours,
            run.correlation_length_m,
            run.correlation_length_lo_m,
            run.correlation_length_hi_m,
            run.field_cov[0],
            run.field_cov[1],
            run.field_cov[2],
            run.scatter_var[0],
            run.scatter_var[1],
            run.log_likelihood,
            run.hyper_source,
            run.loo_z_std,
            run.n_field_outliers,
            run.n_labels_rejected,
            run.elapsed_s,
        ],
    )?;
    tx.execute(
        "DELETE FROM predictions WHERE field_run_id IS NOT ?1",
        params![field_run_id],
    )?;
    let mut ins = tx.prepare_cached(
        "INSERT INTO field_classes (field_run_id, soil_class, n_segments, n_measured, \
         mean_ln_cp, mean_ln_cs, std_ln_cp, std_ln_cs, field_scale, scatter_scale) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)",
    )?;
    for c in classes {
        ins.execute(params![
            field_run_id,
            c.soil_class,
            c.n_segments,
            c.n_measured,
            c.mean[0],
            c.mean[1],
            c.std[0],
            c.std[1],
            c.scale[0],
            c.scale[1],
        ])?;
    }
    Ok(())
}

/// Store a page of segment rows and predictions of the update `field_run_id`.
pub fn insert_field_rows(
    tx: &Connection,
    field_run_id: i64,
    segments: &[FieldSegmentRow],
    predictions: &[Prediction],
) -> Result<(), DbError> {
    {
        let mut ins = tx.prepare_cached(
            "INSERT INTO field_segments (segment_id, field_run_id, label, soil_class, \
             label_rejected, measured, field_leak_band_speed_m_per_s, \
             field_leak_band_speed_std_m_per_s, loo_z, field_outlier, note, information_scale, \
             screen_chi2, class_overridden) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)",
        )?;
        for s in segments {
            ins.execute(params![
                s.segment_id,
                field_run_id,
                s.label,
                s.soil_class,
                s.label_rejected,
                s.measured,
                s.field_leak_band_speed_m_per_s,
                s.field_leak_band_speed_std_m_per_s,
                s.loo_z,
                s.field_outlier,
                s.note,
                s.information_scale,
                s.screen_chi2,
                s.class_overridden,
            ])?;
        }
    }
    {
        let mut ins = tx.prepare_cached(
            "INSERT INTO predictions (segment_id, run_id, soil_p_wave_speed_m_per_s, \
             soil_p_wave_speed_std_m_per_s, soil_s_wave_speed_m_per_s, \
             soil_s_wave_speed_std_m_per_s, soil_youngs_modulus_pa, soil_youngs_modulus_lo_pa, \
             soil_youngs_modulus_hi_pa, soil_poisson, soil_poisson_lo, soil_poisson_hi, \
             leak_band_speed_m_per_s, leak_band_speed_std_m_per_s, soil_class, n_neighbours, \
             note, leak_band_speed_gradient_ln_cp, leak_band_speed_gradient_ln_cs, \
             field_run_id) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, \
             ?17, ?18, ?19, ?20) \
             ON CONFLICT (segment_id) DO UPDATE SET run_id = excluded.run_id, \
             soil_p_wave_speed_m_per_s = excluded.soil_p_wave_speed_m_per_s, \
             soil_p_wave_speed_std_m_per_s = excluded.soil_p_wave_speed_std_m_per_s, \
             soil_s_wave_speed_m_per_s = excluded.soil_s_wave_speed_m_per_s, \
             soil_s_wave_speed_std_m_per_s = excluded.soil_s_wave_speed_std_m_per_s, \
             soil_youngs_modulus_pa = excluded.soil_youngs_modulus_pa, \
             soil_youngs_modulus_lo_pa = excluded.soil_youngs_modulus_lo_pa, \
             soil_youngs_modulus_hi_pa = excluded.soil_youngs_modulus_hi_pa, \
             soil_poisson = excluded.soil_poisson, soil_poisson_lo = excluded.soil_poisson_lo, \
             soil_poisson_hi = excluded.soil_poisson_hi, \
             leak_band_speed_m_per_s = excluded.leak_band_speed_m_per_s, \
             leak_band_speed_std_m_per_s = excluded.leak_band_speed_std_m_per_s, \
             soil_class = excluded.soil_class, n_neighbours = excluded.n_neighbours, \
             note = excluded.note, \
             leak_band_speed_gradient_ln_cp = excluded.leak_band_speed_gradient_ln_cp, \
             leak_band_speed_gradient_ln_cs = excluded.leak_band_speed_gradient_ln_cs, \
             field_run_id = excluded.field_run_id, created_at = excluded.created_at",
        )?;
        let mut curve = tx.prepare_cached(
            "INSERT INTO prediction_curves (segment_id, frequency_hz, phase_speed_m_per_s, \
             phase_speed_std_m_per_s, attenuation_db_per_m, attenuation_std_db_per_m) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6) \
             ON CONFLICT (segment_id, frequency_hz) DO UPDATE SET \
             phase_speed_m_per_s = excluded.phase_speed_m_per_s, \
             phase_speed_std_m_per_s = excluded.phase_speed_std_m_per_s, \
             attenuation_db_per_m = excluded.attenuation_db_per_m, \
             attenuation_std_db_per_m = excluded.attenuation_std_db_per_m",
        )?;
        for (p, pts) in predictions {
            let (cp, cs) = (p.soil_p_wave_speed, p.soil_s_wave_speed);
            let (e, nu) = (p.soil_youngs_modulus, p.soil_poisson);
            ins.execute(params![
                p.segment_id,
                p.run_id,
                cp.map(|v| v.0),
                cp.map(|v| v.1),
                cs.map(|v| v.0),
                cs.map(|v| v.1),
                e.map(|v| v.0),
                e.map(|v| v.1),
                e.map(|v| v.2),
                nu.map(|v| v.0),
                nu.map(|v| v.1),
                nu.map(|v| v.2),
                p.leak_band_speed.map(|v| v.0),
                p.leak_band_speed.map(|v| v.1),
                p.soil_class,
                p.n_neighbours,
                p.note,
                p.leak_band_speed_gradient.map(|g| g[0]),
                p.leak_band_speed_gradient.map(|g| g[1]),
                field_run_id,
            ])?;
            for c in pts {
                curve.execute(params![
                    p.segment_id,
                    c.frequency_hz,
                    c.phase_speed_m_per_s,
                    c.phase_speed_std_m_per_s,
                    c.attenuation_db_per_m,
                    c.attenuation_std_db_per_m,
                ])?;
            }
        }
    }
    Ok(())
}

/// Run `f` in one immediate transaction of `conn`: everything it stores is committed together,
/// or nothing when it fails.
pub fn in_transaction<T>(
    conn: &mut Connection,
    f: impl FnOnce(&Connection) -> Result<T, DbError>,
) -> Result<T, DbError> {
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    let out = f(&tx)?;
    tx.commit()?;
    Ok(out)
}

/// A segment's prediction with its curve (by increasing frequency), if it has one.
pub fn prediction_for(conn: &Connection, segment_id: &str) -> Result<Option<Prediction>, DbError> {
    let row = conn
        .prepare_cached("SELECT * FROM predictions WHERE segment_id = ?1")?
        .query_row([segment_id], |r| {
            let pair = |a: Option<f64>, b: Option<f64>| a.zip(b);
            let triple = |a: Option<f64>, b: Option<f64>, c: Option<f64>| match (a, b, c) {
                (Some(a), Some(b), Some(c)) => Some((a, b, c)),
                _ => None,
            };
            Ok(PredictionRow {
                segment_id: r.get("segment_id")?,
                run_id: r.get("run_id")?,
                soil_p_wave_speed: pair(
                    r.get("soil_p_wave_speed_m_per_s")?,
                    r.get("soil_p_wave_speed_std_m_per_s")?,
                ),
                soil_s_wave_speed: pair(
                    r.get("soil_s_wave_speed_m_per_s")?,
                    r.get("soil_s_wave_speed_std_m_per_s")?,
                ),
                soil_youngs_modulus: triple(
                    r.get("soil_youngs_modulus_pa")?,
                    r.get("soil_youngs_modulus_lo_pa")?,
                    r.get("soil_youngs_modulus_hi_pa")?,
                ),
                soil_poisson: triple(
                    r.get("soil_poisson")?,
                    r.get("soil_poisson_lo")?,
                    r.get("soil_poisson_hi")?,
                ),
                leak_band_speed: pair(
                    r.get("leak_band_speed_m_per_s")?,
                    r.get("leak_band_speed_std_m_per_s")?,
                ),
                leak_band_speed_gradient: pair(
                    r.get("leak_band_speed_gradient_ln_cp")?,
                    r.get("leak_band_speed_gradient_ln_cs")?,
                )
                .map(|(a, b)| [a, b]),
                soil_class: r.get("soil_class")?,
                n_neighbours: r.get::<_, Option<i64>>("n_neighbours")?.unwrap_or(0),
                note: r.get("note")?,
            })
        })
        .optional()?;
    let Some(row) = row else {
        return Ok(None);
    };
    let mut stmt = conn.prepare_cached(
        "SELECT frequency_hz, phase_speed_m_per_s, phase_speed_std_m_per_s, \
         attenuation_db_per_m, attenuation_std_db_per_m FROM prediction_curves \
         WHERE segment_id = ?1 ORDER BY frequency_hz",
    )?;
    let pts = stmt
        .query_map([segment_id], |r| {
            Ok(CurvePoint {
                frequency_hz: r.get(0)?,
                phase_speed_m_per_s: r.get(1)?,
                phase_speed_std_m_per_s: r.get(2)?,
                attenuation_db_per_m: r.get(3)?,
                attenuation_std_db_per_m: r.get(4)?,
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
        })?
        .collect::<Result<_, _>>()?;
    Ok(Some((row, pts)))
}

/// The class multipliers [B, T] of field update `field_run_id`, by class name (classes stored
/// before they existed read as [1, 1]).
pub fn field_class_scales(
    conn: &Connection,
    field_run_id: i64,
) -> Result<std::collections::BTreeMap<String, [f64; 2]>, DbError> {
    let mut stmt = conn.prepare(
        "SELECT soil_class, field_scale, scatter_scale FROM field_classes WHERE field_run_id = ?1",
    )?;
    let rows = stmt.query_map([field_run_id], |r| {
        Ok((
            r.get::<_, String>(0)?,
            [
                r.get::<_, Option<f64>>(1)?.unwrap_or(1.0),
                r.get::<_, Option<f64>>(2)?.unwrap_or(1.0),
            ],
        ))
    })?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// A segment's row of the latest field update, if any.
pub fn field_segment(
    conn: &Connection,
    segment_id: &str,
) -> Result<Option<FieldSegmentRow>, DbError> {
    Ok(conn
        .prepare_cached("SELECT * FROM field_segments WHERE segment_id = ?1")?
        .query_row([segment_id], field_segment_from_row)
        .optional()?)
}

/// Every segment's row of the latest field update, in id order.
pub fn field_segments(conn: &Connection) -> Result<Vec<FieldSegmentRow>, DbError> {
    let mut stmt = conn.prepare("SELECT * FROM field_segments ORDER BY segment_id")?;
    let rows = stmt.query_map([], field_segment_from_row)?;
    Ok(rows.collect::<Result<_, _>>()?)
}

fn field_segment_from_row(r: &Row<'_>) -> rusqlite::Result<FieldSegmentRow> {
    Ok(FieldSegmentRow {
        segment_id: r.get("segment_id")?,
        label: r.get("label")?,
        soil_class: r.get("soil_class")?,
        label_rejected: r.get("label_rejected")?,
        class_overridden: r.get("class_overridden")?,
        measured: r.get("measured")?,
        field_leak_band_speed_m_per_s: r.get("field_leak_band_speed_m_per_s")?,
        field_leak_band_speed_std_m_per_s: r.get("field_leak_band_speed_std_m_per_s")?,
        loo_z: r.get("loo_z")?,
        field_outlier: r.get("field_outlier")?,
        note: r.get("note")?,
        information_scale: r.get("information_scale")?,
        screen_chi2: r.get("screen_chi2")?,
    })
}

/// How many segments of the inventory have a `risk_weight`.
pub fn count_risk_weighted(conn: &Connection) -> Result<i64, DbError> {
    Ok(conn.query_row(
        "SELECT COUNT(*) FROM segments WHERE risk_weight IS NOT NULL",
        [],
        |r| r.get(0),
    )?)
}

/// One pick of a measurement plan (P83).
#[derive(Debug, Clone, PartialEq)]
pub struct PlanPick {
    /// 1 = best.
    pub rank: i64,
    /// The segment to measure.
    pub segment_id: String,
    /// Expected reduction of the network's weighted relative speed variance.
    pub expected_gain: f64,
    /// Its current leak-band speed error, m/s.
    pub leak_band_speed_std_m_per_s: Option<f64>,
    /// Its weight (length or risk weight).
    pub weight: f64,
}

/// Replace the stored plan.
pub fn replace_plan(
    conn: &mut Connection,
    field_run_id: Option<i64>,
    picks: &[PlanPick],
) -> Result<(), DbError> {
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    tx.execute("DELETE FROM plan_picks", [])?;
    {
        let mut ins = tx.prepare(
            "INSERT INTO plan_picks (rank, segment_id, field_run_id, expected_gain, \
             leak_band_speed_std_m_per_s, weight) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
        )?;
        for p in picks {
            ins.execute(params![
                p.rank,
                p.segment_id,
                field_run_id,
                p.expected_gain,
                p.leak_band_speed_std_m_per_s,
                p.weight,
            ])?;
        }
    }
    tx.commit()?;
    Ok(())
}

/// The stored plan, best first.
pub fn plan_picks(conn: &Connection) -> Result<Vec<PlanPick>, DbError> {
    let mut stmt = conn.prepare(
        "SELECT rank, segment_id, expected_gain, leak_band_speed_std_m_per_s, weight \
         FROM plan_picks ORDER BY rank",
    )?;
    let rows = stmt.query_map([], |r| {
        Ok(PlanPick {
            rank: r.get(0)?,
            segment_id: r.get(1)?,
            expected_gain: r.get(2)?,
            leak_band_speed_std_m_per_s: r.get(3)?,
            weight: r.get(4)?,
        })
    })?;
    Ok(rows.collect::<Result<_, _>>()?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::migrate::migrate;
    use std::path::Path;

    fn prediction(id: &str, speed: f64) -> Prediction {
        prediction_at(id, speed, [100.0, 200.0])
    }

    fn prediction_at(id: &str, speed: f64, grid: [f64; 2]) -> Prediction {
        let row = PredictionRow {
            segment_id: id.into(),
            leak_band_speed: Some((speed, 0.02 * speed)),
            note: format!("from {speed}"),
            ..PredictionRow::default()
        };
        let curve = grid
            .map(|f| CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: Some(speed + f / 100.0),
                phase_speed_std_m_per_s: Some(1.0),
                attenuation_db_per_m: Some(0.1),
                attenuation_std_db_per_m: Some(0.01),
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
            .to_vec();
        (row, curve)
    }

    fn update(conn: &mut Connection, preds: &[Prediction]) {
        let grid: Vec<f64> = preds[0].1.iter().map(|c| c.frequency_hz).collect();
        in_transaction(conn, |tx| {
            let run = FieldRunRow::default();
            let id = start_field(tx, &run, &grid)?;
            insert_field_rows(tx, id, &[], preds)?;
            finish_field(tx, id, &run, &[])
        })
        .unwrap();
    }

    /// A field update overwrites each prediction it makes, with its curve, and deletes the
    /// previous update's predictions it did not make (a segment measured since), curves
    /// included, and every point of a curve on another grid: the latest update's predictions
    /// only, as if the table had been emptied first.
    #[test]
    fn an_update_keeps_only_its_own_predictions() {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.pragma_update(None, "foreign_keys", true).unwrap();
        migrate(&mut conn, Path::new(":memory:")).unwrap();
        for id in ["A", "B"] {
            conn.execute(
                "INSERT INTO segments (segment_id, material, outer_diameter_mm, \
                 wall_thickness_mm, soil_density_kg_m3) VALUES (?1, 'PVC', 110, 5.3, 1900)",
                [id],
            )
            .unwrap();
        }
        update(&mut conn, &[prediction("A", 300.0), prediction("B", 310.0)]);
        update(&mut conn, &[prediction("A", 320.0)]);
        let a = prediction_for(&conn, "A").unwrap().expect("A is predicted");
        assert_eq!(a.0.leak_band_speed, Some((320.0, 6.4)));
        assert_eq!(a.0.note, "from 320");
        let speeds: Vec<Option<f64>> = a.1.iter().map(|c| c.phase_speed_m_per_s).collect();
        assert_eq!(speeds, [Some(321.0), Some(322.0)]);
        assert!(prediction_for(&conn, "B").unwrap().is_none());
        let curves: i64 = conn
            .query_row("SELECT COUNT(*) FROM prediction_curves", [], |r| r.get(0))
            .unwrap();
        assert_eq!(curves, 2);
        // Curves on another grid replace the old ones whole.
        update(&mut conn, &[prediction_at("A", 330.0, [100.0, 300.0])]);
        let a = prediction_for(&conn, "A").unwrap().expect("A is predicted");
        let points: Vec<(f64, Option<f64>)> =
            a.1.iter()
                .map(|c| (c.frequency_hz, c.phase_speed_m_per_s))
                .collect();
        assert_eq!(points, [(100.0, Some(331.0)), (300.0, Some(333.0))]);
    }
}
