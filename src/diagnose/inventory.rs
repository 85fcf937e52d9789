//! Inventory-record errors (model §8 E8): the inventory describes another pipe than the one
//! measured. The candidates are whole records, not a model parameter: every other material of
//! §3.3 at its standard sizes, the neighbouring wall classes / SDRs of the recorded material,
//! the diameter and wall in inches read as mm (×25.4) and the reverse (÷25.4), and the nominal
//! size DN recorded in place of the outside diameter. Each candidate is fitted with the same
//! settings as the base; the answer names the record to check.
//!
//! [`fit_with_records`] is the `calibrate --effects inventory_error` entry point: it fits the
//! recorded pipe, tests every candidate record as `diagnose` does ([`fit_best_record`] and the
//! diagnosis's likelihood-ratio, AICc and held-out tests), and keeps the record the data
//! choose, saying which in the fit's message.

use rayon::prelude::*;

use crate::invert::fit::{fit_segment, FitResult, FitSettings, FitStatus};
use crate::invert::problem::SegmentData;
use crate::physics::{InputError, Material, MaterialProps, Pipe};
use crate::synth::sizes;

/// Standard dimension ratios OD/wall of plastic pressure pipe (ISO 4065 series, the SDRs of
/// EN 1452 and EN 12201).
pub const SDR_SERIES: [f64; 10] = [6.0, 7.4, 9.0, 11.0, 13.6, 17.0, 21.0, 26.0, 33.0, 41.0];
/// Wall classes K of ductile iron (ISO 2531: e = K(0.5 + 0.001 DN) mm).
pub const DI_K_CLASSES: [f64; 5] = [7.0, 8.0, 9.0, 10.0, 12.0];
/// Ratio of neighbouring wall classes of grey iron, steel and asbestos cement, for which the
/// catalogue has no class series (an assumption: about one pressure class step).
pub const WALL_CLASS_STEP: f64 = 1.25;
/// Millimetres per inch.
pub const MM_PER_INCH: f64 = 25.4;
/// A recorded outside diameter above this cannot be a number of inches (the largest water
/// mains are about 80 in): the ×25.4 candidate is tried only below it.
pub const MAX_DIAMETER_INCHES: f64 = 80.0;
/// A standard size counts as "near" the recorded diameter within this factor (the catalogue's
/// sizes span 63–429 mm, so every size within a factor 4 is tried: relinings and
/// replacements change the diameter a lot, model §8 E8's example 110 → 180 mm).
pub const NEAR_DIAMETER_FACTOR: f64 = 4.0;
/// Screening fit of every candidate: one DE run with this budget per parameter …
pub const SCREEN_EVALUATIONS_PER_DIMENSION: usize = 60;
/// … then the best few are refitted with the full settings, and the best-screened record of
/// every material besides (a short search can miss a plastic pipe's optimum by far, and each
/// material is a different physical answer).
pub const SCREEN_KEEP: usize = 3;

/// How a candidate record differs from the recorded one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordChange {
    /// Another material at one of its standard sizes.
    Material,
    /// The recorded material with a neighbouring wall class or SDR.
    WallClass,
    /// Diameter and wall recorded in inches (true values ×25.4).
    Inches,
    /// Diameter and wall recorded in mm where inches were meant (true values ÷25.4).
    InverseInches,
    /// The nominal size DN recorded as the outside diameter.
    NominalAsOutside,
}

impl RecordChange {
    /// Plain words.
    pub fn describe(self) -> &'static str {
        match self {
            RecordChange::Material => "another material",
            RecordChange::WallClass => "another wall class",
            RecordChange::Inches => "diameter recorded in inches",
            RecordChange::InverseInches => "diameter converted to inches twice",
            RecordChange::NominalAsOutside => "nominal size DN recorded as the outside diameter",
        }
    }
}

/// One candidate inventory record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordCandidate {
    /// What changed.
    pub change: RecordChange,
    /// Material.
    pub material: Material,
    /// Outside diameter, mm.
    pub outside_diameter_mm: f64,
    /// Wall thickness, mm.
    pub wall_mm: f64,
}

impl RecordCandidate {
    /// The record to check, in the interface's form: `material=HDPE; OD 180 mm; wall 16.4 mm`.
    pub fn label(&self) -> String {
        // Millimetres to one decimal, without trailing zeros ("180", "16.4").
        let mm = |v: f64| ((v * 10.0).round() / 10.0).to_string();
        format!(
            "material={}; OD {} mm; wall {} mm",
            self.material.code(),
            mm(self.outside_diameter_mm),
            mm(self.wall_mm)
        )
    }

    /// The segment with this record in place of the recorded pipe: the candidate material's
    /// typical properties (§3.3) when the material changes, the recorded ones otherwise.
    pub fn segment_data(&self, data: &SegmentData) -> Result<SegmentData, InputError> {
        let props = if Some(self.material) == data.material {
            MaterialProps {
                youngs_modulus: data.pipe.youngs_modulus,
                poisson: data.pipe.poisson,
                density: data.pipe.density,
                loss_factor: data.pipe.loss_factor,
            }
        } else {
            self.material.typical()
        };
        let pipe = Pipe::from_outside_diameter(
            props,
            self.outside_diameter_mm * 1e-3,
            self.wall_mm * 1e-3,
        )?;
        Ok(SegmentData {
            pipe,
            material: Some(self.material),
            ..data.clone()
        })
    }
}

/// The recorded outside diameter and wall, mm (OD = 2a + h, eq. P6).
pub fn recorded_size(data: &SegmentData) -> (f64, f64) {
    let h = data.pipe.wall_thickness;
    ((2.0 * data.pipe.mean_radius + h) * 1e3, h * 1e3)
}

fn neighbours(series: &[f64], value: f64) -> Vec<f64> {
    let i = (0..series.len())
        .min_by(|&a, &b| {
            (series[a] / value)
                .ln()
                .abs()
                .total_cmp(&(series[b] / value).ln().abs())
        })
        .unwrap_or(0);
    [i.checked_sub(1), Some(i + 1)]
        .into_iter()
        .flatten()
        .filter_map(|j| series.get(j).copied())
        .collect()
}

/// The candidate records of model §8 E8 for a segment, each a valid pipe (a candidate the
/// thin-shell model cannot take is left out).
pub fn candidates(data: &SegmentData) -> Vec<RecordCandidate> {
    let (od, wall) = recorded_size(data);
    let mut out = Vec::new();
    // Other materials at their standard sizes near the recorded diameter.
    for m in Material::ALL {
        if Some(m) == data.material {
            continue;
        }
        for s in sizes(m) {
            let ratio = s.od_mm / od;
            if (1.0 / NEAR_DIAMETER_FACTOR..=NEAR_DIAMETER_FACTOR).contains(&ratio) {
                out.push(RecordCandidate {
                    change: RecordChange::Material,
                    material: m,
                    outside_diameter_mm: s.od_mm,
                    wall_mm: s.wall_mm,
                });
            }
        }
    }
    if let Some(m) = data.material {
        // Neighbouring wall classes of the recorded material.
        let walls: Vec<f64> = if m.is_plastic() {
            neighbours(&SDR_SERIES, od / wall)
                .into_iter()
                .map(|sdr| od / sdr)
                .collect()
        } else if m == Material::DuctileIron {
            let dn = sizes(m)
                .iter()
                .min_by(|a, b| (a.od_mm - od).abs().total_cmp(&(b.od_mm - od).abs()))
                .map(|s| s.dn as f64)
                .unwrap_or(od);
            let unit = 0.5 + 0.001 * dn;
            neighbours(&DI_K_CLASSES, wall / unit)
                .into_iter()
                .map(|k| k * unit)
                .collect()
        } else {
            vec![wall / WALL_CLASS_STEP, wall * WALL_CLASS_STEP]
        };
        for w in walls {
            out.push(RecordCandidate {
                change: RecordChange::WallClass,
                material: m,
                outside_diameter_mm: od,
                wall_mm: (w * 10.0).round() / 10.0,
            });
        }
        // DN in place of OD: the standard size whose DN is the recorded "OD".
        if let Some(s) = sizes(m)
            .iter()
            .find(|s| (s.dn as f64 - od).abs() <= 0.5 && (s.od_mm - od).abs() > 0.5)
        {
            out.push(RecordCandidate {
                change: RecordChange::NominalAsOutside,
                material: m,
                outside_diameter_mm: s.od_mm,
                wall_mm: s.wall_mm,
            });
        }
    }
    // Units: inches read as mm, and the reverse.
    for (change, f) in [
        (RecordChange::Inches, MM_PER_INCH),
        (RecordChange::InverseInches, 1.0 / MM_PER_INCH),
    ] {
        if change == RecordChange::Inches && od > MAX_DIAMETER_INCHES {
            continue;
        }
        out.push(RecordCandidate {
            change,
            material: data.material.unwrap_or(Material::DuctileIron),
            outside_diameter_mm: od * f,
            wall_mm: wall * f,
        });
    }
    out.retain(|c| c.segment_data(data).is_ok());
    out
}

/// A candidate record and its fit.
#[derive(Debug, Clone)]
pub struct RecordFit {
    /// The record.
    pub candidate: RecordCandidate,
    /// The segment with that record.
    pub data: SegmentData,
    /// The fit.
    pub fit: FitResult,
    /// How many candidate records were tried (for the significance level).
    pub tried: usize,
    /// The other records fitted in full that the data do not reject against this one: their χ²
    /// exceeds its χ² by less than the χ²₁ quantile at level [`super::ALPHA`] (the level at
    /// which a record is rejected against the recorded one). Grey and ductile iron of about the
    /// same stiffness per length, E_p·h, are one example.
    pub alternatives: Vec<RecordCandidate>,
}

/// Fit every candidate record of `data` with `settings` (screened by a short fit, the best
/// [`SCREEN_KEEP`] refitted in full) and return the best, or `None` when no candidate could be
/// fitted. Deterministic for a given seed, whatever the thread count.
pub fn fit_best_record(data: &SegmentData, settings: &FitSettings, seed: u64) -> Option<RecordFit> {
    fit_best_record_among(data, settings, seed, |_| true)
}

/// [`fit_best_record`] over the candidates that `keep` accepts.
pub fn fit_best_record_among(
    data: &SegmentData,
    settings: &FitSettings,
    seed: u64,
    keep: impl Fn(&RecordCandidate) -> bool,
) -> Option<RecordFit> {
    let mut cands = candidates(data);
    cands.retain(|c| keep(c));
    let tried = cands.len();
    let screen = FitSettings {
        restarts: 1,
        evaluations_per_dimension: SCREEN_EVALUATIONS_PER_DIMENSION,
        ..settings.clone()
    };
    let mut screened: Vec<(usize, f64)> = cands
        .par_iter()
        .enumerate()
        .filter_map(|(i, c)| {
            let d = c.segment_data(data).ok()?;
            let f = fit_segment(&d, &screen, seed);
            (f.status != FitStatus::Failed && f.misfit.is_finite()).then_some((i, f.misfit))
        })
        .collect();
    screened.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let mut seen = Vec::new();
    let screened: Vec<(usize, f64)> = screened
        .iter()
        .enumerate()
        .filter(|(rank, (i, _))| {
            let first_of_material = !seen.contains(&cands[*i].material);
            if first_of_material {
                seen.push(cands[*i].material);
            }
            *rank < SCREEN_KEEP || first_of_material
        })
        .map(|(_, x)| *x)
        .collect();
    let fits: Vec<RecordFit> = screened
        .par_iter()
        .filter_map(|&(i, _)| {
            let candidate = cands[i];
            let d = candidate.segment_data(data).ok()?;
            let fit = fit_segment(&d, settings, seed);
            (fit.status != FitStatus::Failed).then_some(RecordFit {
                candidate,
                data: d,
                fit,
                tried,
                alternatives: Vec::new(),
            })
        })
        .collect();
    let best = fits
        .iter()
        .min_by(|a, b| a.fit.misfit.total_cmp(&b.fit.misfit))?;
    let tie = super::stats::chi2_isf(super::ALPHA, 1.0);
    let alternatives = fits
        .iter()
        .filter(|f| f.candidate != best.candidate && f.fit.misfit < best.fit.misfit + tie)
        .map(|f| f.candidate)
        .collect();
    Some(RecordFit {
        alternatives,
        ..best.clone()
    })
}

/// The fit `calibrate --effects inventory_error` stores, and the record it was made with.
#[derive(Debug, Clone)]
pub struct RecordChoice {
    /// The fit: of the chosen candidate record, or of the recorded pipe. Its `effects` include
    /// `inventory_error`; its message says which record was fitted and why.
    pub fit: FitResult,
    /// The candidate record chosen over the recorded one (None: the recorded pipe was kept).
    pub record: Option<RecordCandidate>,
}

/// `calibrate --effects inventory_error` (model §8 E8): fit the segment as recorded with the
/// other effects of `settings`, and test the candidate records exactly as `diagnose` does (only
/// when the recorded pipe leaves a misfit far above the noise; the best record must pass the
/// likelihood-ratio test with the number of records tried in its level, lower the AICc, predict
/// held-out frequencies better and itself fit within the noise). When a record passes, the
/// stored fit is that record's, made with `settings`; otherwise the recorded pipe's. The
/// message names the record fitted, with χ²/dof of both.
pub fn fit_with_records(data: &SegmentData, settings: &FitSettings, seed: u64) -> RecordChoice {
    use super::report::{evidence, record_sentence};
    use crate::physics::effects::Effect;
    use crate::units::sig;

    let others: Vec<Effect> = settings
        .effects
        .iter()
        .copied()
        .filter(|e| *e != Effect::InventoryError)
        .collect();
    let plain = FitSettings {
        effects: others.clone(),
        ..settings.clone()
    };
    let recorded = fit_segment(data, &plain, seed);
    let ds = super::DiagnoseSettings {
        model: settings.model,
        contact_mode: settings.contact_mode,
        base_effects: others,
        candidates: vec![Effect::InventoryError],
        seed,
    };
    let base = (settings.method == crate::invert::Method::Default).then(|| recorded.clone());
    let diag = super::diagnose_segment(data, base, &ds);
    let chi2 = |f: &FitResult| sig(f.chi2_per_dof.unwrap_or(f64::NAN), 3);
    let (mut fit, record, message) = match (&diag.record, diag.named) {
        (Some((c, d)), Some(Effect::InventoryError)) => {
            let fit = fit_segment(d, &plain, seed);
            let message = format!(
                "inventory_error: {}; this fit is made with the record {} (chi2/dof {} -> {}; {})",
                record_sentence(&diag).unwrap_or_default(),
                c.label(),
                sig(diag.chi2_per_dof_before(), 3),
                sig(diag.chi2_per_dof_after(), 3),
                evidence(&diag)
            );
            (fit, Some(*c), message)
        }
        (Some((c, _)), _) => {
            let message = format!(
                "inventory_error: recorded pipe kept (chi2/dof {}); the best other record, {}, \
                 does not fit significantly better ({})",
                chi2(&recorded),
                c.label(),
                evidence(&diag)
            );
            (recorded, None, message)
        }
        (None, _) => {
            let message = format!(
                "inventory_error: recorded pipe kept (chi2/dof {}): {}",
                chi2(&recorded),
                if super::needs_explanation(&diag) {
                    "no candidate record could be fitted".to_string()
                } else {
                    evidence(&diag)
                }
            );
            (recorded, None, message)
        }
    };
    if fit.status != FitStatus::Failed {
        fit.effects.push(Effect::InventoryError);
        fit.effects.sort();
        fit.effects.dedup();
        fit.message = Some(match fit.message.take() {
            Some(m) => format!("{message}; {m}"),
            None => message,
        });
    }
    RecordChoice { fit, record }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Fluid;

    fn data(material: Material, od_mm: f64, wall_mm: f64) -> SegmentData {
        SegmentData {
            fluid: Fluid::water(),
            pipe: Pipe::from_outside_diameter(material.typical(), od_mm * 1e-3, wall_mm * 1e-3)
                .unwrap(),
            soil_density: 1900.0,
            material: Some(material),
            measurements: Vec::new(),
        }
    }

    #[test]
    fn candidates_cover_the_kinds_of_spec_e8() {
        // PVC 110 SDR 21 (wall 5.3): SDR 17 and 26 walls, MDPE 180 among the materials; 110 is
        // not a number of inches (left out), ÷25.4 is 4.3 mm (left out: a < 5 mm).
        let c = candidates(&data(Material::Pvc, 110.0, 5.3));
        let walls: Vec<f64> = c
            .iter()
            .filter(|c| c.change == RecordChange::WallClass)
            .map(|c| c.wall_mm)
            .collect();
        assert_eq!(walls, vec![6.5, 4.2]);
        assert!(c.iter().any(|c| c.material == Material::Mdpe
            && c.outside_diameter_mm == 180.0
            && c.label() == "material=MDPE; OD 180 mm; wall 16.4 mm"));
        assert!(c
            .iter()
            .all(|c| c.material != Material::Pvc || c.change == RecordChange::WallClass));
        // DN 150 recorded as OD 150 for ductile iron: the standard OD 170 is a candidate; a
        // 12-inch steel pipe (OD 12.75 in, wall 0.28 in) recorded in inches as mm: 323.85 mm.
        let c = candidates(&data(Material::DuctileIron, 150.0, 6.0));
        assert!(c
            .iter()
            .any(|c| c.change == RecordChange::NominalAsOutside && c.outside_diameter_mm == 170.0));
        let c = candidates(&data(Material::Steel, 12.75, 0.28));
        assert!(c.iter().any(|c| c.change == RecordChange::Inches
            && (c.outside_diameter_mm - 323.85).abs() < 1e-9
            && c.label() == "material=ST; OD 323.9 mm; wall 7.1 mm"));
    }
}
