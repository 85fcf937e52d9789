//! The result of fitting one segment: the fitted parameters with their intervals, the misfit,
//! the soil's wave speeds, the predicted curve with its errors, the findings, and the record of
//! the search that found it. Built once from the search's optima by [`super::assemble`].

use num_complex::Complex64;

use super::fit::FitSettings;
use super::flags::{Flag, FlagCode};
use super::problem::{Method, Param, Weighting};
use super::provenance::{Provenance, SearchError};
use super::uncertainty::{Interval, WithError};
use crate::physics::effects::Effect;
use crate::physics::{ContactMode, Model, System};
use crate::types::FitStatus;

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// What it is.
    pub param: Param,
    /// Value in physical units.
    pub value: f64,
    /// One-sigma error in physical units, consistent with `interval` (its width / 3.92);
    /// `None` only for a parameter of a failed fit.
    pub std: Option<f64>,
    /// The search coordinate (log10 for E_m in the default method).
    pub coordinate: f64,
    /// One-sigma error of the coordinate, from the covariance.
    pub coordinate_std: f64,
    /// 95 % interval in physical units (P66 construction, clipped to the search box).
    pub interval: Interval,
}

/// One point of the predicted curve, with its errors (P65).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictedPoint {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Phase speed, m/s (None where the root was not found).
    pub phase_speed: Option<f64>,
    /// Its one-sigma error, m/s.
    pub phase_speed_std: Option<f64>,
    /// Attenuation, dB/m.
    pub attenuation_db: Option<f64>,
    /// Its one-sigma error, dB/m.
    pub attenuation_db_std: Option<f64>,
    /// The model's phase speed, m/s: `phase_speed` unless the curve is corrected by a
    /// discrepancy ([`CurveSource::ModelPlusDiscrepancy`]).
    pub model_phase_speed: Option<f64>,
    /// The model's attenuation, dB/m.
    pub model_attenuation_db: Option<f64>,
}

/// What a fit's curve is (`fits.curve_source`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurveSource {
    /// The fitted model's curve: the model explains the data.
    Model,
    /// The model plus the discrepancy fitted to its residuals (P89): the misfit is significant.
    ModelPlusDiscrepancy,
}

impl CurveSource {
    /// Name used in the database and the exports.
    pub fn as_str(self) -> &'static str {
        match self {
            CurveSource::Model => "model",
            CurveSource::ModelPlusDiscrepancy => "model+discrepancy",
        }
    }
}

/// The result of fitting one segment.
#[derive(Debug, Clone)]
pub struct FitResult {
    /// Status.
    pub status: FitStatus,
    /// Method used.
    pub method: Method,
    /// Model used (after `full_model`).
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects used.
    pub effects: Vec<Effect>,
    /// Fitted parameters, in search-space order (E_m, ν_m, ξ, then effects).
    pub estimates: Vec<Estimate>,
    /// Objective at the optimum: the paper's f (paper method) or the sum of squared weighted
    /// residuals (default).
    pub misfit: f64,
    /// χ²/(2M − n) when measurement standard deviations are known.
    pub chi2_per_dof: Option<f64>,
    /// Weighting used by the default method.
    pub weighting: Weighting,
    /// Number of measurements M.
    pub n_measurements: usize,
    /// Condition number of the column-scaled information matrix.
    pub condition_number: Option<f64>,
    /// Correlation matrix of the fitted coordinates, row-major.
    pub correlations: Vec<f64>,
    /// Flags: what the user must act on (empty: status `ok`).
    pub flags: Vec<Flag>,
    /// Notes: what the data leave undetermined.
    pub notes: Vec<Flag>,
    /// Forward-model evaluations used (search + polish + uncertainty); a Jacobian step solved
    /// one Newton step from its centre's roots, and the centre's re-solve, count one each.
    pub evaluations: usize,
    /// The fitted system, `None` when the fit failed.
    pub system: Option<System>,
    /// Model wavenumbers at the measured frequencies.
    pub predicted: Vec<Complex64>,
    /// Why the fit failed.
    pub message: Option<String>,
    /// Best objective of every restart (and of the nested start), after
    /// polish.
    pub restart_misfits: Vec<f64>,
    /// The search path's roots agreed with the reference path at the optimum.
    pub path_checked: bool,
    /// The soil's compressional speed c_P, m/s (P63, P65).
    pub p_wave_speed: Option<WithError>,
    /// The soil's shear speed c_S, m/s (P64, P65).
    pub s_wave_speed: Option<WithError>,
    /// The predicted curve on [`STANDARD_GRID_HZ`](crate::physics::curves::STANDARD_GRID_HZ)
    /// with errors (empty when failed).
    pub curve: Vec<PredictedPoint>,
    /// Mean phase speed over [`LEAK_BAND_HZ`](crate::physics::curves::LEAK_BAND_HZ), m/s, with
    /// its error.
    pub leak_band_speed: Option<WithError>,
    /// The information about (ln c_P, ln c_S) with ξ and the effects profiled out, divided by
    /// the misfit's variance factor (R_B², P88): (I_PP, I_PS, I_SS), eq. P79. What the soil
    /// field of the network learns from this fit. None for a failed fit or unknown curvature.
    pub soil_information: Option<[f64; 3]>,
    /// Whether `curve` and `leak_band_speed` are the model's or corrected by a discrepancy.
    pub curve_source: CurveSource,
    /// How far [`LEAK_BAND_HZ`](crate::physics::curves::LEAK_BAND_HZ) reaches beyond the
    /// measured frequencies, octaves.
    pub leak_band_extrapolation_octaves: Option<f64>,
    /// Wall-clock time of building the result after the search (uncertainty, curve with
    /// errors, findings), s: what reporting what the data determine costs (`pipewave bench`).
    pub result_seconds: f64,
    /// Which stage of the search found the answer, and what every stage did.
    pub provenance: Provenance,
}

impl FitResult {
    /// Whether a flag (not a note) of this kind was raised.
    pub fn has_flag(&self, code: FlagCode) -> bool {
        self.flags.iter().any(|f| f.code == code)
    }
    /// The estimate of a parameter.
    pub fn get(&self, param: Param) -> Option<&Estimate> {
        self.estimates.iter().find(|e| e.param == param)
    }
    /// Fitted soil Young's modulus, Pa.
    pub fn soil_modulus(&self) -> Option<f64> {
        self.get(Param::SoilModulus).map(|e| e.value)
    }
    /// Fitted soil Poisson's ratio.
    pub fn soil_poisson(&self) -> Option<f64> {
        self.get(Param::SoilPoisson).map(|e| e.value)
    }
    /// Fitted contact coefficient.
    pub fn contact(&self) -> Option<f64> {
        self.get(Param::Contact).map(|e| e.value)
    }
    /// The optimum in the search coordinates, in the order of the parameter space (empty for a
    /// failed fit): a start for [`refit_from`](super::fit::refit_from).
    pub fn coordinates(&self) -> Vec<f64> {
        self.estimates.iter().map(|e| e.coordinate).collect()
    }
    /// Comma-separated flag codes.
    pub fn flag_codes(&self) -> String {
        codes(&self.flags)
    }
    /// Comma-separated note codes.
    pub fn note_codes(&self) -> String {
        codes(&self.notes)
    }

    pub(super) fn failed(
        settings: &FitSettings,
        weighting: Weighting,
        n: usize,
        msg: String,
    ) -> Self {
        FitResult {
            status: FitStatus::Failed,
            method: settings.method,
            model: settings.model,
            contact_mode: settings.contact_mode,
            effects: settings.effects.clone(),
            estimates: Vec::new(),
            misfit: f64::NAN,
            chi2_per_dof: None,
            weighting,
            n_measurements: n,
            condition_number: None,
            correlations: Vec::new(),
            flags: Vec::new(),
            notes: Vec::new(),
            evaluations: 0,
            system: None,
            predicted: Vec::new(),
            message: Some(msg),
            restart_misfits: Vec::new(),
            path_checked: true,
            p_wave_speed: None,
            s_wave_speed: None,
            curve: Vec::new(),
            leak_band_speed: None,
            soil_information: None,
            curve_source: CurveSource::Model,
            leak_band_extrapolation_octaves: None,
            result_seconds: 0.0,
            provenance: Provenance::default(),
        }
    }

    /// A failed fit whose search gave the typed reason `e`.
    pub(super) fn failed_by(
        settings: &FitSettings,
        weighting: Weighting,
        n: usize,
        e: SearchError,
    ) -> Self {
        let mut r = Self::failed(settings, weighting, n, e.to_string());
        r.provenance.error = Some(e);
        r
    }
}

fn codes(v: &[Flag]) -> String {
    v.iter()
        .map(|f| f.code.as_str())
        .collect::<Vec<_>>()
        .join(",")
}
