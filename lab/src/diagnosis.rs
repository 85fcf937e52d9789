//! The independent generator of diagnosis trials (`pipewave-lab diagnosis`).
//!
//! Four sets, each a network directory that `pipewave import` / `pipewave run` read as they are:
//!
//! * `main`: one hidden effect of docs/model.md §8 per segment at a clearly detectable size —
//!   `soil_damping` (E1, η_m in P13), `air_in_water` (E3, P60–P61), `wall_thinning` (E4, P62;
//!   metal and AC walls only), `pipe_loss` (E2, η_p in P9), `viscoelastic_wall` (E7, P70–P71;
//!   polymer walls only) — and controls without any (`none`), in equal numbers;
//! * `floor`: the same effects and controls, each effect at its segment's detection floor: the
//!   size at which the segment's own one-parameter test has 50 % power (below, [`Z_FLOOR`]);
//! * `records`: inventory errors (E8): the recorded row of `segments.csv` describes another pipe
//!   (another material, another wall class, the DN written as the outside diameter) while the
//!   wavenumbers are those of the true pipe; and controls whose record is right;
//! * `groups`: cast-iron networks grouped by `soil_zone`; in half the zones a fraction 20–40 %
//!   of the members carries one effect (`wall_thinning` or `air_in_water`, alternately) each at
//!   its own floor, the other zones are clean.
//!
//! Every segment is one campaign (`DX-2025`) measured at a frequency plan and with a noise law
//! of its own, drawn as the campaigns generator draws them ([`crate::campaigns`]: 5–12
//! frequencies in a band of the segment's own, σ varying over the band). The noiseless
//! wavenumbers are roots of pipewave's dispersion relation (P31–P32, `full` P33, `reciprocal`
//! P34) by the reference continuation (P41–P43), the effects applied by
//! `pipewave::physics::effects`.
//!
//! **Detectability.** A hidden effect is judged by the test a diagnosis can make: the base fit
//! (E_m, ν_m, ξ of P51) is free to absorb what it can of the effect. The noncentrality of that
//! test is the χ² the base model's best soil near the true one leaves on the noiseless measured
//! curve, with r_i = (k_effect,i − k_base,i(θ))/σ_i (Re k and α at every measured frequency, σ
//! the stated ones):
//!
//! ```text
//! z² = min over θ near the true soil of |r(θ)|²,   θ = (ln E_m, ν_m, ξ)
//! ```
//!
//! found by Gauss–Newton from the true soil ([`profiled_z`]), a parameter on its bound of P51
//! (ξ at 0 or 1, ν_m at 0.499) held there when a step would move it out. `z_raw` = |r| at the
//! true soil, with no refit (P93's form for one campaign against its model).
//!
//! **The floor.** The diagnosis tests each candidate effect as one parameter on the bound of
//! its range, whose null law is χ̄² = ½χ²₀ + ½χ²₁; at a level of 10⁻³ over 4 candidates the
//! test rejects when the signed root of its statistic exceeds
//! Φ⁻¹(1 − 2.5·10⁻⁴) = 3.4808, so a segment with z = 3.4808 is detected half the time. The floor
//! size is found by bisection on z(size) = [`Z_FLOOR`]; a main size is drawn from its range
//! below and kept when z ≥ [`Z_MAIN_MIN`] (power ≥ 0.99 at that level).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use num_complex::Complex64;
use pipewave::invert::assemble::leak_band_speed_of;
use pipewave::physics::effects::{exponent_of_loss_factor, Effect};
use pipewave::physics::inputs::MAX_SOIL_POISSON;
use pipewave::physics::{Material, Pipe, Soil, System};
use rand::seq::SliceRandom;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::campaigns::{
    buried_pipe, draw_plan, is_plastic, measure, noiseless, NoiseLaw, Plan, Row,
};
use crate::catalogue::{
    draw_contact, draw_wall, pick, sizes, Size, SoilClass, Wall, MATERIAL_SHARES, SOIL_CLASSES,
};
use crate::draw::{log_uniform, network_rng, segment_rng, std_normal, uniform, zone_rng};

/// The campaign every segment is measured in.
pub const CAMPAIGN: &str = "DX-2025";
/// Detectability of a floor-size effect: Φ⁻¹(1 − 2.5·10⁻⁴), the one-segment χ̄² test at
/// 10⁻³ over 4 candidates has 50 % power there.
pub const Z_FLOOR: f64 = 3.4808;
/// Smallest detectability of a main-size effect.
pub const Z_MAIN_MIN: f64 = 6.0;
/// Draws of one segment before the generator gives up.
pub const MAX_ATTEMPTS: usize = 2000;
/// Largest relative distance of a floor trial's z from [`Z_FLOOR`].
pub const FLOOR_TOLERANCE: f64 = 0.01;
/// Bisection steps of the floor size.
const FLOOR_STEPS: usize = 30;

/// A set of trials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Set {
    /// Hidden effects at main sizes and controls.
    Main,
    /// Hidden effects at the detection floor and controls.
    Floor,
    /// Inventory errors and controls.
    Records,
    /// Zones of cast-iron pipes, some with an effect in 20–40 % of their members.
    Groups,
}

impl Set {
    /// The name written to truth.csv's `set`.
    pub fn name(self) -> &'static str {
        match self {
            Set::Main => "main",
            Set::Floor => "floor",
            Set::Records => "records",
            Set::Groups => "groups",
        }
    }

    /// The prefix of the segment ids.
    fn prefix(self) -> &'static str {
        match self {
            Set::Main => "DM",
            Set::Floor => "DF",
            Set::Records => "DR",
            Set::Groups => "DG",
        }
    }

    /// Default number of segments: 20 trials of each of the six kinds (main, floor), 12 of each
    /// of the four (records), 8 zones of 40 (groups).
    pub fn default_segments(self) -> usize {
        match self {
            Set::Main | Set::Floor => 120,
            Set::Records => 48,
            Set::Groups => 320,
        }
    }
}

/// The hidden effects of the main and floor sets, and the controls (`None`), in the order the
/// trials are dealt.
pub const HIDDEN: [Option<Effect>; 6] = [
    None,
    Some(Effect::SoilDamping),
    Some(Effect::AirInWater),
    Some(Effect::WallThinning),
    Some(Effect::PipeLoss),
    Some(Effect::ViscoelasticWall),
];

/// The effects of the affected zones of the groups set, alternately.
pub const GROUP_EFFECTS: [Effect; 2] = [Effect::WallThinning, Effect::AirInWater];

/// An inventory error (model §8 E8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordError {
    /// The record names another material (an unrecorded relining or replacement).
    WrongMaterial,
    /// The record names another wall class or SDR of the same material and diameter.
    WrongWallClass,
    /// The record gives the nominal diameter DN as the outside diameter.
    DnAsOd,
}

impl RecordError {
    /// Every record error, in the order the trials are dealt (after the controls).
    pub const ALL: [RecordError; 3] = [
        RecordError::WrongMaterial,
        RecordError::WrongWallClass,
        RecordError::DnAsOd,
    ];

    /// truth.csv's `kind`.
    pub fn name(self) -> &'static str {
        match self {
            RecordError::WrongMaterial => "wrong_material",
            RecordError::WrongWallClass => "wrong_wall_class",
            RecordError::DnAsOd => "dn_as_od",
        }
    }

    /// The true materials the error is drawn on: a wall class only where the catalogue has
    /// several walls at one diameter (the plastics' SDRs, ductile iron's K7 and K9); a DN only
    /// where the outside diameter is not the nominal size (iron, steel, AC).
    fn applies_to(self, m: Material) -> bool {
        match self {
            RecordError::WrongMaterial => true,
            RecordError::WrongWallClass => is_plastic(m) || m == Material::DuctileIron,
            RecordError::DnAsOd => !is_plastic(m),
        }
    }
}

/// What a segment of a set hides.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trial {
    /// A hidden physical effect, or none.
    Effect(Option<Effect>),
    /// An inventory error, or none.
    Record(Option<RecordError>),
}

impl Trial {
    /// truth.csv's `effect`: the canonical name pipewave should name (docs/interface.md).
    pub fn effect_name(self) -> &'static str {
        match self {
            Trial::Effect(Some(e)) => e.name(),
            Trial::Record(Some(_)) => "inventory_error",
            _ => "none",
        }
    }

    /// truth.csv's `kind`: the effect, or which record error.
    pub fn kind_name(self) -> &'static str {
        match self {
            Trial::Effect(Some(e)) => e.name(),
            Trial::Record(Some(r)) => r.name(),
            _ => "none",
        }
    }

    /// Whether `material` can carry this trial.
    fn applies_to(self, m: Material) -> bool {
        match self {
            Trial::Effect(Some(e)) => e.applies_to(m),
            Trial::Record(Some(r)) => r.applies_to(m),
            _ => true,
        }
    }
}

/// Options of one generated set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Which set.
    pub set: Set,
    /// Number of segments.
    pub segments: usize,
    /// Seed of the ChaCha8 streams.
    pub seed: u64,
    /// Members per zone (groups set).
    pub group_size: usize,
    /// Fraction of the zones that carry an effect (groups set; round(F·zones) of them).
    pub affected_fraction: f64,
}

impl Options {
    /// The options of a set at its defaults.
    pub fn new(set: Set, seed: u64) -> Self {
        Options {
            set,
            segments: set.default_segments(),
            seed,
            group_size: 40,
            affected_fraction: 0.5,
        }
    }
}

/// A pipe record: material, outside diameter and wall, as `segments.csv` holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// Material.
    pub material: Material,
    /// Outside diameter and wall, mm.
    pub size: Size,
}

impl std::fmt::Display for Record {
    /// pipewave's record syntax (docs/record-errors.md): `material=DI; OD 170 mm; wall 6 mm`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "material={}; OD {} mm; wall {} mm",
            self.material.code(),
            self.size.od_mm,
            self.size.wall_mm
        )
    }
}

/// The zone plan of the groups set.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    /// Name written to `soil_zone` (`Z01`, …).
    pub name: String,
    /// The zone's effect, None when clean.
    pub effect: Option<Effect>,
    /// The zone's soil class.
    pub class: SoilClass,
    /// Centre of the members' E_m (Pa), ν_m and ρ_m (kg/m³).
    pub soil: (f64, f64, f64),
    /// Indices of the members (into the segment list).
    pub members: Vec<usize>,
    /// Indices of the members carrying the effect.
    pub carriers: Vec<usize>,
}

/// One generated segment and its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Segment id.
    pub id: String,
    /// What it hides.
    pub trial: Trial,
    /// The true pipe.
    pub truth: Record,
    /// The pipe as `segments.csv` records it (equal to `truth` unless a record error).
    pub recorded: Record,
    /// The true wall's properties.
    pub wall: Wall,
    /// Whether the wall's properties are written as overrides (not in the records set, where
    /// the record itself is in question: there every wall has its material's typical values of
    /// model §3.3, so the true record with pipewave's typical values is the true pipe).
    pub overrides: bool,
    /// Soil class name.
    pub soil_type: &'static str,
    /// `soil_zone` (groups set).
    pub soil_zone: Option<String>,
    /// The zone's effect (groups set; None for a clean zone and outside the groups set).
    pub group_effect: Option<Effect>,
    /// Length, m.
    pub length_m: f64,
    /// Install year.
    pub install_year: u32,
    /// The true system without the effect.
    pub base: System,
    /// The system measured (with the effect).
    pub measured: System,
    /// The effect's parameter (truth.csv `value`): η_m, φ, r_h, η_p after or n.
    pub value: Option<f64>,
    /// The parameter's neutral value for this pipe (0, 0, 1, η_p, atan(η_p)/(π/2)).
    pub neutral: Option<f64>,
    /// The plan.
    pub plan: Plan,
    /// The noise law.
    pub noise: NoiseLaw,
    /// The measured rows.
    pub rows: Vec<Row>,
    /// Detectability with the soil refitted (module docs).
    pub z: f64,
    /// Detectability without a refit, |r|.
    pub z_raw: f64,
    /// Leak-band speed of the base system, m/s.
    pub speed_base: f64,
    /// Leak-band speed of the measured system, m/s.
    pub speed_measured: f64,
    /// Draws rejected before this one.
    pub rejected: usize,
}

/// Pick a material by the catalogue's shares among those `ok` accepts.
fn pick_material<R: Rng>(rng: &mut R, ok: impl Fn(Material) -> bool) -> Material {
    let items: Vec<(Material, f64)> = MATERIAL_SHARES
        .iter()
        .copied()
        .filter(|&(m, _)| ok(m))
        .collect();
    pick(rng, &items)
}

/// The nominal size DN (mm) of a catalogue size whose outside diameter is not its DN: ISO 2531
/// ductile iron, the imperial grey-iron sizes (3–12 in), steel (4–24 in) and AC.
pub fn nominal_dn(material: Material, od_mm: f64) -> Option<f64> {
    let table: &[(f64, f64)] = match material {
        Material::DuctileIron => &[
            (98.0, 80.0),
            (118.0, 100.0),
            (170.0, 150.0),
            (222.0, 200.0),
            (274.0, 250.0),
            (326.0, 300.0),
            (429.0, 400.0),
        ],
        Material::CastIron => &[
            (96.0, 80.0),
            (121.9, 100.0),
            (177.8, 150.0),
            (232.2, 200.0),
            (286.0, 250.0),
            (345.4, 300.0),
        ],
        Material::Steel => &[
            (114.3, 100.0),
            (168.3, 150.0),
            (219.1, 200.0),
            (273.0, 250.0),
            (323.9, 300.0),
            (406.4, 400.0),
            (508.0, 500.0),
            (610.0, 600.0),
        ],
        Material::AsbestosCement => &[
            (122.0, 100.0),
            (177.0, 150.0),
            (232.0, 200.0),
            (286.0, 250.0),
            (345.0, 300.0),
        ],
        _ => &[],
    };
    table
        .iter()
        .find(|(od, _)| (od - od_mm).abs() < 1e-9)
        .map(|t| t.1)
}

/// Whether pipewave's import accepts a record's geometry (docs/interface.md): mean radius
/// 5–1500 mm, 0.005 ≤ h/a ≤ 0.25.
pub fn importable(size: Size) -> bool {
    let a = (size.od_mm - size.wall_mm) / 2.0;
    (5.0..=1500.0).contains(&a) && (0.005..=0.25).contains(&(size.wall_mm / a))
}

/// The recorded (wrong) record of a record error on the true record `t`, or None when this
/// pipe cannot have it (e.g. no other material within a factor 1.5 of its diameter).
fn draw_recorded<R: Rng>(rng: &mut R, err: RecordError, t: Record) -> Option<Record> {
    let rec = match err {
        RecordError::WrongMaterial => {
            // Another material by the catalogue's shares, at its size nearest the true OD.
            let m = pick_material(rng, |m| m != t.material);
            let size = sizes(m).into_iter().min_by(|a, b| {
                (a.od_mm - t.size.od_mm)
                    .abs()
                    .total_cmp(&(b.od_mm - t.size.od_mm).abs())
            })?;
            let ratio = size.od_mm / t.size.od_mm;
            if !(1.0 / 1.5..=1.5).contains(&ratio) {
                return None;
            }
            Record { material: m, size }
        }
        RecordError::WrongWallClass => {
            // Another wall of the same material at the same outside diameter.
            let others: Vec<Size> = sizes(t.material)
                .into_iter()
                .filter(|s| s.od_mm == t.size.od_mm && s.wall_mm != t.size.wall_mm)
                .collect();
            Record {
                material: t.material,
                size: *others.choose(rng)?,
            }
        }
        RecordError::DnAsOd => Record {
            material: t.material,
            size: Size {
                od_mm: nominal_dn(t.material, t.size.od_mm)?,
                wall_mm: t.size.wall_mm,
            },
        },
    };
    importable(rec.size).then_some(rec)
}

/// The base fit's parameters θ = (ln E_m, ν_m, ξ) of P51 applied to a system.
fn with_theta(sys: &System, theta: [f64; 3]) -> Option<System> {
    let soil = Soil::new(
        theta[0].exp(),
        theta[1],
        sys.soil.density,
        sys.soil.loss_factor,
    )
    .ok()?;
    (0.0..=1.0).contains(&theta[2]).then_some(System {
        soil,
        contact: theta[2],
        ..*sys
    })
}

/// The base model's wavenumbers at a plan and their derivatives with respect to θ, for the
/// Gauss–Newton steps of [`profiled_z`].
pub struct Profile {
    /// Frequencies, Hz.
    pub frequencies: Vec<f64>,
    /// Noiseless wavenumbers of the base system.
    pub k_base: Vec<Complex64>,
    /// ∂k/∂θ_j at every frequency, j = ln E_m, ν_m, ξ.
    pub jacobian: Vec<[Complex64; 3]>,
    /// Which θ_j sit on a bound of P51 (ν_m ≥ 0.499 − step, ξ within a step of 0 or 1) and in
    /// which direction they may move: −1 only down, +1 only up, 0 free.
    pub bound: [i8; 3],
}

/// Steps of the central differences in θ.
const THETA_STEPS: [f64; 3] = [0.01, 0.002, 0.002];

impl Profile {
    /// The profile of `base` at `frequencies`, None when a root is not clean.
    pub fn new(base: &System, frequencies: &[f64]) -> Option<Self> {
        let k_base = noiseless(base, frequencies)?;
        let theta = [
            base.soil.youngs_modulus.ln(),
            base.soil.poisson,
            base.contact,
        ];
        let lower = [f64::NEG_INFINITY, 0.0, 0.0];
        let upper = [f64::INFINITY, MAX_SOIL_POISSON, 1.0];
        let mut jacobian = vec![[Complex64::new(0.0, 0.0); 3]; frequencies.len()];
        let mut bound = [0i8; 3];
        for j in 0..3 {
            let h = THETA_STEPS[j];
            let up_ok = theta[j] + h <= upper[j];
            let down_ok = theta[j] - h >= lower[j];
            bound[j] = match (down_ok, up_ok) {
                (true, true) => 0,
                (true, false) => -1,
                (false, true) => 1,
                (false, false) => return None,
            };
            let shifted = |d: f64| {
                let mut t = theta;
                t[j] += d;
                with_theta(base, t).and_then(|s| noiseless(&s, frequencies))
            };
            let (kp, km, span) = match bound[j] {
                0 => (shifted(h)?, shifted(-h)?, 2.0 * h),
                1 => (shifted(h)?, k_base.clone(), h),
                _ => (k_base.clone(), shifted(-h)?, h),
            };
            for i in 0..frequencies.len() {
                jacobian[i][j] = (kp[i] - km[i]) / span;
            }
        }
        Some(Profile {
            frequencies: frequencies.to_vec(),
            k_base,
            jacobian,
            bound,
        })
    }

    /// The χ² of the noiseless wavenumbers `k` against this profile's base wavenumbers, σ of
    /// `law` at each frequency from `k` (as the files state them); with `linear`, the χ² left
    /// after the linearised soil step, and that step (ln E_m, ν_m, ξ).
    fn chi2(&self, k: &[Complex64], law: &NoiseLaw) -> (f64, f64, [f64; 3]) {
        let mut r = Vec::with_capacity(2 * k.len());
        let mut cols: [Vec<f64>; 3] = Default::default();
        for (i, (&f, &ki)) in self.frequencies.iter().zip(k).enumerate() {
            let (s_re, s_att) = law.sigma(f, ki);
            let kb = self.k_base[i];
            // Re k and α = −Im k (P2), each over its σ.
            r.push((ki.re - kb.re) / s_re);
            r.push((kb.im - ki.im) / s_att);
            for (j, col) in cols.iter_mut().enumerate() {
                let d = self.jacobian[i][j];
                col.push(d.re / s_re);
                col.push(-d.im / s_att);
            }
        }
        let chi2 = r.iter().map(|x| x * x).sum::<f64>();
        // Active set: solve with every free column; a bounded parameter asked to move out of
        // its range is held on its bound (its column dropped) and the rest solved again.
        let mut active = [true; 3];
        loop {
            let idx: Vec<usize> = (0..3).filter(|&j| active[j]).collect();
            let col_refs: Vec<&[f64]> = idx.iter().map(|&j| &cols[j][..]).collect();
            let delta = least_squares(&col_refs, &r);
            let out = idx.iter().zip(&delta).find(|(&j, &d)| {
                (self.bound[j] == 1 && d < 0.0) || (self.bound[j] == -1 && d > 0.0)
            });
            if let Some((&j, _)) = out {
                active[j] = false;
                continue;
            }
            let mut res = r.clone();
            let mut step = [0.0; 3];
            for (&j, &d) in idx.iter().zip(&delta) {
                step[j] = d;
                for (x, c) in res.iter_mut().zip(&cols[j]) {
                    *x -= c * d;
                }
            }
            return (chi2, res.iter().map(|x| x * x).sum::<f64>(), step);
        }
    }
}

/// Gauss–Newton steps of the profile.
const PROFILE_STEPS: usize = 8;

/// (z, z_raw) of noiseless data `k` at `frequencies` (σ of `law`) against the base model of
/// `model`: z_raw at `model`'s own soil, z at the best soil near it (Gauss–Newton from it on
/// θ = (ln E_m, ν_m, ξ), each step halved until χ² falls, within P51's bounds). None when a
/// root is not clean.
pub fn profiled_z(
    model: &System,
    frequencies: &[f64],
    k: &[Complex64],
    law: &NoiseLaw,
) -> Option<(f64, f64)> {
    let mut prof = Profile::new(model, frequencies)?;
    let mut sys = *model;
    let (chi2_0, _, _) = prof.chi2(k, law);
    let mut best = chi2_0;
    for _ in 0..PROFILE_STEPS {
        let (_, predicted, step) = prof.chi2(k, law);
        if best - predicted <= 1e-9 * best {
            break;
        }
        let theta = [sys.soil.youngs_modulus.ln(), sys.soil.poisson, sys.contact];
        let mut t = 1.0;
        let mut moved = false;
        for _ in 0..6 {
            let next = [
                (theta[0] + t * step[0]).clamp(1e3f64.ln(), 1e10f64.ln()),
                (theta[1] + t * step[1]).clamp(0.0, MAX_SOIL_POISSON),
                (theta[2] + t * step[2]).clamp(0.0, 1.0),
            ];
            if let Some(s2) = with_theta(&sys, next) {
                if let Some(p2) = Profile::new(&s2, frequencies) {
                    let c = p2.chi2(k, law).0;
                    if c < best {
                        best = c;
                        sys = s2;
                        prof = p2;
                        moved = true;
                        break;
                    }
                }
            }
            t *= 0.5;
        }
        if !moved {
            break;
        }
    }
    Some((best.sqrt(), chi2_0.sqrt()))
}

/// Least squares min |r − Σ_j δ_j c_j|² by the normal equations (at most 3 columns), Gaussian
/// elimination with partial pivoting; a column dependent on the others (pivot below 1e-12 of
/// the diagonal) gets δ = 0.
fn least_squares(cols: &[&[f64]], r: &[f64]) -> Vec<f64> {
    let n = cols.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut a: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let mut row: Vec<f64> = (0..n).map(|j| dot(cols[i], cols[j])).collect();
            row.push(dot(cols[i], r));
            row
        })
        .collect();
    let scale: Vec<f64> = (0..n).map(|i| a[i][i].max(f64::MIN_POSITIVE)).collect();
    let mut pivot_ok = vec![true; n];
    for c in 0..n {
        let p = (c..n)
            .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
            .expect("a row");
        a.swap(c, p);
        if a[c][c].abs() < 1e-12 * scale[c] {
            pivot_ok[c] = false;
            continue;
        }
        let pivot = a[c].clone();
        for (i, row) in a.iter_mut().enumerate() {
            if i != c {
                let m = row[c] / pivot[c];
                for (x, pj) in row.iter_mut().zip(&pivot).skip(c) {
                    *x -= m * pj;
                }
            }
        }
    }
    (0..n)
        .map(|i| if pivot_ok[i] { a[i][n] / a[i][i] } else { 0.0 })
        .collect()
}

/// The range a main size is drawn from, and its neutral value, for `effect` on `sys`
/// (model §8): η_m U(0.05, 0.3); φ log-uniform 3e-5 – 1.5e-3; r_h U(0.5, 0.9); η_p raised by a
/// log-uniform 0.015–0.15 (at most 0.3); n = n₀ + U(0.02, 0.12) (at most 0.2), n₀ = atan(η_p)/(π/2)
/// the exponent whose loss equals the wall's (P71).
fn draw_main_size<R: Rng>(rng: &mut R, effect: Effect, sys: &System) -> f64 {
    match effect {
        Effect::SoilDamping => uniform(rng, 0.05, 0.3),
        Effect::AirInWater => log_uniform(rng, 3e-5, 1.5e-3),
        Effect::WallThinning => uniform(rng, 0.5, 0.9),
        Effect::PipeLoss => (sys.pipe.loss_factor + log_uniform(rng, 0.015, 0.15)).min(0.3),
        _ => (exponent_of_loss_factor(sys.pipe.loss_factor) + uniform(rng, 0.02, 0.12)).min(0.2),
    }
}

/// The neutral value of `effect` on `sys` and the far end of its range (model §8, the
/// parameter's bounds), and whether the floor is searched on a log scale (air: φ spans
/// decades).
fn floor_span(effect: Effect, sys: &System) -> (f64, f64, bool) {
    match effect {
        Effect::SoilDamping => (0.0, 0.3, false),
        Effect::AirInWater => (0.0, 0.02, true),
        Effect::WallThinning => (1.0, 0.3, false),
        Effect::PipeLoss => (sys.pipe.loss_factor, 0.3, false),
        _ => (exponent_of_loss_factor(sys.pipe.loss_factor), 0.2, false),
    }
}

/// The neutral value of an effect on a system (the parameter at which it is absent).
pub fn neutral_value(effect: Effect, sys: &System) -> f64 {
    floor_span(effect, sys).0
}

/// z of `effect` at size `v` on `base`, None when a root is not clean.
fn z_at(
    frequencies: &[f64],
    base: &System,
    effect: Effect,
    v: f64,
    law: &NoiseLaw,
) -> Option<(f64, f64, System, Vec<Complex64>)> {
    let sys = effect.apply(base, v).ok()?;
    let k = noiseless(&sys, frequencies)?;
    let (z, raw) = profiled_z(base, frequencies, &k, law)?;
    Some((z, raw, sys, k))
}

/// The floor size of `effect` on `base`: bisection on z(size) = [`Z_FLOOR`] between the
/// neutral value and the far end of the range (on ln φ for air, from φ = 1e-8). None when even
/// the far end stays below the floor or a root is not clean.
fn floor_size(frequencies: &[f64], base: &System, effect: Effect, law: &NoiseLaw) -> Option<f64> {
    let (neutral, far, log) = floor_span(effect, base);
    let at = |t: f64| {
        if log {
            (1e-8f64.ln() + t * (far.ln() - 1e-8f64.ln())).exp()
        } else {
            neutral + t * (far - neutral)
        }
    };
    if z_at(frequencies, base, effect, at(1.0), law)?.0 < Z_FLOOR {
        return None;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..FLOOR_STEPS {
        let mid = 0.5 * (lo + hi);
        if z_at(frequencies, base, effect, at(mid), law)?.0 < Z_FLOOR {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(at(hi))
}

/// What the network stream deals a segment: its trial, and for the groups set its zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Deal {
    /// The trial of each segment.
    pub trials: Vec<Trial>,
    /// The zones (groups set only).
    pub zones: Vec<Zone>,
}

/// Deal the trials: the kinds of the set in equal numbers (±1), placed by a shuffle of the
/// network stream; for the groups set, zones of `group_size` consecutive segments, round(F·zones)
/// of them affected (by a shuffle), each with a carried fraction U(0.2, 0.4) of its members
/// (round, at least 1) from the zone's own stream.
pub fn deal(opts: &Options) -> Result<Deal> {
    let n = opts.segments;
    let mut rng = network_rng(opts.seed);
    let kinds: Vec<Trial> = match opts.set {
        Set::Main | Set::Floor => HIDDEN.iter().map(|&e| Trial::Effect(e)).collect(),
        Set::Records => std::iter::once(Trial::Record(None))
            .chain(RecordError::ALL.iter().map(|&r| Trial::Record(Some(r))))
            .collect(),
        Set::Groups => vec![Trial::Effect(None)],
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut rng);
    let mut trials = vec![Trial::Effect(None); n];
    for (pos, &i) in order.iter().enumerate() {
        trials[i] = kinds[pos % kinds.len()];
    }
    let mut zones = Vec::new();
    if opts.set == Set::Groups {
        if opts.group_size < 2 {
            bail!("--group-size must be at least 2");
        }
        let n_zones = n.div_ceil(opts.group_size);
        let n_affected = ((opts.affected_fraction * n_zones as f64).round() as usize).min(n_zones);
        let mut zidx: Vec<usize> = (0..n_zones).collect();
        zidx.shuffle(&mut rng);
        let mut affected = vec![false; n_zones];
        for &g in &zidx[..n_affected] {
            affected[g] = true;
        }
        let mut k_affected = 0;
        for (g, &is_affected) in affected.iter().enumerate() {
            let mut zr = zone_rng(opts.seed, g);
            let class = pick(&mut zr, &SOIL_CLASSES);
            let soil = (
                log_uniform(&mut zr, class.youngs.0, class.youngs.1),
                uniform(&mut zr, class.poisson.0, class.poisson.1),
                uniform(&mut zr, class.density.0, class.density.1),
            );
            let members: Vec<usize> =
                (g * opts.group_size..((g + 1) * opts.group_size).min(n)).collect();
            let (effect, carriers) = if is_affected {
                let e = GROUP_EFFECTS[k_affected % GROUP_EFFECTS.len()];
                k_affected += 1;
                let frac = uniform(&mut zr, 0.2, 0.4);
                let m = ((frac * members.len() as f64).round() as usize).clamp(1, members.len());
                let mut c = members.clone();
                c.shuffle(&mut zr);
                c.truncate(m);
                c.sort_unstable();
                for &i in &c {
                    trials[i] = Trial::Effect(Some(e));
                }
                (Some(e), c)
            } else {
                (None, Vec::new())
            };
            zones.push(Zone {
                name: format!("Z{:02}", g + 1),
                effect,
                class,
                soil,
                members,
                carriers,
            });
        }
    }
    Ok(Deal { trials, zones })
}

/// One draw of segment `index`; None when it is not clean (a root, the leak-band mean, a
/// recorded record, a main size below [`Z_MAIN_MIN`], a floor out of the effect's range).
fn try_segment(
    rng: &mut ChaCha8Rng,
    opts: &Options,
    index: usize,
    trial: Trial,
    zone: Option<&Zone>,
) -> Result<Option<Segment>> {
    let material = if zone.is_some() {
        Material::CastIron
    } else {
        pick_material(rng, |m| trial.applies_to(m))
    };
    let size = *sizes(material).choose(rng).expect("catalogue");
    let overrides = opts.set != Set::Records;
    let wall = if overrides {
        draw_wall(rng, material)
    } else {
        let t = material.typical();
        Wall {
            youngs: t.youngs_modulus,
            poisson: t.poisson,
            density: t.density,
            loss: t.loss_factor,
        }
    };
    let (soil_type, soil) = match zone {
        // A zone's members scatter about its centre: E_m by a factor e^(0.3 N(0,1)), ν_m by
        // U(−0.03, 0.03) (kept in 0.2–0.49), ρ_m by U(−50, 50) kg/m³.
        Some(z) => (
            z.class.name,
            Soil::new(
                (z.soil.0 * (0.3 * std_normal(rng)).exp()).clamp(1e6, 1e9),
                (z.soil.1 + uniform(rng, -0.03, 0.03)).clamp(0.2, 0.49),
                z.soil.2 + uniform(rng, -50.0, 50.0),
                0.0,
            )?,
        ),
        None => {
            let class: SoilClass = pick(rng, &SOIL_CLASSES);
            (
                class.name,
                Soil::new(
                    log_uniform(rng, class.youngs.0, class.youngs.1),
                    uniform(rng, class.poisson.0, class.poisson.1),
                    uniform(rng, class.density.0, class.density.1),
                    0.0,
                )?,
            )
        }
    };
    let contact = draw_contact(rng);
    let length_m = (log_uniform(rng, 40.0, 600.0) * 10.0).round() / 10.0;
    let install_year = rng.gen_range(match material {
        Material::CastIron => 1890..=1965,
        Material::AsbestosCement => 1945..=1985,
        Material::Steel => 1930..=1995,
        Material::DuctileIron => 1965..=2020,
        _ => 1970..=2022,
    });
    let truth = Record { material, size };
    let recorded = match trial {
        Trial::Record(Some(err)) => match draw_recorded(rng, err, truth) {
            Some(r) => r,
            None => return Ok(None),
        },
        _ => truth,
    };
    let Some((base, f_max)) = buried_pipe(&wall, &size, soil, contact)? else {
        return Ok(None);
    };
    let plan = draw_plan(rng, f_max);
    let noise = NoiseLaw::draw(rng, &plan);
    let Some(k_base) = noiseless(&base, &plan.frequencies) else {
        return Ok(None);
    };
    let effect = match trial {
        Trial::Effect(e) => e,
        Trial::Record(_) => None,
    };
    let (value, neutral, measured, k, z, z_raw) = match effect {
        None => {
            let k = k_base;
            let (z, z_raw) = match trial {
                // A record error: the data against the recorded pipe's model at the true soil.
                Trial::Record(Some(_)) => {
                    let rp = pipe_of(recorded)?;
                    let rsys = System { pipe: rp, ..base };
                    match profiled_z(&rsys, &plan.frequencies, &k, &noise) {
                        // An error the data cannot show is no trial of the diagnosis: kept
                        // only at a main detectability, as a main-size effect.
                        Some(z) if z.0 >= Z_MAIN_MIN => z,
                        _ => return Ok(None),
                    }
                }
                _ => (0.0, 0.0),
            };
            (None, None, base, k, z, z_raw)
        }
        Some(e) => {
            let v = if opts.set == Set::Main {
                draw_main_size(rng, e, &base)
            } else {
                match floor_size(&plan.frequencies, &base, e, &noise) {
                    Some(v) => v,
                    None => return Ok(None),
                }
            };
            let Some((z, z_raw, sys, k)) = z_at(&plan.frequencies, &base, e, v, &noise) else {
                return Ok(None);
            };
            if opts.set == Set::Main && z < Z_MAIN_MIN {
                return Ok(None);
            }
            // Where the profile's optimum jumps between two soils at the crossing, z is not
            // continuous in the size and the bisection ends off the floor: such a draw is
            // redrawn, so every floor trial has z within 1 % of the floor.
            if opts.set != Set::Main && (z / Z_FLOOR - 1.0).abs() > FLOOR_TOLERANCE {
                return Ok(None);
            }
            (Some(v), Some(neutral_value(e, &base)), sys, k, z, z_raw)
        }
    };
    let Some(speed_base) = leak_band_speed_of(&base) else {
        return Ok(None);
    };
    let speed_measured = if effect.is_some() {
        match leak_band_speed_of(&measured) {
            Some(v) => v,
            None => return Ok(None),
        }
    } else {
        speed_base
    };
    let Some(rows) = measure(rng, &plan, &k, &noise) else {
        return Ok(None);
    };
    Ok(Some(Segment {
        id: format!("{}{:05}", opts.set.prefix(), index + 1),
        trial,
        truth,
        recorded,
        wall,
        overrides,
        soil_type,
        soil_zone: zone.map(|z| z.name.clone()),
        group_effect: zone.and_then(|z| z.effect),
        length_m,
        install_year,
        base,
        measured,
        value,
        neutral,
        plan,
        noise,
        rows,
        z,
        z_raw,
        speed_base,
        speed_measured,
        rejected: 0,
    }))
}

/// The pipe a record describes, with the material's typical properties (model §3.3), as
/// pipewave reads a record without overrides.
fn pipe_of(rec: Record) -> Result<Pipe> {
    Ok(Pipe::from_outside_diameter(
        rec.material.typical(),
        rec.size.od_mm / 1000.0,
        rec.size.wall_mm / 1000.0,
    )?)
}

/// Draw segment `index` (redrawing until clean, at most [`MAX_ATTEMPTS`] times).
pub fn draw_segment(opts: &Options, deal: &Deal, index: usize) -> Result<Segment> {
    let mut rng = segment_rng(opts.seed, index);
    let zone = deal.zones.iter().find(|z| z.members.contains(&index));
    for attempt in 0..MAX_ATTEMPTS {
        if let Some(mut s) = try_segment(&mut rng, opts, index, deal.trials[index], zone)? {
            s.rejected = attempt;
            return Ok(s);
        }
    }
    bail!(
        "segment {index} ({}): no clean draw in {MAX_ATTEMPTS} attempts",
        deal.trials[index].kind_name()
    )
}

/// Generate a set (in parallel; the result does not depend on the number of threads).
pub fn generate(opts: &Options) -> Result<(Vec<Segment>, Deal)> {
    if opts.segments == 0 {
        bail!("--segments must be at least 1");
    }
    if !(0.0..=1.0).contains(&opts.affected_fraction) {
        bail!(
            "--affected-fraction must be within 0-1, got {}",
            opts.affected_fraction
        );
    }
    let d = deal(opts)?;
    let segs = (0..opts.segments)
        .into_par_iter()
        .map(|i| draw_segment(opts, &d, i))
        .collect::<Result<Vec<_>>>()?;
    Ok((segs, d))
}

/// The measurement date of segment `index` (September 2025).
pub fn measured_on(index: usize) -> String {
    format!("2025-09-{:02}", 1 + index % 28)
}

/// segments.csv in pipewave's import format (docs/interface.md): the recorded record; the true
/// wall's properties as overrides except in the records set; `soil_zone` in the groups set.
pub fn segments_csv(segs: &[Segment]) -> String {
    let overrides = segs.iter().any(|s| s.overrides);
    let zones = segs.iter().any(|s| s.soil_zone.is_some());
    let mut s =
        String::from("segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3");
    if overrides {
        s.push_str(",pipe_youngs_modulus_pa,pipe_poisson,pipe_density_kg_m3,pipe_loss_factor");
    }
    s.push_str(",length_m,soil_type,install_year");
    if zones {
        s.push_str(",soil_zone");
    }
    s.push('\n');
    for g in segs {
        write!(
            s,
            "{},{},{},{},{}",
            g.id,
            g.recorded.material.code(),
            g.recorded.size.od_mm,
            g.recorded.size.wall_mm,
            g.base.soil.density
        )
        .expect("write to string");
        if overrides {
            write!(
                s,
                ",{},{},{},{}",
                g.wall.youngs, g.wall.poisson, g.wall.density, g.wall.loss
            )
            .expect("write to string");
        }
        write!(s, ",{},{},{}", g.length_m, g.soil_type, g.install_year).expect("write to string");
        if zones {
            write!(s, ",{}", g.soil_zone.as_deref().unwrap_or("")).expect("write to string");
        }
        s.push('\n');
    }
    s
}

/// measurements.csv: one row per segment and frequency, campaign [`CAMPAIGN`].
pub fn measurements_csv(segs: &[Segment]) -> String {
    let mut s = String::from(
        "segment_id,campaign,measured_on,frequency_hz,k_re_rad_per_m,attenuation_np_per_m,\
         k_re_std,attenuation_std\n",
    );
    for (i, g) in segs.iter().enumerate() {
        let date = measured_on(i);
        for r in &g.rows {
            writeln!(
                s,
                "{},{},{},{},{},{},{},{}",
                g.id,
                CAMPAIGN,
                date,
                r.frequency_hz,
                r.k_re,
                r.attenuation,
                r.k_re_std,
                r.attenuation_std
            )
            .expect("write to string");
        }
    }
    s
}

/// The columns of truth.csv, in order.
pub const TRUTH_COLUMNS: [&str; 27] = [
    "segment_id",
    "set",
    "effect",
    "kind",
    "value",
    "neutral_value",
    "z",
    "z_raw",
    "true_record",
    "recorded_record",
    "material",
    "recorded_material",
    "soil_zone",
    "group_effect",
    "soil_youngs_modulus_pa",
    "soil_poisson",
    "contact",
    "soil_density_kg_m3",
    "soil_type",
    "pipe_youngs_modulus_pa",
    "pipe_loss_factor",
    "n_frequencies",
    "frequency_min_hz",
    "frequency_max_hz",
    "k_re_rel_std",
    "leak_band_speed_base_m_per_s",
    "leak_band_speed_m_per_s",
];

/// truth.csv: per segment the hidden effect (`none`, an effect name, or `inventory_error`), its
/// kind, value and neutral value, z, the true and recorded records, the soil and the plan.
pub fn truth_csv(set: Set, segs: &[Segment]) -> String {
    let mut s = TRUTH_COLUMNS.join(",");
    s.push('\n');
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    for g in segs {
        let f = &g.plan.frequencies;
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},\"{}\",\"{}\",{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            g.id,
            set.name(),
            g.trial.effect_name(),
            g.trial.kind_name(),
            opt(g.value),
            opt(g.neutral),
            g.z,
            g.z_raw,
            g.truth,
            g.recorded,
            g.truth.material.code(),
            g.recorded.material.code(),
            g.soil_zone.as_deref().unwrap_or(""),
            match (&g.soil_zone, g.group_effect) {
                (None, _) => "",
                (Some(_), None) => "none",
                (Some(_), Some(e)) => e.name(),
            },
            g.base.soil.youngs_modulus,
            g.base.soil.poisson,
            g.base.contact,
            g.base.soil.density,
            g.soil_type,
            g.wall.youngs,
            g.wall.loss,
            f.len(),
            f[0],
            f[f.len() - 1],
            g.noise.rel_re,
            g.speed_base,
            g.speed_measured
        )
        .expect("write to string");
    }
    s
}

/// Counts of a generated set, for the summary, the README's table and the tests.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Segments.
    pub segments: usize,
    /// Per kind (truth.csv `kind`): count, median z, smallest z, largest z.
    pub by_kind: Vec<(&'static str, usize, f64, f64, f64)>,
    /// Zones, affected zones, carriers (groups set).
    pub zones: (usize, usize, usize),
    /// Draws rejected in all.
    pub rejected: usize,
}

/// Count a set.
pub fn summarize(segs: &[Segment], deal: &Deal) -> Summary {
    let mut kinds: Vec<&'static str> = Vec::new();
    for g in segs {
        let k = g.trial.kind_name();
        if !kinds.contains(&k) {
            kinds.push(k);
        }
    }
    let by_kind = kinds
        .into_iter()
        .map(|k| {
            let mut z: Vec<f64> = segs
                .iter()
                .filter(|g| g.trial.kind_name() == k)
                .map(|g| g.z)
                .collect();
            z.sort_by(f64::total_cmp);
            (k, z.len(), z[z.len() / 2], z[0], z[z.len() - 1])
        })
        .collect();
    Summary {
        segments: segs.len(),
        by_kind,
        zones: (
            deal.zones.len(),
            deal.zones.iter().filter(|z| z.effect.is_some()).count(),
            deal.zones.iter().map(|z| z.carriers.len()).sum(),
        ),
        rejected: segs.iter().map(|g| g.rejected).sum(),
    }
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{} segments; {} draws rejected",
            self.segments, self.rejected
        )?;
        for (k, n, med, lo, hi) in &self.by_kind {
            writeln!(
                f,
                "  {k:<18} {n:>5}   z median {med:.2} (min {lo:.2}, max {hi:.2})"
            )?;
        }
        if self.zones.0 > 0 {
            writeln!(
                f,
                "zones: {} ({} affected, {} carriers)",
                self.zones.0, self.zones.1, self.zones.2
            )?;
        }
        Ok(())
    }
}

/// Write segments.csv, measurements.csv and truth.csv into `dir` (created if missing).
pub fn write(dir: &Path, set: Set, segs: &[Segment]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in [
        ("segments.csv", segments_csv(segs)),
        ("measurements.csv", measurements_csv(segs)),
        ("truth.csv", truth_csv(set, segs)),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
