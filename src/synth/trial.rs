//! Synthetic trials of the diagnosis (acceptance trials): one segment with a hidden effect or
//! a wrong inventory record, measured with the synthetic network's noise (1 % on Re k, 5 % on
//! the attenuation). The diagnosis is given only the record and the measurements.

use rand::Rng;

use crate::invert::problem::SegmentData;
use crate::physics::effects::Effect;
use crate::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};
use crate::synth::{band_hz, measure, segment_data, sizes, PipeSize, SOILS};

use crate::diagnose::inventory::MM_PER_INCH;

/// A kind of inventory error (model §8 E8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordError {
    /// The pipe is of another material (the record: the recorded material's size nearest in
    /// outside diameter).
    WrongMaterial,
    /// The pipe has a neighbouring wall class / SDR of the recorded material.
    WallClass,
    /// The record's diameter and wall are the true ones in inches.
    Inches,
}

/// One trial: what the diagnosis is given, and the truth.
#[derive(Debug, Clone)]
pub struct Trial {
    /// The record and the measurements.
    pub data: SegmentData,
    /// The true pipe: material, outside diameter and wall (mm).
    pub true_pipe: (Material, f64, f64),
    /// The hidden effect and its value, if any.
    pub hidden: Option<(Effect, f64)>,
    /// The system that made the measurements (the truth, effect applied).
    pub true_system: System,
}

/// Measure a pipe of `material` (outside diameter and wall in mm) in a random soil of the
/// synthetic network's classes, with `hidden` applied, at 4–8 frequencies of the material's
/// band; the record given to the fit is `record` (material, OD, wall in mm). `None` where the
/// forward model fails.
pub fn trial<R: Rng + ?Sized>(
    rng: &mut R,
    material: Material,
    true_size: (f64, f64),
    hidden: Option<(Effect, f64)>,
    record: (Material, f64, f64),
) -> Option<Trial> {
    let pipe =
        Pipe::from_outside_diameter(material.typical(), true_size.0 * 1e-3, true_size.1 * 1e-3)
            .ok()?;
    let (_, e_r, nu_r, rho_r) = SOILS[rng.gen_range(0..SOILS.len())];
    let e = (e_r.0.ln() + rng.gen::<f64>() * (e_r.1.ln() - e_r.0.ln())).exp();
    let nu = rng.gen_range(nu_r.0..nu_r.1);
    let rho = rng.gen_range(rho_r.0..rho_r.1).round();
    let soil = Soil::new(e, nu, rho, 0.0).ok()?;
    let mut sys = System::new(
        Fluid::water(),
        pipe,
        soil,
        rng.gen::<f64>(),
        Model::Full,
        ContactMode::Reciprocal,
    )
    .ok()?;
    if let Some((eff, v)) = hidden {
        sys = eff.apply(&sys, v).ok()?;
    }
    let mut band = band_hz(material);
    band.1 = band.1.min(0.45 * pipe.ring_frequency_hz());
    let m = rng.gen_range(4..=8);
    let freqs: Vec<f64> = (0..m)
        .map(|i| {
            let lo = band.0 + (band.1 - band.0) * i as f64 / m as f64;
            let hi = band.0 + (band.1 - band.0) * (i + 1) as f64 / m as f64;
            (lo + rng.gen::<f64>() * (hi - lo)).round()
        })
        .collect();
    let meas = measure(&sys, &freqs, rng)?;
    let rec_pipe =
        Pipe::from_outside_diameter(record.0.typical(), record.1 * 1e-3, record.2 * 1e-3).ok()?;
    Some(Trial {
        data: segment_data(record.0, rec_pipe, rho, &meas),
        true_pipe: (material, true_size.0, true_size.1),
        hidden,
        true_system: sys,
    })
}

fn nearest(material: Material, od: f64) -> PipeSize {
    *sizes(material)
        .iter()
        .min_by(|a, b| (a.od_mm - od).abs().total_cmp(&(b.od_mm - od).abs()))
        .expect("every material has sizes")
}

/// A trial with an inventory error of `kind` (no hidden effect).
pub fn record_error_trial<R: Rng + ?Sized>(rng: &mut R, kind: RecordError) -> Option<Trial> {
    match kind {
        RecordError::WrongMaterial => {
            let m = Material::ALL[rng.gen_range(0..Material::ALL.len())];
            let s = sizes(m)[rng.gen_range(0..sizes(m).len())];
            let others: Vec<Material> = Material::ALL.into_iter().filter(|x| *x != m).collect();
            let rm = others[rng.gen_range(0..others.len())];
            let r = nearest(rm, s.od_mm);
            trial(rng, m, (s.od_mm, s.wall_mm), None, (rm, r.od_mm, r.wall_mm))
        }
        RecordError::WallClass => {
            // Another wall class of the catalogue at the same OD: an SDR of ISO 4427 / EN 1452
            // for plastics (three trials in four), a K class of ISO 2531 for ductile iron.
            let plastics = [Material::Pvc, Material::Mdpe, Material::Hdpe];
            let m = if rng.gen_bool(0.75) {
                plastics[rng.gen_range(0..3)]
            } else {
                Material::DuctileIron
            };
            let s = sizes(m)[rng.gen_range(0..sizes(m).len())];
            let walls: Vec<f64> = crate::diagnose::catalogue::sizes_of(m)
                .filter(|(_, z)| {
                    (z.od_mm - s.od_mm).abs() < 0.5 && (z.wall_mm - s.wall_mm).abs() > 0.05
                })
                .map(|(_, z)| z.wall_mm)
                .collect();
            if walls.is_empty() {
                return None;
            }
            let wall = walls[rng.gen_range(0..walls.len())];
            trial(rng, m, (s.od_mm, wall), None, (m, s.od_mm, s.wall_mm))
        }
        RecordError::Inches => {
            // Sizes large enough that the number of inches is still a valid pipe in mm.
            let big: Vec<(Material, PipeSize)> = Material::ALL
                .into_iter()
                .flat_map(|m| sizes(m).iter().map(move |s| (m, *s)))
                .filter(|(_, s)| s.od_mm >= 260.0)
                .collect();
            let (m, s) = big[rng.gen_range(0..big.len())];
            trial(
                rng,
                m,
                (s.od_mm, s.wall_mm),
                None,
                (m, s.od_mm / MM_PER_INCH, s.wall_mm / MM_PER_INCH),
            )
        }
    }
}

/// A trial of the catalogue's pipe of `material` with `hidden` (no record error).
pub fn effect_trial<R: Rng + ?Sized>(
    rng: &mut R,
    material: Material,
    hidden: Option<(Effect, f64)>,
) -> Option<Trial> {
    let s = sizes(material)[rng.gen_range(0..sizes(material).len())];
    trial(
        rng,
        material,
        (s.od_mm, s.wall_mm),
        hidden,
        (material, s.od_mm, s.wall_mm),
    )
}
