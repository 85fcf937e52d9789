//! The discrepancy workflow: find where model and measurements disagree, name the
//! missing physical effect, refit with it, and show the misfit shrink.
//!
//! 1. **Find.** Residuals of the current fit normalised by the measurement standard deviations,
//!    per frequency, for Re k and the attenuation separately, with tests for structure: misfit
//!    far above the noise, a trend with frequency, runs of one sign, one part fine and the other
//!    off ([`structure`]).
//! 2. **Name.** Every effect of the library ([`Effect`], model §8) is a nested extension of the
//!    model with one parameter at a neutral value. At the current fit a score (Lagrange
//!    multiplier) test says how much χ² each could remove, cheaply and without refitting; the
//!    one-sided effects (air, thinning, losses only move one way) score zero when the data pull
//!    the wrong way. The best candidates are refitted; an effect is accepted only when a
//!    likelihood-ratio test that accounts for the parameter on its bound (χ̄² = ½χ²₀ + ½χ²₁,
//!    Self & Liang 1987) rejects the base model at level α after a Bonferroni correction for
//!    the candidates tried, **and** leave-one-frequency-out prediction improves. "None" is a
//!    valid answer.
//! 3. **Add** and 4. **Show** are done by the `diagnose` command: a new fit row with the effect
//!    and its value, and a report.

pub mod ambiguity;
pub mod catalogue;
pub mod group;
pub mod inventory;
pub mod report;
pub mod run;
pub mod stats;
pub mod units;

use num_complex::Complex64;

use crate::invert::problem::{predict, Measurement, Param, Problem, SegmentData};
use crate::invert::{fit_segment, FitResult, FitSettings};
use crate::optimize::{FiniteDifference, LevenbergMarquardt};
use crate::physics::effects::Effect;
use crate::physics::{ContactMode, Model};
use crate::types::FitStatus;

/// Assumed relative noise on Re k when a segment has no stated standard deviations (typical
/// of two-sensor field estimates; it only matters for such segments and is reported).
pub const ASSUMED_K_RE_RSTD: f64 = 0.01;
/// Assumed relative noise on the attenuation when none is stated.
pub const ASSUMED_ATTENUATION_RSTD: f64 = 0.1;
/// Level of the tests (before the Bonferroni correction over candidates).
pub const ALPHA: f64 = 1e-3;
/// A base fit is "structured" (worth naming an effect) when its χ² has upper-tail probability
/// below this.
pub const STRUCTURE_P: f64 = 1e-3;
/// The refit with a named effect must leave a χ² whose upper-tail probability is at least this
/// (looser than [`STRUCTURE_P`]: a good explanation, not necessarily a perfect one).
pub const EXPLAINED_P: f64 = 1e-4;
/// Accepted effects whose χ² after differs by less than this explain the data equally well
/// (two units of χ²: the AIC's price of a parameter).
pub const TIE_LR: f64 = 2.0;
/// Tie-break between equally good effects, most plausible first: the loss factor of a wall
/// is the least certain input (plastics 0.04–0.1, iron a single published value, model §3.3);
/// wall thinning is common in old iron; free air needs a reason (a high point, a recent
/// repair); soil damping shows only in stiff soil (model §8 E1); the full model is the default.
/// A viscoelastic wall is a wall loss with a rising modulus: it comes after the plain loss
/// factor. The inventory record is listed last, but a tie between a record and a physical
/// effect is broken by AICc instead (see [`name_effect`]). A unit mix-up, the other discrete
/// alternative to the stored inputs, comes last.
pub const PRIOR_ORDER: [Effect; 8] = [
    Effect::PipeLoss,
    Effect::ViscoelasticWall,
    Effect::WallThinning,
    Effect::AirInWater,
    Effect::SoilDamping,
    Effect::FullModel,
    Effect::InventoryError,
    Effect::MeasurementUnits,
];
/// The leave-one-frequency-out prediction error must fall by at least this fraction.
pub const MIN_HOLDOUT_GAIN: f64 = 0.2;

/// Settings of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseSettings {
    /// Model variant of the base fit.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects already in the base model.
    pub base_effects: Vec<Effect>,
    /// Candidate effects.
    pub candidates: Vec<Effect>,
    /// Seed of the refits.
    pub seed: u64,
    /// The utility's inventory: its sizes join the candidate records, and its materials, sizes
    /// and eras rank a set of records the data cannot tell apart (None: catalogue only,
    /// ranked by χ² alone).
    pub inventory: Option<std::sync::Arc<inventory::InventoryProfile>>,
    /// The segment's installation year, for that ranking.
    pub install_year: Option<i64>,
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        Self {
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            base_effects: Vec::new(),
            candidates: Effect::ALL.to_vec(),
            seed: 1,
            inventory: None,
            install_year: None,
        }
    }
}

/// One record of a set the data cannot tell apart.
#[derive(Debug, Clone)]
pub struct RecordSetMember {
    /// The record.
    pub candidate: inventory::RecordCandidate,
    /// χ² of its fit.
    pub chi2: f64,
    /// How likely the inventory makes it ([`inventory::InventoryProfile::prior`]; 1 without
    /// an inventory).
    pub prior: f64,
    /// Its fit.
    pub fit: FitResult,
}

impl RecordSetMember {
    /// The ranking key: χ² − 2 ln(prior), the record's misfit plus what the inventory says
    /// against it (a posterior ranking; lower is more likely).
    pub fn rank_key(&self) -> f64 {
        self.chi2 - 2.0 * self.prior.max(1e-300).ln()
    }
}

/// Normalised residuals (model − measured)/σ of a fit, per measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Residuals {
    /// Frequency, Hz.
    pub frequency_hz: Vec<f64>,
    /// Re k residuals in standard deviations.
    pub re: Vec<f64>,
    /// Attenuation residuals in standard deviations.
    pub att: Vec<f64>,
}

impl Residuals {
    /// Residuals of the predicted wavenumbers `k` against `data` (which has stds).
    pub fn of(data: &SegmentData, k: &[Complex64]) -> Self {
        let mut r = Residuals {
            frequency_hz: Vec::new(),
            re: Vec::new(),
            att: Vec::new(),
        };
        for (m, k) in data.measurements.iter().zip(k) {
            r.frequency_hz.push(m.omega / std::f64::consts::TAU);
            r.re.push((k.re - m.k_re) / m.k_re_std.unwrap_or(f64::NAN));
            r.att
                .push((-k.im - m.attenuation) / m.attenuation_std.unwrap_or(f64::NAN));
        }
        r
    }

    /// χ² = Σ r².
    pub fn chi2(&self) -> f64 {
        self.re.iter().chain(&self.att).map(|v| v * v).sum()
    }
}

/// Structure found in a fit's residuals.
#[derive(Debug, Clone, PartialEq)]
pub struct Structure {
    /// χ² of the Re k residuals.
    pub chi2_re: f64,
    /// χ² of the attenuation residuals.
    pub chi2_att: f64,
    /// Degrees of freedom of the fit (2M − n).
    pub dof: usize,
    /// Upper-tail probability of the total χ².
    pub p_value: f64,
    /// t statistic of a linear trend of the Re k residuals with frequency.
    pub trend_re: f64,
    /// t statistic of a linear trend of the attenuation residuals with frequency.
    pub trend_att: f64,
    /// Runs of one sign in the Re k residuals, and in the attenuation residuals.
    pub runs: (usize, usize),
    /// The misfit is far above the noise.
    pub structured: bool,
    /// A plain-words summary ("attenuation high at high frequency", …).
    pub pattern: String,
}

/// t statistic of the slope of `y` on `x` (ordinary least squares); 0 with fewer than 3 points.
pub fn trend_t(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len();
    if n < 3 {
        return 0.0;
    }
    let nf = n as f64;
    let (mx, my) = (x.iter().sum::<f64>() / nf, y.iter().sum::<f64>() / nf);
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    if sxx <= 0.0 {
        return 0.0;
    }
    let slope = sxy / sxx;
    let resid: f64 = x
        .iter()
        .zip(y)
        .map(|(a, b)| (b - my - slope * (a - mx)).powi(2))
        .sum();
    let se = (resid / (nf - 2.0) / sxx).sqrt();
    if se > 0.0 {
        slope / se
    } else if slope == 0.0 {
        0.0
    } else {
        slope.signum() * f64::INFINITY
    }
}

/// Number of runs of one sign.
pub fn runs(v: &[f64]) -> usize {
    if v.is_empty() {
        return 0;
    }
    1 + v
        .windows(2)
        .filter(|w| (w[0] >= 0.0) != (w[1] >= 0.0))
        .count()
}

/// Tests for structure in the residuals of a fit with `n_params` parameters.
pub fn structure(r: &Residuals, n_params: usize) -> Structure {
    let chi2_re: f64 = r.re.iter().map(|v| v * v).sum();
    let chi2_att: f64 = r.att.iter().map(|v| v * v).sum();
    let dof = (2 * r.re.len()).saturating_sub(n_params);
    let p_value = if dof > 0 {
        stats::chi2_sf(chi2_re + chi2_att, dof as f64)
    } else {
        1.0
    };
    let trend_re = trend_t(&r.frequency_hz, &r.re);
    let trend_att = trend_t(&r.frequency_hz, &r.att);
    let m = r.re.len().max(1) as f64;
    let (mean_re, mean_att) = (r.re.iter().sum::<f64>() / m, r.att.iter().sum::<f64>() / m);
    let structured = p_value < STRUCTURE_P;
    let mut words = Vec::new();
    let part = |chi2: f64, mean: f64, trend: f64, name: &str| -> Option<String> {
        if chi2 / m <= 2.0 {
            return None;
        }
        let level = if mean > 1.0 {
            "model above the data"
        } else if mean < -1.0 {
            "model below the data"
        } else {
            "scattered"
        };
        let tr = if trend > 2.0 {
            ", rising with frequency"
        } else if trend < -2.0 {
            ", falling with frequency"
        } else {
            ""
        };
        Some(format!("{name}: {level}{tr}"))
    };
    if let Some(s) = part(chi2_re, mean_re, trend_re, "Re k") {
        words.push(s);
    }
    if let Some(s) = part(chi2_att, mean_att, trend_att, "attenuation") {
        words.push(s);
    }
    let pattern = if words.is_empty() {
        "residuals within the noise".to_string()
    } else {
        words.join("; ")
    };
    Structure {
        chi2_re,
        chi2_att,
        dof,
        p_value,
        trend_re,
        trend_att,
        runs: (runs(&r.re), runs(&r.att)),
        structured,
        pattern,
    }
}

/// A candidate effect for one segment.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The effect.
    pub effect: Effect,
    /// Score statistic at the current fit (χ² it could remove to first order; 0 when the data
    /// pull the parameter out of its allowed range). `NaN` for `full_model`, which has no
    /// parameter and is judged by its refit alone.
    pub score: f64,
    /// The refit with this effect, when it was tried.
    pub refit: Option<Refit>,
}

/// A nested refit and its evidence.
#[derive(Debug, Clone)]
pub struct Refit {
    /// The extended fit.
    pub fit: FitResult,
    /// χ²(base) − χ²(extended).
    pub lr: f64,
    /// p-value of the likelihood-ratio test (χ̄² mixture for a parameter on its bound; χ²₁
    /// for the parameter-free `full_model`, conservatively).
    pub p_value: f64,
    /// AICc(extended) − AICc(base).
    pub d_aicc: f64,
    /// Leave-one-frequency-out prediction χ² of the base model.
    pub holdout_base: f64,
    /// Leave-one-frequency-out prediction χ² of the extended model.
    pub holdout_ext: f64,
    /// The extended fit itself explains the data: its χ² has upper-tail probability at least
    /// [`EXPLAINED_P`].
    pub explains: bool,
    /// Accepted as the missing effect.
    pub accepted: bool,
    /// How many discrete alternatives this one is the best of (records or unit mix-ups tried;
    /// 1 for a physical effect, whose parameter is priced by AICc).
    pub choices: usize,
}

/// The diagnosis of one segment.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The base fit (chi-square, with stds assumed where none were stated).
    pub base: FitResult,
    /// The data as diagnosed (stds filled in where none were stated).
    pub data: SegmentData,
    /// True when the stds were assumed.
    pub assumed_noise: bool,
    /// Residuals of the base fit.
    pub before: Residuals,
    /// Their structure.
    pub structure: Structure,
    /// Candidates, best score first.
    pub candidates: Vec<Candidate>,
    /// The named effect, if any.
    pub named: Option<Effect>,
    /// Other accepted effects that explain the data as well (within [`TIE_LR`]).
    pub ambiguous_with: Vec<Effect>,
    /// For each of them: the quantity both change and the measurement that separates them.
    pub ambiguity: Vec<ambiguity::Ambiguity>,
    /// The best candidate inventory record, when the inventory was checked, and the segment
    /// with that record.
    pub record: Option<(inventory::RecordCandidate, SegmentData)>,
    /// Other records the data do not reject against it ([`inventory::RecordFit::alternatives`]).
    pub record_alternatives: Vec<inventory::RecordCandidate>,
    /// The best record and those alternatives, most likely first ([`RecordSetMember::rank_key`]).
    pub record_set: Vec<RecordSetMember>,
    /// What would separate the records of the set: a frequency band where their fitted
    /// models differ, or a trial hole.
    pub record_separation: String,
    /// The best unit mix-up tried, and the data with it undone.
    pub units: Option<(units::UnitMixUp, SegmentData)>,
    /// Residuals after adding it.
    pub after: Option<Residuals>,
    /// Leave-one-frequency-out prediction χ² of the base model (computed once, when needed).
    pub holdout_base: Option<f64>,
}

impl Diagnosis {
    /// True when the base model could not be fitted.
    pub fn base_failed(&self) -> bool {
        self.base.status == FitStatus::Failed
    }

    /// The segment data an effect's refit was made on: the candidate record's for
    /// `inventory_error`, the segment's otherwise.
    pub fn fit_data(&self, e: Effect) -> &SegmentData {
        match (&self.record, &self.units, e) {
            (Some((_, d)), _, Effect::InventoryError) => d,
            (_, Some((_, d)), Effect::MeasurementUnits) => d,
            _ => &self.data,
        }
    }

    /// The records of the set, in the interface's syntax, joined by ` | `, most likely first.
    pub fn record_set_text(&self) -> String {
        self.record_set
            .iter()
            .map(|m| m.candidate.label())
            .collect::<Vec<_>>()
            .join(" | ")
    }

    /// The base model's leave-one-frequency-out prediction χ² (∞ without a base fit).
    pub fn holdout_base(&mut self, settings: &DiagnoseSettings) -> f64 {
        if let Some(v) = self.holdout_base {
            return v;
        }
        let v = if self.base_failed() {
            f64::INFINITY
        } else {
            holdout(&self.data, &self.base, settings, &settings.base_effects)
        };
        self.holdout_base = Some(v);
        v
    }

    /// The refit of an effect, if it was tried.
    pub fn refit_of(&self, e: Effect) -> Option<&Refit> {
        self.candidates
            .iter()
            .find(|c| c.effect == e)
            .and_then(|c| c.refit.as_ref())
    }

    /// A gross misfit that no physical effect explains: the base could not be fitted, or its
    /// misfit is far above the noise and no refit with a physical effect leaves a χ² consistent
    /// with it ([`Refit::explains`]). Such a segment (a wrong record, a unit or transcription
    /// error in its data) says nothing about an effect its group shares.
    pub fn unexplained(&self) -> bool {
        if self.base_failed() {
            return true;
        }
        self.structure.structured
            && !self
                .candidates
                .iter()
                .filter(|c| !c.effect.is_discrete())
                .filter_map(|c| c.refit.as_ref())
                .any(|r| r.explains)
    }

    /// The accepted refit.
    pub fn chosen(&self) -> Option<&Refit> {
        self.candidates
            .iter()
            .filter_map(|c| c.refit.as_ref())
            .find(|r| r.accepted)
    }
    /// χ²/dof before.
    pub fn chi2_per_dof_before(&self) -> f64 {
        self.base.chi2_per_dof.unwrap_or(f64::NAN)
    }
    /// χ²/dof after (the base's when nothing was named).
    pub fn chi2_per_dof_after(&self) -> f64 {
        self.chosen()
            .and_then(|r| r.fit.chi2_per_dof)
            .unwrap_or_else(|| self.chi2_per_dof_before())
    }
}

/// Fill missing standard deviations with the assumed noise.
pub fn with_noise(data: &SegmentData) -> (SegmentData, bool) {
    let mut d = data.clone();
    let mut assumed = false;
    for m in &mut d.measurements {
        if m.k_re_std.is_none() {
            m.k_re_std = Some(ASSUMED_K_RE_RSTD * m.k_re);
            assumed = true;
        }
        if m.attenuation_std.is_none() {
            m.attenuation_std = Some(ASSUMED_ATTENUATION_RSTD * m.attenuation.max(1e-9));
            assumed = true;
        }
    }
    (d, assumed)
}

fn fit_settings(s: &DiagnoseSettings, effects: Vec<Effect>) -> FitSettings {
    FitSettings {
        model: s.model,
        contact_mode: s.contact_mode,
        effects,
        ..FitSettings::default()
    }
}

/// Diagnose one segment, in the steps of the module's description: prepare the base fit and
/// its residuals ([`prepare`]), score every candidate ([`score_candidates`]), refit the ones
/// worth refitting and test them ([`refit_candidates`]), check the inventory record when no
/// physics explains the misfit ([`check_inventory`]), then name the effect and the ones the data
/// cannot tell apart from it ([`name_effect`]). `base` is the segment's current fit when it
/// already has stated stds and was made with `settings`; otherwise the base is refitted with
/// the assumed noise.
pub fn diagnose_segment(
    data: &SegmentData,
    base: Option<FitResult>,
    settings: &DiagnoseSettings,
) -> Diagnosis {
    let mut diag = prepare(data, base, settings);
    diag.candidates = score_candidates(&diag, settings);
    if needs_explanation(&diag) {
        refit_candidates(&mut diag, settings);
        if settings.candidates.contains(&Effect::InventoryError) {
            check_inventory(&mut diag, settings);
        }
        if settings.candidates.contains(&Effect::MeasurementUnits) {
            check_units(&mut diag, settings);
        }
        name_effect(&mut diag);
    }
    diag
}

/// Step 1 (find): the data with stds, the base fit, its residuals and their structure.
pub fn prepare(
    data: &SegmentData,
    base: Option<FitResult>,
    settings: &DiagnoseSettings,
) -> Diagnosis {
    let (data, assumed_noise) = with_noise(data);
    let base = match base {
        Some(b) if !assumed_noise && b.status != FitStatus::Failed => b,
        _ => fit_segment(
            &data,
            &fit_settings(settings, settings.base_effects.clone()),
            settings.seed,
        ),
    };
    let before = Residuals::of(&data, &base.predicted);
    let structure = structure(&before, base.estimates.len());
    Diagnosis {
        base,
        data,
        assumed_noise,
        before,
        structure,
        candidates: Vec::new(),
        named: None,
        ambiguous_with: Vec::new(),
        ambiguity: Vec::new(),
        record: None,
        record_alternatives: Vec::new(),
        record_set: Vec::new(),
        record_separation: String::new(),
        units: None,
        after: None,
        holdout_base: None,
    }
}

/// Whether the base leaves something to explain: misfit far above the noise, or no base fit.
pub fn needs_explanation(diag: &Diagnosis) -> bool {
    diag.structure.structured || diag.base_failed()
}

/// Step 2a (name, cheaply): the score statistic of every candidate physical effect at the base
/// fit, best first (`full_model` only for a `seed` base; the discrete alternatives,
/// `inventory_error` and `measurement_units`, are not scored). An effect the segment's
/// material cannot have ([`Effect::applies_to`]: a plastic wall does not thin) is no candidate.
pub fn score_candidates(diag: &Diagnosis, settings: &DiagnoseSettings) -> Vec<Candidate> {
    let material = diag.data.material;
    let mut cands: Vec<Candidate> = settings
        .candidates
        .iter()
        .filter(|e| !settings.base_effects.contains(e) && !e.is_discrete())
        .filter(|e| material.is_none_or(|m| e.applies_to(m)))
        .filter(|e| **e != Effect::FullModel || diag.base.model == Model::Seed)
        .map(|&e| Candidate {
            effect: e,
            score: score(&diag.data, &diag.base, settings, e),
            refit: None,
        })
        .collect();
    let key = |c: &Candidate| {
        if c.score.is_nan() {
            f64::INFINITY
        } else {
            c.score
        }
    };
    cands.sort_by(|a, b| key(b).total_cmp(&key(a)));
    cands
}

/// The candidates to refit: those with a positive score; all of them when the best could
/// remove less than half the excess χ² (the score is a local, first-order view, and a base fit
/// far from the truth can point the wrong way), or the base could not be fitted at all.
pub fn refit_plan(diag: &Diagnosis) -> Vec<usize> {
    let excess = diag.before.chi2() - diag.structure.dof as f64;
    let best_score = diag
        .candidates
        .iter()
        .map(|c| c.score)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let all = diag.base_failed() || best_score < 0.5 * excess;
    (0..diag.candidates.len())
        .filter(|&i| all || diag.candidates[i].score.is_nan() || diag.candidates[i].score > 0.0)
        .collect()
}

/// The fit with `effects` added to the base model, never worse than the base: the
/// search also starts from the base optimum with the added effects at their neutral values.
pub fn extended_fit(
    data: &SegmentData,
    settings: &DiagnoseSettings,
    effects: Vec<Effect>,
    base: &FitResult,
) -> FitResult {
    crate::invert::fit::fit_extended(data, &fit_settings(settings, effects), settings.seed, base)
}

/// χ² of a diagnosed segment's data under its base model with `e` added and its parameter
/// held at `value` (physical units), every other parameter minimised
/// ([`crate::invert::assemble::predicted_with_effect_at`]) from the segment's own refit with `e`
/// where it has one (the nearest optimum), else from the base. `None` when the base failed,
/// the value is outside the effect's range, or the model gives no prediction.
pub fn chi2_with_effect_at(
    diag: &Diagnosis,
    settings: &DiagnoseSettings,
    e: Effect,
    value: f64,
) -> Option<f64> {
    let own = diag
        .refit_of(e)
        .map(|r| &r.fit)
        .filter(|f| f.status != FitStatus::Failed);
    chi2_with_effect_from(diag, settings, e, value, own)
}

/// [`chi2_with_effect_at`] minimised from `start`, a fit of the segment's data with `e` (its
/// own refit, or one made for the pooled test), else from the base.
pub fn chi2_with_effect_from(
    diag: &Diagnosis,
    settings: &DiagnoseSettings,
    e: Effect,
    value: f64,
    start: Option<&FitResult>,
) -> Option<f64> {
    if diag.base_failed() {
        return None;
    }
    let mut effects = settings.base_effects.clone();
    effects.push(e);
    effects.sort();
    effects.dedup();
    let k = crate::invert::assemble::predicted_with_effect_at(
        &diag.data,
        &fit_settings(settings, effects),
        start
            .filter(|f| f.status != FitStatus::Failed)
            .unwrap_or(&diag.base),
        e,
        value,
    )?;
    Some(Residuals::of(&diag.data, &k).chi2()).filter(|c| c.is_finite())
}

/// Step 2b (name, by refitting): refit the planned candidates and test each against the base.
pub fn refit_candidates(diag: &mut Diagnosis, settings: &DiagnoseSettings) {
    let tried = refit_plan(diag);
    let n_tests = tried.len().max(1);
    for i in tried {
        let e = diag.candidates[i].effect;
        let mut effects = settings.base_effects.clone();
        effects.push(e);
        effects.sort();
        let fit = extended_fit(&diag.data, settings, effects.clone(), &diag.base);
        if fit.status == FitStatus::Failed {
            continue;
        }
        let data = diag.data.clone();
        let refit = judge(
            diag,
            settings,
            &data,
            fit,
            &effects,
            e.parameter().is_some(),
            n_tests,
        );
        diag.candidates[i].refit = Some(refit);
    }
}

/// The evidence for an extended fit of `data` (the segment's data, or an inventory candidate's)
/// against the base: likelihood ratio and its p-value (χ̄² for a parameter on its bound, χ²₁
/// otherwise), ΔAICc, leave-one-frequency-out prediction, and whether the extended fit itself
/// explains the data. Accepted when all pass at level [`ALPHA`]/`n_tests`.
fn judge(
    diag: &mut Diagnosis,
    settings: &DiagnoseSettings,
    data: &SegmentData,
    fit: FitResult,
    effects: &[Effect],
    on_bound: bool,
    n_tests: usize,
) -> Refit {
    let chi2_base = if diag.base_failed() {
        f64::INFINITY
    } else {
        diag.before.chi2()
    };
    let after = Residuals::of(data, &fit.predicted);
    let lr = chi2_base - after.chi2();
    let p_value = if lr.is_infinite() {
        0.0
    } else if on_bound {
        stats::chibar_sf(lr)
    } else {
        stats::chi2_sf(lr, 1.0)
    };
    let n = 2 * data.measurements.len();
    let (k0, k1) = (diag.base.estimates.len(), fit.estimates.len());
    let d_aicc = aicc(after.chi2(), n, k1) - aicc(chi2_base, n, k0);
    let hb = diag.holdout_base(settings);
    let he = holdout(data, &fit, settings, effects);
    // The extension must itself explain the data: an effect that removes part of a gross
    // misfit (a wrong inventory material, a unit mix-up) is not the missing physics.
    let explains = structure(&after, fit.estimates.len()).p_value >= EXPLAINED_P;
    let accepted = p_value < ALPHA / n_tests as f64
        && explains
        && d_aicc < 0.0
        && he.is_finite()
        && he < (1.0 - MIN_HOLDOUT_GAIN) * hb;
    Refit {
        fit,
        lr,
        p_value,
        d_aicc,
        holdout_base: hb,
        holdout_ext: he,
        explains,
        accepted,
        choices: 1,
    }
}

/// Step 2c (inventory, model §8 E8): fit the candidate records of a segment whose misfit needs
/// explaining, whether or not a physical effect was accepted (a thinner wall class looks like
/// thinning, a thicker one like a stiffer, lossier wall, another material like either). The
/// best record is tested like an effect, with the number of records tried in the
/// significance level. The records within [`inventory::record_set_threshold`] of it form the set the
/// data cannot tell apart (the wave sees mainly the hoop stiffness E_p·h/a), ranked by what the
/// inventory makes likely, with what would separate them.
pub fn check_inventory(diag: &mut Diagnosis, settings: &DiagnoseSettings) {
    let fs = fit_settings(settings, settings.base_effects.clone());
    let profile = settings.inventory.as_deref();
    let Some(best) =
        inventory::fit_best_record_among(&diag.data, profile, &fs, settings.seed, |_| true)
    else {
        return;
    };
    let effects = settings.base_effects.clone();
    let n_tests = best.tried.max(1);
    let prior =
        |c: &inventory::RecordCandidate| profile.map_or(1.0, |p| p.prior(c, settings.install_year));
    let mut set: Vec<RecordSetMember> = std::iter::once((best.candidate, &best.fit))
        .chain(
            best.alternatives
                .iter()
                .copied()
                .zip(best.alternative_fits.iter().map(|(_, f)| f)),
        )
        .map(|(c, f)| RecordSetMember {
            candidate: c,
            chi2: f.misfit,
            prior: prior(&c),
            fit: f.clone(),
        })
        .collect();
    set.sort_by(|a, b| a.rank_key().total_cmp(&b.rank_key()));
    diag.record_separation = record_separation(&diag.data, &set);
    diag.record_set = set;
    let mut refit = judge(
        diag, settings, &best.data, best.fit, &effects, false, n_tests,
    );
    refit.choices = n_tests;
    diag.record = Some((best.candidate, best.data));
    diag.record_alternatives = best.alternatives;
    diag.candidates.push(Candidate {
        effect: Effect::InventoryError,
        score: f64::NAN,
        refit: Some(refit),
    });
}

/// What would separate the records of a set from its first: the frequencies (on the grid of
/// [`ambiguity::separating_band`]) where some member's fitted model differs from the first's by
/// more than the noise; a trial hole for the members no frequency separates.
pub fn record_separation(data: &SegmentData, set: &[RecordSetMember]) -> String {
    let Some(first) = set.first() else {
        return String::new();
    };
    if set.len() == 1 {
        return String::new();
    }
    let mut bands: Vec<(f64, f64)> = Vec::new();
    let mut inseparable: Vec<String> = Vec::new();
    for m in &set[1..] {
        match ambiguity::separating_band(data, &first.fit, &m.fit) {
            Some(b) => bands.push(b),
            None => inseparable.push(m.candidate.label()),
        }
    }
    let mut words = Vec::new();
    if !bands.is_empty() {
        let lo = bands.iter().map(|b| b.0).fold(f64::INFINITY, f64::min);
        let hi = bands.iter().map(|b| b.1).fold(0.0, f64::max);
        words.push(format!(
            "{} of the {} other records differ from the first by more than {} sigma somewhere \
             in {}-{} Hz: measure there",
            bands.len(),
            set.len() - 1,
            ambiguity::SEPARATION_SIGMAS,
            crate::units::sig(lo, 3),
            crate::units::sig(hi, 3)
        ));
    }
    if !inseparable.is_empty() {
        words.push(format!(
            "no frequency separates {} from the first at this noise: {}",
            inseparable.join(" | "),
            ambiguity::field_test(Effect::InventoryError)
        ));
    }
    words.join("; ")
}

/// Step 2c' (measurement units): refit the data with each unit mix-up undone
/// ([`units::UnitMixUp`]); the best is tested like a record, with the number of mix-ups tried
/// in the level. The stored measurements are not touched.
pub fn check_units(diag: &mut Diagnosis, settings: &DiagnoseSettings) {
    use rayon::prelude::*;
    let fs = fit_settings(settings, settings.base_effects.clone());
    let fits: Vec<(units::UnitMixUp, SegmentData, FitResult)> = units::UnitMixUp::ALL
        .par_iter()
        .map(|&u| {
            let d = u.corrected(&diag.data);
            let f = fit_segment(&d, &fs, settings.seed);
            (u, d, f)
        })
        .collect();
    let Some((u, d, f)) = fits
        .into_iter()
        .filter(|x| x.2.status != FitStatus::Failed && x.2.misfit.is_finite())
        .min_by(|a, b| a.2.misfit.total_cmp(&b.2.misfit))
    else {
        return;
    };
    let effects = settings.base_effects.clone();
    let mut refit = judge(
        diag,
        settings,
        &d,
        f,
        &effects,
        false,
        units::UnitMixUp::ALL.len(),
    );
    refit.choices = units::UnitMixUp::ALL.len();
    diag.units = Some((u, d));
    diag.candidates.push(Candidate {
        effect: Effect::MeasurementUnits,
        score: f64::NAN,
        refit: Some(refit),
    });
}

/// Step 2d: among accepted effects keep the one that explains most (lowest χ² after). Effects
/// within [`TIE_LR`] of it explain the data equally well: the tie is broken by [`PRIOR_ORDER`]
/// and the others are reported as ambiguous, with the quantity both change and the measurement
/// that would separate them. A record and a physical effect are not nested (a discrete choice
/// against a continuum that can mimic it): the data tell them apart only when their χ² differ by
/// more than the χ²₁ quantile at level [`ALPHA`], the level at which a record is accepted. Within
/// that window they are a tie, broken by AICc: the record, which has no continuous parameter,
/// is named when its AICc, plus 2 ln K for being the best of the K records (or unit mix-ups)
/// tried, is no higher than that of the best tied physical effect, the physical effect
/// otherwise; the other is reported as ambiguous with it. A
/// wrong record is the commonest real discrepancy and the cheapest to check. One
/// exception: in a pipe that corrodes or graphitises (every non-plastic material, model §8 E4),
/// wall thinning keeps its place when it is the physical effect [`PRIOR_ORDER`] names and fits
/// at least as well as the record, because an old iron wall thins as often as its record is
/// wrong; a plastic wall does not thin, so there a thinner wall is a record to check.
pub fn name_effect(diag: &mut Diagnosis) {
    let chi2_of = |c: &Candidate| -> Option<f64> {
        let r = c.refit.as_ref().filter(|r| r.accepted)?;
        Some(r.fit.misfit)
    };
    let accepted: Vec<(usize, f64)> = diag
        .candidates
        .iter()
        .enumerate()
        .filter_map(|(i, c)| chi2_of(c).map(|x| (i, x)))
        .collect();
    let is_record = |i: usize| diag.candidates[i].effect.is_discrete();
    let (top_i, top) = accepted
        .iter()
        .copied()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((usize::MAX, f64::INFINITY));
    let record_tie = stats::chi2_isf(ALPHA, 1.0);
    let tied: Vec<usize> = accepted
        .iter()
        .filter(|a| {
            let window = if top_i != usize::MAX && is_record(a.0) != is_record(top_i) {
                record_tie
            } else {
                TIE_LR
            };
            a.1 <= top + window
        })
        .map(|a| a.0)
        .collect();
    let rank = |i: &usize| {
        PRIOR_ORDER
            .iter()
            .position(|e| *e == diag.candidates[*i].effect)
            .unwrap_or(PRIOR_ORDER.len())
    };
    let d_aicc = |i: usize| {
        diag.candidates[i]
            .refit
            .as_ref()
            .map_or(f64::INFINITY, |r| r.d_aicc)
    };
    let chi2 = |i: usize| {
        accepted
            .iter()
            .find(|a| a.0 == i)
            .map_or(f64::INFINITY, |a| a.1)
    };
    let physical = tied.iter().copied().filter(|&i| !is_record(i));
    // The discrete alternative (a record or the units) that fits best.
    let record = tied
        .iter()
        .copied()
        .filter(|&i| is_record(i))
        .min_by(|&a, &b| chi2(a).total_cmp(&chi2(b)).then(rank(&a).cmp(&rank(&b))));
    let best_physical_aicc = physical.clone().map(d_aicc).fold(f64::INFINITY, f64::min);
    let physical_named = physical.min_by_key(rank);
    let corroded_wall = |r: usize| {
        physical_named.is_some_and(|i| {
            diag.candidates[i].effect == Effect::WallThinning && chi2(i) <= chi2(r)
        }) && diag.data.material.is_some_and(|m| !m.is_plastic())
    };
    // The best of K discrete alternatives is chosen after seeing the data: that choice is a
    // parameter too, priced like one in the information criterion at 2 ln K (the description
    // length of picking one of K), so a large catalogue does not win ties by its size alone.
    let choice_price = |i: usize| {
        let k = diag.candidates[i].refit.as_ref().map_or(1, |r| r.choices);
        2.0 * (k.max(1) as f64).ln()
    };
    let best = match record {
        Some(r) if d_aicc(r) + choice_price(r) <= best_physical_aicc && !corroded_wall(r) => {
            Some(r)
        }
        _ => physical_named.or(record),
    };
    for (i, c) in diag.candidates.iter_mut().enumerate() {
        if let Some(r) = c.refit.as_mut() {
            r.accepted = Some(i) == best;
        }
    }
    let Some(b) = best else { return };
    let named = diag.candidates[b].effect;
    let named_fit = diag.candidates[b]
        .refit
        .as_ref()
        .expect("accepted")
        .fit
        .clone();
    diag.named = Some(named);
    let named_data = diag.fit_data(named).clone();
    diag.after = Some(Residuals::of(&named_data, &named_fit.predicted));
    for &i in tied.iter().filter(|&&i| i != b) {
        let other = diag.candidates[i].effect;
        let fit = &diag.candidates[i].refit.as_ref().expect("accepted").fit;
        let band = ambiguity::separating_band(&diag.data, &named_fit, fit);
        diag.ambiguous_with.push(other);
        diag.ambiguity.push(ambiguity::describe(named, other, band));
    }
}

/// AICc = χ² + 2k + 2k(k + 1)/(n − k − 1) (Hurvich & Tsai 1989), ∞ when n ≤ k + 1.
pub fn aicc(chi2: f64, n: usize, k: usize) -> f64 {
    if n <= k + 1 {
        return f64::INFINITY;
    }
    chi2 + 2.0 * k as f64 + 2.0 * (k * (k + 1)) as f64 / (n - k - 1) as f64
}

/// Score statistic of effect `e` at the base fit: U²/I, with U = J_θᵀr the gradient of χ²/2
/// in the effect's natural parameter at its neutral value, and I = J_θᵀJ_θ − J_θᵀJ_b(J_bᵀJ_b)⁻¹J_bᵀJ_θ
/// the information left after the base parameters adjust (the efficient score). One-sided:
/// 0 when lowering χ² needs the parameter to leave its allowed side. `NaN` for `full_model`.
/// `NaN` also for `viscoelastic_wall`, whose nearest wall to the base's (same loss factor) still
/// differs from it away from ω_ref: the model is not nested, so it is judged by its refit.
fn score(data: &SegmentData, base: &FitResult, s: &DiagnoseSettings, e: Effect) -> f64 {
    if e.parameter().is_none() || e == Effect::ViscoelasticWall {
        return f64::NAN;
    }
    let Some(sys0) = base.system else {
        return 0.0;
    };
    let omegas: Vec<f64> = data.measurements.iter().map(|m| m.omega).collect();
    let resid = |k: &[Complex64]| -> Vec<f64> {
        let r = Residuals::of(data, k);
        r.re.iter()
            .zip(&r.att)
            .flat_map(|(a, b)| [*a, *b])
            .collect()
    };
    let r0 = resid(&base.predicted);
    // Neutral value and allowed direction of the natural parameter.
    let Some(neutral) = e.neutral_value(&sys0) else {
        return f64::NAN;
    };
    let dir = if e == Effect::WallThinning { -1.0 } else { 1.0 };
    // One-sided step in the natural parameter: 1e-6 in air fraction (it acts on the scale of
    // 1e-5, model §8 E3), 1e-3 in the loss factors and the wall ratio.
    let h = if e == Effect::AirInWater { 1e-6 } else { 1e-3 };
    let Ok(sys1) = e.apply(&sys0, neutral + dir * h) else {
        return 0.0;
    };
    let Some(k1) = predict(&sys1, &omegas) else {
        return 0.0;
    };
    let r1 = resid(&k1);
    let jt: Vec<f64> = r1.iter().zip(&r0).map(|(a, b)| (a - b) / h).collect();
    // Base Jacobian at the base optimum, in the base search coordinates.
    let p = Problem::new(
        data,
        crate::invert::Method::Default,
        s.model,
        s.contact_mode,
        &s.base_effects,
    );
    let x: Vec<f64> = base.estimates.iter().map(|e| e.coordinate).collect();
    let (m, n) = (r0.len(), x.len());
    let mut jb = vec![0.0; m * n];
    let Ok(b) = p.bounds() else { return 0.0 };
    // Residual order of Problem: (re, att) per measurement, the same as `resid`. Central
    // differences, else forward ones (near a bound or a grazing region one side may fail);
    // if both fail, the score is taken without projecting out the base parameters (it then
    // overstates what the effect can remove, which only affects the ranking: the refit and
    // its likelihood-ratio test decide).
    let jac_ok = [FiniteDifference::Central, FiniteDifference::Forward]
        .into_iter()
        .any(|scheme| {
            crate::optimize::jacobian_fd(&p, &x, &r0, Some(&b), scheme, 1e-6, &mut jb).is_ok()
        });
    if !jac_ok {
        jb.iter_mut().for_each(|v| *v = 0.0);
    }
    let u: f64 = jt.iter().zip(&r0).map(|(a, b)| a * b).sum();
    // The data lower χ² along +dir only if U < 0 (χ² decreases along −gradient).
    if u >= 0.0 {
        return 0.0;
    }
    let jtj = crate::optimize::linalg::jtj(&jb, m, n);
    let jbt_jt = crate::optimize::linalg::jt_vec(&jb, m, n, &jt);
    let sol = crate::optimize::linalg::solve_spd(&jtj, n, &jbt_jt);
    let info = jt.iter().map(|v| v * v).sum::<f64>()
        - jbt_jt.iter().zip(&sol).map(|(a, b)| a * b).sum::<f64>();
    if info <= 1e-12 * jt.iter().map(|v| v * v).sum::<f64>() {
        return 0.0;
    }
    // Efficient score: the residuals' gradient with the base directions projected out.
    let proj: Vec<f64> = {
        let jbr = crate::optimize::linalg::jt_vec(&jb, m, n, &r0);
        let sol_r = crate::optimize::linalg::solve_spd(&jtj, n, &jbr);
        (0..m)
            .map(|i| r0[i] - (0..n).map(|j| jb[i * n + j] * sol_r[j]).sum::<f64>())
            .collect()
    };
    let ue: f64 = jt.iter().zip(&proj).map(|(a, b)| a * b).sum();
    if ue >= 0.0 {
        return 0.0;
    }
    ue * ue / info
}

/// Leave-one-frequency-out prediction χ² of a fitted model: each measurement is dropped in
/// turn, the model is refitted locally (Levenberg–Marquardt from its full-data optimum) on the
/// rest, and the dropped measurement is predicted. NaN with fewer than 3 measurements.
pub fn holdout(
    data: &SegmentData,
    fit: &FitResult,
    s: &DiagnoseSettings,
    effects: &[Effect],
) -> f64 {
    let m = data.measurements.len();
    if m < 3 {
        return f64::NAN;
    }
    let x0: Vec<f64> = fit.estimates.iter().map(|e| e.coordinate).collect();
    let omegas: Vec<f64> = data.measurements.iter().map(|m| m.omega).collect();
    let mut total = 0.0;
    for i in 0..m {
        let mut d = data.clone();
        let held: Measurement = d.measurements.remove(i);
        let p = Problem::new(
            &d,
            crate::invert::Method::Default,
            s.model,
            s.contact_mode,
            effects,
        );
        let Ok(b) = p.bounds() else {
            return f64::INFINITY;
        };
        let x = match LevenbergMarquardt::new().minimize(&p, &x0, Some(&b)) {
            Ok(r) => r.x,
            Err(_) => x0.clone(),
        };
        let Some(sys) = p.system_at(&x) else {
            return f64::INFINITY;
        };
        let Some(k) = predict(&sys, &omegas) else {
            return f64::INFINITY;
        };
        let k = k[i];
        total += ((k.re - held.k_re) / held.k_re_std.unwrap_or(f64::NAN)).powi(2)
            + ((-k.im - held.attenuation) / held.attenuation_std.unwrap_or(f64::NAN)).powi(2);
    }
    total
}

/// The effect's fitted value and standard error in a fit.
pub fn effect_value(fit: &FitResult, e: Effect) -> Option<(f64, Option<f64>)> {
    fit.get(Param::Effect(e)).map(|x| (x.value, x.std))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trend_runs_and_aicc() {
        let x = [100.0, 200.0, 300.0, 400.0, 500.0];
        // A perfect line has an infinite t statistic; noise around a flat line a small one.
        assert!(trend_t(&x, &[1.0, 2.0, 3.0, 4.0, 5.0]).is_infinite());
        let t = trend_t(&x, &[0.1, -0.2, 0.15, -0.1, 0.05]);
        assert!(t.abs() < 1.0, "{t}");
        // Hand value: y = [0, 1, 0, 1, 3] on x = 1..5: slope 0.6, residual sum of squares 2.4,
        // t = 0.6 / sqrt(2.4/3/10).
        let t = trend_t(&[1.0, 2.0, 3.0, 4.0, 5.0], &[0.0, 1.0, 0.0, 1.0, 3.0]);
        assert!(
            (t - 0.6 / (2.4f64 / 3.0 / 10.0).sqrt()).abs() < 1e-12,
            "{t}"
        );
        assert_eq!(runs(&[1.0, 2.0, -1.0, -3.0, 2.0]), 3);
        assert_eq!(runs(&[]), 0);
        assert_eq!(aicc(10.0, 12, 3), 10.0 + 6.0 + 24.0 / 8.0);
        assert!(aicc(1.0, 4, 3).is_infinite());
    }

    #[test]
    fn structure_separates_noise_from_misfit() {
        let f = vec![100.0, 200.0, 300.0, 400.0, 500.0, 600.0];
        let quiet = Residuals {
            frequency_hz: f.clone(),
            re: vec![0.5, -0.8, 0.3, 1.1, -0.4, 0.2],
            att: vec![-0.9, 0.4, 0.7, -0.2, 1.0, -0.6],
        };
        let s = structure(&quiet, 3);
        assert!(
            !s.structured && s.pattern == "residuals within the noise",
            "{s:?}"
        );
        // Attenuation far above the data and rising: the signature of a missing loss.
        let lossy = Residuals {
            frequency_hz: f,
            re: vec![0.5, -0.8, 0.3, 1.1, -0.4, 0.2],
            att: vec![-2.0, -3.5, -5.0, -6.8, -8.1, -9.9],
        };
        let s = structure(&lossy, 3);
        assert!(s.structured, "{s:?}");
        assert_eq!(
            s.pattern,
            "attenuation: model below the data, falling with frequency"
        );
        assert_eq!(s.runs, (5, 1));
    }
}
