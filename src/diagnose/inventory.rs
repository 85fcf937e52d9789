//! Inventory-record errors (model §8 E8): the inventory describes another pipe than the one
//! measured. The candidates are whole records, not a model parameter, drawn from the standard
//! catalogues ([`super::catalogue`]) and the utility's own sizes ([`InventoryProfile`]): every
//! other material at its sizes near the recorded diameter, every wall class / SDR of the
//! recorded material, the diameter and wall in inches read as mm (×25.4) and the reverse
//! (÷25.4), and the nominal size DN recorded in place of the outside diameter, the last two at
//! every wall of the catalogue. Each candidate is fitted with the same settings as the base;
//! the answer is the set of records the data cannot tell apart.
//!
//! [`fit_with_records`] is the `calibrate --effects inventory_error` entry point: it fits the
//! recorded pipe, tests every candidate record as `diagnose` does ([`fit_best_record`] and the
//! diagnosis's likelihood-ratio, AICc and held-out tests), and keeps the record the data
//! choose, saying which in the fit's message.

use rayon::prelude::*;

use crate::invert::problem::SegmentData;
use crate::invert::{fit_segment, FitResult, FitSettings};
use crate::physics::{InputError, Material, MaterialProps, Pipe};
use crate::types::FitStatus;

/// Standard dimension ratios OD/wall of plastic pressure pipe (ISO 4065 series, the SDRs of
/// EN 1452 and EN 12201).
pub const SDR_SERIES: [f64; 10] = [6.0, 7.4, 9.0, 11.0, 13.6, 17.0, 21.0, 26.0, 33.0, 41.0];
/// Wall classes K of ductile iron (ISO 2531: e = K(0.5 + 0.001 DN) mm).
pub const DI_K_CLASSES: [f64; 5] = [7.0, 8.0, 9.0, 10.0, 12.0];
/// Millimetres per inch.
pub const MM_PER_INCH: f64 = 25.4;
/// A recorded outside diameter above this cannot be a number of inches (the largest water
/// mains are about 80 in): the ×25.4 candidates are tried only below it.
pub const MAX_DIAMETER_INCHES: f64 = 80.0;
/// Another material's size counts as "near" the recorded diameter within this factor: a
/// relining or an unrecorded replacement keeps the nominal size or changes it by a few steps
/// (model §8 E8's example, a PVC 110 that is a PE 180, is a factor 1.64).
pub const NEAR_DIAMETER_FACTOR: f64 = 1.7;
/// A nominal size DN recorded in place of the outside diameter: the true outside diameter is
/// above the recorded number by at most this factor (DN 80 → OD 98, DN 100 → OD 125).
pub const DN_TO_OD_FACTOR: f64 = 1.25;
/// A nominal size in inches matches a catalogue size whose OD or DN is within this fraction
/// of the number of inches × 25.4 (4 in → DN 100, 6 in → OD 160 or 168.3).
pub const INCH_MATCH: f64 = 0.12;
/// Screening fit of every candidate: one DE run with this budget per parameter …
pub const SCREEN_EVALUATIONS_PER_DIMENSION: usize = 60;
/// … then the candidates whose screened χ² is within this many times the set's threshold of
/// the best screened one are refitted with the full settings (a short search can overshoot a
/// record's optimum, never undershoot it), at most [`MAX_FULL_FITS`] of them, and the
/// best-screened record of every material besides (each material is a different answer).
pub const SCREEN_MARGIN: f64 = 3.0;
/// The most candidates refitted in full from the screening.
pub const MAX_FULL_FITS: usize = 14;

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

/// One pipe of the utility's inventory, as the record check sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InventoryPipe {
    /// Material.
    pub material: Material,
    /// Outside diameter, mm.
    pub od_mm: f64,
    /// Wall, mm.
    pub wall_mm: f64,
    /// Installation year, if recorded.
    pub install_year: Option<i64>,
}

/// The utility's inventory (read from the database at diagnosis time): its sizes are added to
/// the catalogue's candidate records, and its materials, sizes and eras rank a set of records
/// the data cannot tell apart.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InventoryProfile {
    /// Every pipe of the inventory.
    pub pipes: Vec<InventoryPipe>,
}

/// Installation years within this many years of the segment's count as "its era".
pub const ERA_YEARS: i64 = 15;

fn same_size(a: (f64, f64), b: (f64, f64)) -> bool {
    (a.0 - b.0).abs() <= 0.5 && (a.1 - b.1).abs() <= 0.05
}

impl InventoryProfile {
    /// The distinct (material, OD, wall) of the inventory, in a fixed order.
    pub fn sizes(&self) -> Vec<(Material, f64, f64)> {
        let mut v: Vec<(Material, f64, f64)> = Vec::new();
        for p in &self.pipes {
            if !v
                .iter()
                .any(|s| s.0 == p.material && same_size((s.1, s.2), (p.od_mm, p.wall_mm)))
            {
                v.push((p.material, p.od_mm, p.wall_mm));
            }
        }
        v.sort_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.total_cmp(&b.2))
        });
        v
    }

    /// How likely the inventory makes a record for a segment installed in `year`, up to a
    /// constant: the material's share of the inventory (add-½ smoothed over the 7 materials),
    /// times 1 when the inventory holds this very size, ½ when it holds the diameter in another
    /// wall, ¼ otherwise, times the share of that material's dated pipes laid within
    /// [`ERA_YEARS`] of `year` (add-½ smoothed; 1 without dates).
    pub fn prior(&self, c: &RecordCandidate, year: Option<i64>) -> f64 {
        let n = self.pipes.len() as f64;
        let of: Vec<&InventoryPipe> = self
            .pipes
            .iter()
            .filter(|p| p.material == c.material)
            .collect();
        let share = (of.len() as f64 + 0.5) / (n + 0.5 * Material::ALL.len() as f64);
        let size = if of
            .iter()
            .any(|p| same_size((p.od_mm, p.wall_mm), (c.outside_diameter_mm, c.wall_mm)))
        {
            1.0
        } else if of
            .iter()
            .any(|p| (p.od_mm - c.outside_diameter_mm).abs() <= 0.5)
        {
            0.5
        } else {
            0.25
        };
        let era = match year {
            Some(y) => {
                let dated: Vec<i64> = of.iter().filter_map(|p| p.install_year).collect();
                if dated.is_empty() {
                    1.0
                } else {
                    let near = dated
                        .iter()
                        .filter(|d| (**d - y).abs() <= ERA_YEARS)
                        .count();
                    (near as f64 + 0.5) / (dated.len() as f64 + 1.0)
                }
            }
            None => 1.0,
        };
        share * size * era
    }
}

/// The candidate records of model §8 E8 for a segment, each a valid pipe (a candidate the
/// thin-shell model cannot take is left out), without repeats, from the catalogue
/// ([`super::catalogue::CATALOGUE`]) and the inventory's own sizes:
/// * every wall of the recorded material at the recorded diameter (a wrong wall class / SDR);
/// * every size of the recorded material whose OD is above the recorded number by at most
///   [`DN_TO_OD_FACTOR`], at every wall (the nominal size DN recorded as the OD);
/// * for a recorded number of at most [`MAX_DIAMETER_INCHES`]: OD and wall × 25.4 (recorded in
///   inches), and every size of the recorded material whose OD or DN is within [`INCH_MATCH`]
///   of that many inches, at every wall (a nominal size in inches); OD and wall ÷ 25.4;
/// * every size of every other material within [`NEAR_DIAMETER_FACTOR`] of the recorded OD.
pub fn candidates(data: &SegmentData, profile: Option<&InventoryProfile>) -> Vec<RecordCandidate> {
    use super::catalogue::CATALOGUE;
    let (od, wall) = recorded_size(data);
    let recorded = data.material;
    // (material, DN, OD, wall): the catalogue, then the inventory's sizes (DN unknown: the OD).
    let mut pool: Vec<(Material, f64, f64, f64)> = CATALOGUE
        .iter()
        .flat_map(|s| {
            s.sizes
                .iter()
                .map(move |z| (s.material, z.dn, z.od_mm, z.wall_mm))
        })
        .collect();
    if let Some(p) = profile {
        for (m, o, w) in p.sizes() {
            if !pool
                .iter()
                .any(|x| x.0 == m && same_size((x.2, x.3), (o, w)))
            {
                pool.push((m, o, o, w));
            }
        }
    }
    let mut out: Vec<RecordCandidate> = Vec::new();
    let mut push = |change: RecordChange, material: Material, o: f64, w: f64| {
        let is_recorded = Some(material) == recorded && same_size((o, w), (od, wall));
        if !is_recorded
            && !out.iter().any(|c| {
                c.material == material && same_size((c.outside_diameter_mm, c.wall_mm), (o, w))
            })
        {
            out.push(RecordCandidate {
                change,
                material,
                outside_diameter_mm: o,
                wall_mm: w,
            });
        }
    };
    if let Some(m) = recorded {
        let own = pool.iter().filter(|x| x.0 == m);
        for x in own.clone().filter(|x| (x.2 - od).abs() <= 1.0) {
            push(RecordChange::WallClass, m, od, x.3);
        }
        for x in own
            .clone()
            .filter(|x| x.2 > od + 0.5 && x.2 <= od * DN_TO_OD_FACTOR)
        {
            push(RecordChange::NominalAsOutside, m, x.2, x.3);
        }
        if od <= MAX_DIAMETER_INCHES {
            let target = od * MM_PER_INCH;
            push(RecordChange::Inches, m, target, wall * MM_PER_INCH);
            let near = |v: f64| (v / target - 1.0).abs() <= INCH_MATCH;
            for x in own.filter(|x| near(x.1) || near(x.2)) {
                push(RecordChange::Inches, m, x.2, x.3);
            }
        }
        push(
            RecordChange::InverseInches,
            m,
            od / MM_PER_INCH,
            wall / MM_PER_INCH,
        );
    }
    for x in pool.iter().filter(|x| Some(x.0) != recorded) {
        let ratio = x.2 / od;
        if (1.0 / NEAR_DIAMETER_FACTOR..=NEAR_DIAMETER_FACTOR).contains(&ratio) {
            push(RecordChange::Material, x.0, x.2, x.3);
        }
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
    /// exceeds its χ² by less than [`record_set_threshold`]. Records of about the same hoop stiffness
    /// E_p·h/a (and mass per length) are the usual reason: the wave sees little else.
    pub alternatives: Vec<RecordCandidate>,
    /// The full fits of those alternatives, in the same order.
    pub alternative_fits: Vec<(SegmentData, FitResult)>,
}

/// The χ² gap that screening allows before a record is refitted in full (times
/// [`SCREEN_MARGIN`]): the χ²₁ quantile at the level [`super::ALPHA`] at which a record is
/// accepted against the recorded one.
pub fn record_tie() -> f64 {
    super::stats::chi2_isf(super::ALPHA, 1.0)
}

/// Level of the record set: the records whose χ² is within the χ²₁ quantile at this level of
/// the best (3.84) form a 95 % likelihood-ratio confidence set for the record (its coverage is
/// measured by `examples/record_trials.rs`).
pub const RECORD_SET_LEVEL: f64 = 0.05;

/// The χ² gap within which records explain the data equally ([`RECORD_SET_LEVEL`]).
pub fn record_set_threshold() -> f64 {
    super::stats::chi2_isf(RECORD_SET_LEVEL, 1.0)
}

/// Fit every candidate record of `data` with `settings` (screened by a short fit, the
/// promising ones refitted in full) and return the best, or `None` when no candidate could be
/// fitted. Deterministic for a given seed, whatever the thread count.
pub fn fit_best_record(data: &SegmentData, settings: &FitSettings, seed: u64) -> Option<RecordFit> {
    fit_best_record_among(data, None, settings, seed, |_| true)
}

/// [`fit_best_record`] over the candidates (with the inventory's own sizes from `profile`)
/// that `keep` accepts.
pub fn fit_best_record_among(
    data: &SegmentData,
    profile: Option<&InventoryProfile>,
    settings: &FitSettings,
    seed: u64,
    keep: impl Fn(&RecordCandidate) -> bool,
) -> Option<RecordFit> {
    let mut cands = candidates(data, profile);
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
    let limit = screened.first()?.1 + SCREEN_MARGIN * record_tie();
    let mut seen = Vec::new();
    let screened: Vec<(usize, f64)> = screened
        .iter()
        .enumerate()
        .filter(|(rank, (i, chi2))| {
            let first_of_material = !seen.contains(&cands[*i].material);
            if first_of_material {
                seen.push(cands[*i].material);
            }
            (*rank < MAX_FULL_FITS && *chi2 <= limit) || first_of_material
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
                alternative_fits: Vec::new(),
            })
        })
        .collect();
    let best = fits
        .iter()
        .min_by(|a, b| a.fit.misfit.total_cmp(&b.fit.misfit))?;
    let tie = record_set_threshold();
    let others: Vec<&RecordFit> = fits
        .iter()
        .filter(|f| f.candidate != best.candidate && f.fit.misfit < best.fit.misfit + tie)
        .collect();
    Some(RecordFit {
        alternatives: others.iter().map(|f| f.candidate).collect(),
        alternative_fits: others
            .iter()
            .map(|f| (f.data.clone(), f.fit.clone()))
            .collect(),
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
        inventory: None,
        install_year: None,
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
        // PVC 110 SDR 21 (wall 5.3): the other EN 1452 walls at 110, MDPE 180 SDR 11 among the
        // materials (a factor 1.64); 110 is not a number of inches (left out), ÷25.4 is 4.3 mm
        // (left out: a < 5 mm).
        let c = candidates(&data(Material::Pvc, 110.0, 5.3), None);
        let walls: Vec<f64> = c
            .iter()
            .filter(|c| c.change == RecordChange::WallClass)
            .map(|c| c.wall_mm)
            .collect();
        assert_eq!(walls, vec![6.6, 4.2, 3.4, 2.7]);
        assert!(c.iter().any(|c| c.material == Material::Mdpe
            && c.outside_diameter_mm == 180.0
            && c.label() == "material=MDPE; OD 180 mm; wall 16.4 mm"));
        assert!(!c.iter().any(|c| c.change == RecordChange::Inches));
        // A PVC 160 recorded as its DN 150: OD 160 at every EN 1452 wall.
        let c = candidates(&data(Material::Pvc, 150.0, 7.7), None);
        let at160: Vec<f64> = c
            .iter()
            .filter(|c| c.material == Material::Pvc && c.outside_diameter_mm == 160.0)
            .map(|c| c.wall_mm)
            .collect();
        assert_eq!(at160, vec![9.5, 7.7, 6.2, 4.9, 4.0]);
        // DN 150 recorded as OD 150 for ductile iron: OD 170 at K7, K9 and K10.
        let c = candidates(&data(Material::DuctileIron, 150.0, 6.0), None);
        let at170 = c
            .iter()
            .filter(|c| {
                c.change == RecordChange::NominalAsOutside && c.outside_diameter_mm == 170.0
            })
            .count();
        assert_eq!(at170, 3, "K7, K9 and K10");
        // A 12-inch steel pipe (OD 12.75 in, wall 0.28 in) recorded in inches: 323.85 mm, and
        // the catalogue's OD 323.9 at its other walls; a nominal 12 recorded for a PVC pipe
        // (304.8 mm): every EN 1452 wall of OD 280 and 315.
        let c = candidates(&data(Material::Steel, 12.75, 0.28), None);
        assert!(c.iter().any(|c| c.change == RecordChange::Inches
            && (c.outside_diameter_mm - 323.85).abs() < 1e-9
            && c.label() == "material=ST; OD 323.9 mm; wall 7.1 mm"));
        for w in [5.6, 8.8] {
            assert!(c
                .iter()
                .any(|c| c.change == RecordChange::Inches && c.wall_mm == w));
        }
        let c = candidates(&data(Material::Pvc, 12.0, 0.6), None);
        for (od, n) in [(280.0, 5), (315.0, 5), (355.0, 0)] {
            let k = c
                .iter()
                .filter(|c| c.change == RecordChange::Inches && c.outside_diameter_mm == od)
                .count();
            assert_eq!(k, n, "OD {od}");
        }
    }

    #[test]
    fn inventory_sizes_join_the_candidates_and_rank_the_set() {
        let pipe = |material, od_mm, wall_mm, install_year| InventoryPipe {
            material,
            od_mm,
            wall_mm,
            install_year,
        };
        // A utility whose grey iron is of BS 78 sizes (OD 175, not in ISO 13) laid before 1960,
        // and whose PVC is from the 1980s.
        let profile = InventoryProfile {
            pipes: vec![
                pipe(Material::CastIron, 175.0, 10.0, Some(1935)),
                pipe(Material::CastIron, 175.0, 10.0, Some(1950)),
                pipe(Material::CastIron, 229.0, 11.0, Some(1940)),
                pipe(Material::Pvc, 160.0, 7.7, Some(1985)),
                pipe(Material::Pvc, 160.0, 7.7, Some(1990)),
            ],
        };
        let c = candidates(&data(Material::DuctileIron, 170.0, 6.0), Some(&profile));
        assert!(c.iter().any(|c| c.material == Material::CastIron
            && c.outside_diameter_mm == 175.0
            && c.wall_mm == 10.0));
        assert!(candidates(&data(Material::DuctileIron, 170.0, 6.0), None)
            .iter()
            .all(|c| c.outside_diameter_mm != 175.0));
        let rec = |material, od, wall| RecordCandidate {
            change: RecordChange::Material,
            material,
            outside_diameter_mm: od,
            wall_mm: wall,
        };
        // Same data fit: the utility's own size and era rank first.
        let ci = profile.prior(&rec(Material::CastIron, 175.0, 10.0), Some(1945));
        let ci_b = profile.prior(&rec(Material::CastIron, 170.0, 11.0), Some(1945));
        let pvc = profile.prior(&rec(Material::Pvc, 160.0, 7.7), Some(1945));
        let pvc_now = profile.prior(&rec(Material::Pvc, 160.0, 7.7), Some(1988));
        let hdpe = profile.prior(&rec(Material::Hdpe, 160.0, 9.5), Some(1988));
        assert!(ci > ci_b && ci_b > 0.0, "{ci} {ci_b}");
        assert!(pvc_now > pvc, "{pvc_now} {pvc}");
        assert!(pvc_now > hdpe, "{pvc_now} {hdpe}");
        // Hand value: CI share (3 + 0.5)/(5 + 3.5), own size, 3 of 3 dated within 15 years
        // of 1945: (3 + 0.5)/(3 + 1).
        assert!((ci - 3.5 / 8.5 * 1.0 * 3.5 / 4.0).abs() < 1e-12, "{ci}");
    }
}
