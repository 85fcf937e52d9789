//! The lab's own pipe catalogue and soil classes, chosen from handbook values and the ranges of
//! docs/model.md §3.1 and §3.3, independently of `pipewave synth`.
//!
//! Every property drawn here is written to `segments.csv` (the pipe's modulus, Poisson's ratio,
//! density and loss factor as overrides), so pipewave is told exactly the pipe the generator
//! solved: the only unknowns left to a fit are the soil, the contact and the change.

use pipewave::physics::Material;
use rand::Rng;

use crate::draw::{log_uniform, uniform};

/// One catalogue entry: outside diameter and wall thickness, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Size {
    /// Outside diameter D_o, mm.
    pub od_mm: f64,
    /// Wall thickness h, mm.
    pub wall_mm: f64,
}

/// Share of each material in a drawn network (sums to 1).
pub const MATERIAL_SHARES: [(Material, f64); 7] = [
    (Material::Pvc, 0.20),
    (Material::Mdpe, 0.12),
    (Material::Hdpe, 0.12),
    (Material::DuctileIron, 0.20),
    (Material::CastIron, 0.16),
    (Material::Steel, 0.08),
    (Material::AsbestosCement, 0.12),
];

/// Sizes of each material. Plastics by outside diameter and SDR (h = D_o / SDR): PVC-U SDR 17,
/// 21, 26; PE80 (MDPE) SDR 11, 17; PE100 (HDPE) SDR 11, 17, 26. Ductile iron at the ISO 2531
/// outside diameters with K9 and K7 walls (e = K(0.5 + 0.001 DN) mm, at least 6 and 5 mm),
/// grey cast iron at imperial sizes with pit-cast walls, steel at ASME B36.10 outside
/// diameters with standard and light walls, asbestos cement at class-20-like walls.
pub fn sizes(material: Material) -> Vec<Size> {
    let s = |od_mm: f64, wall_mm: f64| Size { od_mm, wall_mm };
    let sdr = |ods: &[f64], sdrs: &[f64]| -> Vec<Size> {
        let mut v = Vec::new();
        for &od in ods {
            for &r in sdrs {
                v.push(s(od, (od / r * 10.0).round() / 10.0));
            }
        }
        v
    };
    let ductile = |k: f64, min: f64| -> Vec<Size> {
        [
            (80.0, 98.0),
            (100.0, 118.0),
            (150.0, 170.0),
            (200.0, 222.0),
            (250.0, 274.0),
            (300.0, 326.0),
            (400.0, 429.0),
        ]
        .iter()
        .map(|&(dn, od)| s(od, (k * (0.5 + 0.001 * dn)).max(min)))
        .collect()
    };
    match material {
        Material::Pvc => sdr(
            &[90.0, 110.0, 160.0, 200.0, 250.0, 315.0],
            &[17.0, 21.0, 26.0],
        ),
        Material::Mdpe => sdr(&[63.0, 90.0, 125.0, 180.0], &[11.0, 17.0]),
        Material::Hdpe => sdr(&[110.0, 160.0, 250.0, 315.0, 400.0], &[11.0, 17.0, 26.0]),
        Material::DuctileIron => {
            let mut v = ductile(9.0, 6.0);
            v.extend(ductile(7.0, 5.0));
            v
        }
        Material::CastIron => vec![
            s(96.0, 9.0),
            s(121.9, 10.4),
            s(177.8, 11.7),
            s(232.2, 13.0),
            s(286.0, 14.2),
            s(345.4, 15.5),
        ],
        Material::Steel => vec![
            s(114.3, 6.0),
            s(168.3, 7.1),
            s(219.1, 6.3),
            s(273.0, 6.3),
            s(323.9, 7.1),
            s(406.4, 8.0),
            s(508.0, 9.5),
            s(610.0, 9.5),
        ],
        Material::AsbestosCement => vec![
            s(122.0, 11.0),
            s(177.0, 13.5),
            s(232.0, 16.0),
            s(286.0, 19.0),
            s(345.0, 22.0),
        ],
    }
}

/// Ranges the wall's properties are drawn from (uniform; the loss factor log-uniform):
/// `(E_p lo, E_p hi, ν_p lo, ν_p hi, ρ_p lo, ρ_p hi, η_p lo, η_p hi)`. Plastics at their
/// dynamic (leak-noise frequency) moduli, model §3.3 and §8 E7.
pub fn wall_ranges(material: Material) -> [f64; 8] {
    match material {
        Material::CastIron => [0.85e11, 1.30e11, 0.25, 0.27, 7000.0, 7300.0, 0.005, 0.03],
        Material::DuctileIron => [1.60e11, 1.76e11, 0.27, 0.29, 7050.0, 7150.0, 0.004, 0.02],
        Material::Steel => [2.00e11, 2.10e11, 0.29, 0.30, 7800.0, 7870.0, 0.0005, 0.005],
        Material::Pvc => [2.8e9, 3.5e9, 0.38, 0.42, 1380.0, 1450.0, 0.02, 0.07],
        Material::Mdpe => [1.6e9, 2.3e9, 0.40, 0.45, 930.0, 950.0, 0.04, 0.09],
        Material::Hdpe => [1.8e9, 2.5e9, 0.42, 0.46, 945.0, 965.0, 0.04, 0.09],
        Material::AsbestosCement => [2.1e10, 2.9e10, 0.18, 0.22, 1800.0, 2000.0, 0.005, 0.03],
    }
}

/// A soil class of the lab: name, E_m range (log-uniform), ν_m range and ρ_m range (uniform).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoilClass {
    /// Name written to `segments.csv` `soil_type`.
    pub name: &'static str,
    /// E_m range, Pa.
    pub youngs: (f64, f64),
    /// ν_m range.
    pub poisson: (f64, f64),
    /// ρ_m range, kg/m³.
    pub density: (f64, f64),
}

/// The soil classes and their shares: loose-to-dense sand, soft-to-stiff clay, loam.
pub const SOIL_CLASSES: [(SoilClass, f64); 3] = [
    (
        SoilClass {
            name: "sand",
            youngs: (1.5e7, 1.5e8),
            poisson: (0.22, 0.38),
            density: (1600.0, 2100.0),
        },
        0.4,
    ),
    (
        SoilClass {
            name: "clay",
            youngs: (5e6, 6e7),
            poisson: (0.35, 0.49),
            density: (1500.0, 2000.0),
        },
        0.3,
    ),
    (
        SoilClass {
            name: "loam",
            youngs: (1e7, 1e8),
            poisson: (0.28, 0.42),
            density: (1700.0, 2200.0),
        },
        0.3,
    ),
];

/// Pick one of `items` by its share.
pub fn pick<T: Copy, R: Rng>(rng: &mut R, items: &[(T, f64)]) -> T {
    let total: f64 = items.iter().map(|i| i.1).sum();
    let mut u = rng.gen::<f64>() * total;
    for &(item, w) in items {
        if u < w {
            return item;
        }
        u -= w;
    }
    items[items.len() - 1].0
}

/// Drawn wall properties of one pipe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// E_p, Pa.
    pub youngs: f64,
    /// ν_p.
    pub poisson: f64,
    /// ρ_p, kg/m³.
    pub density: f64,
    /// η_p.
    pub loss: f64,
}

/// Draw the wall's properties of `material` (ranges of [`wall_ranges`]).
pub fn draw_wall<R: Rng>(rng: &mut R, material: Material) -> Wall {
    let r = wall_ranges(material);
    Wall {
        youngs: uniform(rng, r[0], r[1]),
        poisson: uniform(rng, r[2], r[3]),
        density: uniform(rng, r[4], r[5]),
        loss: log_uniform(rng, r[6], r[7]),
    }
}

/// Contact coefficient ξ (model §4.10): a third near bonded (0.8–1), a third near slip
/// (0–0.2), a third uniform on 0–1.
pub fn draw_contact<R: Rng>(rng: &mut R) -> f64 {
    match rng.gen_range(0..3) {
        0 => uniform(rng, 0.8, 1.0),
        1 => uniform(rng, 0.0, 0.2),
        _ => uniform(rng, 0.0, 1.0),
    }
}
