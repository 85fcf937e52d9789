//! Row conversion between the inventory, the inversion and the result tables: a stored segment
//! into the checked inputs of a fit, a fit result into its `fits` row and its curve, and the hash
//! of the settings a fit is stored under.

use crate::db::hash::Canonical;
use crate::db::{CurvePoint, FitRow, FitStatus, SegmentRecord};
use crate::invert::{self, FitResult, FitSettings, Measurement, Method, Param};
use crate::physics::effects::{effects_text, Effect};
use crate::physics::InputError;
use crate::physics::{ContactMode, Model};
use crate::types::FIT_ALGORITHM_VERSION;

/// Version tag of the settings hash: change it (and only then) when the meaning of the hashed
/// settings changes, so every segment is refitted once.
const SETTINGS_HASH_TAG: &str = "pipewave-settings-v1";

/// FNV-1a 64 of the canonical text of the fit settings, 16 hex digits.
pub fn settings_hash(
    method: Method,
    model: Model,
    contact_mode: ContactMode,
    effects: &[Effect],
) -> String {
    let mut sorted = effects.to_vec();
    sorted.sort();
    sorted.dedup();
    Canonical::new(SETTINGS_HASH_TAG)
        .text("method", Some(method.as_str()))
        .text("model", Some(model.as_str()))
        .text("contact_mode", Some(contact_mode.as_str()))
        .text("effects", Some(&effects_text(&sorted)))
        .hash_hex()
}

/// The checked inputs of a fit from a stored segment.
pub fn segment_data(rec: &SegmentRecord) -> Result<invert::SegmentData, InputError> {
    let measurements = rec
        .measurements
        .iter()
        .map(|m| {
            Measurement::new(
                m.omega_rad_s,
                m.k_re_rad_per_m,
                m.attenuation_np_per_m,
                m.k_re_std,
                m.attenuation_std,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(invert::SegmentData {
        fluid: rec.fluid()?,
        pipe: rec.pipe()?,
        soil_density: rec.soil_density()?,
        material: Some(rec.material),
        measurements,
    })
}

/// The fitted curve with its errors as stored rows; points whose root was not found are NULL.
pub fn curve_points(r: &FitResult) -> Vec<CurvePoint> {
    r.curve
        .iter()
        .map(|p| CurvePoint {
            frequency_hz: p.frequency_hz,
            phase_speed_m_per_s: p.phase_speed,
            attenuation_db_per_m: p.attenuation_db,
            phase_speed_std_m_per_s: p.phase_speed_std.and_then(finite),
            attenuation_std_db_per_m: p.attenuation_db_std.and_then(finite),
            model_phase_speed_m_per_s: p.model_phase_speed,
            model_attenuation_db_per_m: p.model_attenuation_db,
        })
        .collect()
}

/// A finite number, or NULL.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// A number, or NULL for NaN (infinities are stored: an infinite condition number means a
/// singular Jacobian).
fn not_nan(v: f64) -> Option<f64> {
    (!v.is_nan()).then_some(v)
}

/// The campaigns of the measurements a fit is made from, latest first, comma-separated: the
/// segment's current state is its latest campaign ([`crate::db::load_segment`]).
fn campaigns_of(rec: &SegmentRecord) -> String {
    let mut names: Vec<&str> = Vec::new();
    for m in &rec.measurements {
        if let Some(c) = m.campaign.as_deref() {
            if !names.contains(&c) {
                names.push(c);
            }
        }
    }
    names.join(",")
}

/// A failed fit whose inputs could not be built.
pub fn failed_row(rec: &SegmentRecord, run_id: i64, settings: &FitSettings, msg: String) -> FitRow {
    let mut f = FitRow::new(
        rec.segment_id.clone(),
        run_id,
        FitStatus::Failed,
        settings.model,
        settings.contact_mode,
    );
    f.method = settings.method.as_str().to_string();
    f.effects = effects_text(&settings.effects);
    f.n_measurements = i64::try_from(rec.measurements.len()).ok();
    f.campaigns = campaigns_of(rec);
    f.evaluations = Some(0);
    f.algorithm_version = Some(FIT_ALGORITHM_VERSION);
    f.message = Some(msg);
    f
}

/// The `fits` row of a fit result (segment, run and result columns; the caller adds seed,
/// hashes and time).
pub fn fit_row(rec: &SegmentRecord, run_id: i64, r: &FitResult) -> FitRow {
    let mut f = FitRow::new(
        rec.segment_id.clone(),
        run_id,
        r.status,
        r.model,
        r.contact_mode,
    );
    f.method = r.method.as_str().to_string();
    f.effects = effects_text(&r.effects);
    f.campaigns = campaigns_of(rec);
    let value = |p: Param| r.get(p).map(|e| e.value).and_then(not_nan);
    let std = |p: Param| r.get(p).and_then(|e| e.std).and_then(not_nan);
    let lo = |p: Param| r.get(p).map(|e| e.interval.lo).and_then(not_nan);
    let hi = |p: Param| r.get(p).map(|e| e.interval.hi).and_then(not_nan);
    f.soil_youngs_modulus_pa = value(Param::SoilModulus);
    f.soil_poisson = value(Param::SoilPoisson);
    f.contact = value(Param::Contact);
    f.soil_youngs_modulus_std_pa = std(Param::SoilModulus);
    f.soil_poisson_std = std(Param::SoilPoisson);
    f.contact_std = std(Param::Contact);
    f.soil_youngs_modulus_lo_pa = lo(Param::SoilModulus);
    f.soil_youngs_modulus_hi_pa = hi(Param::SoilModulus);
    f.soil_poisson_lo = lo(Param::SoilPoisson);
    f.soil_poisson_hi = hi(Param::SoilPoisson);
    f.contact_lo = lo(Param::Contact);
    f.contact_hi = hi(Param::Contact);
    for &e in &r.effects {
        let p = Param::Effect(e);
        let (v, s) = (value(p), std(p));
        match e {
            Effect::SoilDamping => (f.soil_loss_factor, f.soil_loss_factor_std) = (v, s),
            Effect::AirInWater => (f.air_fraction, f.air_fraction_std) = (v, s),
            Effect::WallThinning => (f.wall_thickness_ratio, f.wall_thickness_ratio_std) = (v, s),
            Effect::PipeLoss => (f.pipe_loss_factor, f.pipe_loss_factor_std) = (v, s),
            Effect::ViscoelasticWall => {
                (f.viscoelastic_exponent, f.viscoelastic_exponent_std) = (v, s)
            }
            // inventory_error has no parameter (the record chosen is in the fit's message).
            Effect::FullModel | Effect::InventoryError | Effect::MeasurementUnits => {}
        }
    }
    if let Some(cp) = r.p_wave_speed {
        f.soil_p_wave_speed_m_per_s = not_nan(cp.value);
        f.soil_p_wave_speed_std_m_per_s = finite(cp.std);
    }
    if let Some(cs) = r.s_wave_speed {
        f.soil_s_wave_speed_m_per_s = not_nan(cs.value);
        f.soil_s_wave_speed_std_m_per_s = finite(cs.std);
    }
    if let Some(b) = r.leak_band_speed {
        f.leak_band_speed_m_per_s = finite(b.value);
        f.leak_band_speed_std_m_per_s = finite(b.std);
    }
    if let Some([pp, ps, ss]) = r.soil_information {
        (
            f.soil_information_pp,
            f.soil_information_ps,
            f.soil_information_ss,
        ) = (finite(pp), finite(ps), finite(ss));
    }
    f.curve_source = r.curve_source.as_str().to_string();
    f.leak_band_extrapolation_octaves = r.leak_band_extrapolation_octaves.and_then(finite);
    f.misfit = not_nan(r.misfit);
    f.chi2_per_dof = r.chi2_per_dof.and_then(not_nan);
    f.n_measurements = i64::try_from(r.n_measurements).ok();
    f.condition_number = r.condition_number.and_then(not_nan);
    f.correlations =
        (!r.correlations.is_empty()).then(|| correlations_json(&r.correlations, r.estimates.len()));
    f.flags = r.flag_codes();
    f.flag_reasons = lines(&r.flags);
    f.notes = r.note_codes();
    f.note_reasons = lines(&r.notes);
    f.algorithm_version = Some(FIT_ALGORITHM_VERSION);
    f.evaluations = i64::try_from(r.evaluations).ok();
    f.message = r.message.clone();
    f
}

fn lines(v: &[invert::Flag]) -> String {
    v.iter()
        .map(|fl| fl.to_string())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The correlation matrix as JSON (serde_json): an array of `n` rows of `n` numbers, in the
/// order of the fitted parameters (E_m, ν_m, ξ, then the effects' parameters in the order of
/// `fits.effects`); a flat array when the length is not `n²`. Non-finite entries are `null`.
pub fn correlations_json(values: &[f64], n: usize) -> String {
    let num = |v: f64| v.is_finite().then_some(v);
    let json = if n > 0 && values.len() == n * n {
        serde_json::to_string(
            &values
                .chunks(n)
                .map(|r| r.iter().map(|&v| num(v)).collect::<Vec<_>>())
                .collect::<Vec<_>>(),
        )
    } else {
        serde_json::to_string(&values.iter().map(|&v| num(v)).collect::<Vec<_>>())
    };
    json.unwrap_or_else(|_| "null".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn correlations_are_a_json_matrix() {
        assert_eq!(
            correlations_json(&[1.0, -0.25, -0.25, 1.0], 2),
            "[[1.0,-0.25],[-0.25,1.0]]"
        );
        assert_eq!(correlations_json(&[1.0, f64::NAN], 3), "[1.0,null]");
        let v: Vec<Vec<f64>> = serde_json::from_str(&correlations_json(&[1e-20], 1)).unwrap();
        assert_eq!(v, vec![vec![1e-20]]);
    }
}
