//! Synthetic pipe networks: inventories with field-like measurements made by the forward model
//! from known soil parameters (and, optionally, hidden effects), with realistic noise.
//!
//! Used by `pipewave synth`, the bundled `sample_network`, and the recovery tests. The known
//! truth is returned separately and never reaches the fit.

use num_complex::Complex64;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub mod bench;
pub mod field;
pub mod honesty;
pub mod locate;
pub mod network;
pub mod recordings;
pub mod trial;
pub mod zones;

use crate::invert::assemble::leak_band_speed_of;
use crate::physics::effects::Effect;
use crate::physics::solver::{solve_curve, Continuation};
use crate::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};
use crate::stats::normal;
use crate::units::hz_to_omega;

/// Relative noise (one sigma) on Re k of a synthetic measurement (1 %).
pub const NOISE_K_RE: f64 = 0.01;
/// Relative noise (one sigma) on the attenuation (5 %).
pub const NOISE_ATTENUATION: f64 = 0.05;

/// Default scatter of log10 E_m within a synthetic soil zone, decades: 0.04 decade is about
/// 10 % in E (model §7.11, typical of one soil unit).
pub const ZONE_SCATTER_E_DECADES: f64 = 0.04;
/// Default scatter of ν_m within a synthetic soil zone (model §7.11).
pub const ZONE_SCATTER_NU: f64 = 0.01;
/// Stream of [`crate::seed::derive`] for the zones' soils (independent of the segments').
const ZONE_SEED_STREAM: u64 = 12;
/// Stream for the geological units and their soil field.
const GEOLOGY_SEED_STREAM: u64 = 13;
/// Stream for the per-pipe soil scatter inside the units.
const PIPE_SOIL_SEED_STREAM: u64 = 14;
/// Stream for the choice of the measured segments.
const MEASURED_SEED_STREAM: u64 = 15;
/// Stream for the choice of the wrong labels.
const LABEL_SEED_STREAM: u64 = 16;
/// Stream for the noise of the second campaign (`synth --campaigns 2`): its own, so the first
/// campaign's numbers are those of a one-campaign network.
const SECOND_NOISE_SEED_STREAM: u64 = 17;
/// Stream for the choice of the pipes that changed between the campaigns, and their changes.
const CHANGE_SEED_STREAM: u64 = 18;

/// Default correlation length of the soil field inside a geological unit, m (model §7.12: a
/// few hundred metres).
pub const DEFAULT_CORRELATION_LENGTH_M: f64 = 350.0;

/// The "table" soil a correlator's material/diameter table assumes (model §7.12): E_m 5e7 Pa,
/// ν_m 0.33, and the contact ξ 0.5; the density is the inventory's.
pub const TABLE_SOIL_MODULUS: f64 = 5e7;
/// Poisson's ratio of the table soil.
pub const TABLE_SOIL_POISSON: f64 = 0.33;
/// Contact coefficient of the table soil.
pub const TABLE_CONTACT: f64 = 0.5;

/// A pipe size from a standard: nominal size, outside diameter and wall thickness (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipeSize {
    /// Nominal diameter DN, mm.
    pub dn: u32,
    /// Outside diameter, mm.
    pub od_mm: f64,
    /// Wall thickness, mm.
    pub wall_mm: f64,
}

const fn size(dn: u32, od_mm: f64, wall_mm: f64) -> PipeSize {
    PipeSize { dn, od_mm, wall_mm }
}

/// Typical sizes of a European / North American distribution network, per material.
/// DI: ISO 2531 K9 (e = 9(0.5 + 0.001 DN) mm, not checked against the standard, model §9);
/// CI: pit- and spun-cast grey iron, thicker walls; ST: EN 10220 / API 5L line pipe;
/// PVC: EN 1452 SDR 21; MDPE: PE80 SDR 11; HDPE: PE100 SDR 17; AC: class 20 pressure pipe.
pub fn sizes(material: Material) -> &'static [PipeSize] {
    match material {
        Material::CastIron => &CI_SIZES,
        Material::DuctileIron => &DI_SIZES,
        Material::Steel => &ST_SIZES,
        Material::Pvc => &PVC_SIZES,
        Material::Mdpe => &MDPE_SIZES,
        Material::Hdpe => &HDPE_SIZES,
        Material::AsbestosCement => &AC_SIZES,
    }
}

const CI_SIZES: [PipeSize; 4] = [
    size(100, 122.0, 9.0),
    size(150, 175.0, 10.0),
    size(200, 229.0, 11.0),
    size(300, 335.0, 13.0),
];

const DI_SIZES: [PipeSize; 5] = [
    size(100, 118.0, 6.0),
    size(150, 170.0, 6.0),
    size(200, 222.0, 6.3),
    size(300, 326.0, 7.2),
    size(400, 429.0, 8.1),
];

const ST_SIZES: [PipeSize; 4] = [
    size(100, 114.3, 4.5),
    size(150, 168.3, 5.6),
    size(200, 219.1, 6.3),
    size(300, 323.9, 7.1),
];

const PVC_SIZES: [PipeSize; 4] = [
    size(100, 110.0, 5.3),
    size(150, 160.0, 7.7),
    size(200, 200.0, 9.6),
    size(250, 250.0, 11.9),
];

const MDPE_SIZES: [PipeSize; 4] = [
    size(50, 63.0, 5.8),
    size(80, 90.0, 8.2),
    size(100, 125.0, 11.4),
    size(150, 180.0, 16.4),
];

const HDPE_SIZES: [PipeSize; 4] = [
    size(100, 110.0, 6.6),
    size(150, 160.0, 9.5),
    size(200, 250.0, 14.8),
    size(300, 315.0, 18.7),
];

const AC_SIZES: [PipeSize; 3] = [
    size(100, 122.0, 11.5),
    size(150, 177.0, 14.0),
    size(200, 232.0, 17.0),
];

/// A soil class: (name, E_m range Pa, ν_m range, ρ_m range kg/m³).
pub type SoilClass = (&'static str, (f64, f64), (f64, f64), (f64, f64));

/// Soil classes from soft clay to gravel.
pub const SOILS: [SoilClass; 6] = [
    ("soft_clay", (5e6, 2e7), (0.40, 0.47), (1600.0, 1800.0)),
    ("stiff_clay", (2e7, 6e7), (0.35, 0.42), (1800.0, 2000.0)),
    ("loam", (3e7, 7e7), (0.30, 0.38), (1800.0, 2000.0)),
    ("sand", (4e7, 1.2e8), (0.25, 0.35), (1700.0, 2000.0)),
    ("dense_sand", (1e8, 2.5e8), (0.25, 0.33), (1900.0, 2100.0)),
    ("gravel", (1.5e8, 4e8), (0.20, 0.30), (2000.0, 2200.0)),
];

/// Network-wide share of each material (a utility with old iron and newer plastics).
pub const MATERIAL_MIX: [(Material, f64); 7] = [
    (Material::CastIron, 0.25),
    (Material::DuctileIron, 0.2),
    (Material::Steel, 0.07),
    (Material::Pvc, 0.16),
    (Material::Mdpe, 0.14),
    (Material::Hdpe, 0.1),
    (Material::AsbestosCement, 0.08),
];

/// One synthetic measurement (attenuation in Np/m, positive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthMeasurement {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Measured Re k, rad/m.
    pub k_re: f64,
    /// Measured attenuation, Np/m.
    pub attenuation: f64,
    /// Stated one-sigma of Re k.
    pub k_re_std: f64,
    /// Stated one-sigma of the attenuation.
    pub attenuation_std: f64,
}

impl SynthMeasurement {
    /// The checked measurement the inversion takes (ω from the frequency).
    pub fn measurement(&self) -> crate::invert::Measurement {
        crate::invert::Measurement::new(
            crate::units::hz_to_omega(self.frequency_hz),
            self.k_re,
            self.attenuation,
            Some(self.k_re_std),
            Some(self.attenuation_std),
        )
        .expect("synthetic measurements are valid")
    }
}

/// What the fit of a synthetic pipe is given: water, the material's typical wall, the soil
/// density and the measurements (never the truth).
pub fn segment_data(
    material: Material,
    pipe: Pipe,
    soil_density: f64,
    measurements: &[SynthMeasurement],
) -> crate::invert::SegmentData {
    crate::invert::SegmentData {
        fluid: Fluid::water(),
        pipe,
        soil_density,
        material: Some(material),
        measurements: measurements
            .iter()
            .map(SynthMeasurement::measurement)
            .collect(),
    }
}

impl SynthSegment {
    /// What the fit is given about this segment (its inventory and measurements).
    pub fn segment_data(&self) -> crate::invert::SegmentData {
        segment_data(
            self.material,
            pipe_of(self.material, &self.size),
            self.soil_density,
            &self.measurements,
        )
    }
}

/// A deliberate defect of a "genuinely bad" segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Defect {
    /// Nothing wrong.
    None,
    /// One measurement is a gross outlier (a wrong sensor spacing: speed 25 % off).
    Outlier,
    /// The attenuation was recorded in dB/m in a Np/m column (8.7× too large).
    UnitMixUp,
    /// The measurements belong to another pipe (the inventory material is wrong).
    WrongMaterial,
    /// A single measured frequency only.
    TooFew,
}

impl Defect {
    /// Name for truth.csv.
    pub fn as_str(self) -> &'static str {
        match self {
            Defect::None => "",
            Defect::Outlier => "outlier",
            Defect::UnitMixUp => "attenuation_in_db",
            Defect::WrongMaterial => "wrong_material",
            Defect::TooFew => "too_few_measurements",
        }
    }
}

/// A synthetic segment with its truth.
#[derive(Debug, Clone)]
pub struct SynthSegment {
    /// Asset id.
    pub id: String,
    /// Material in the inventory.
    pub material: Material,
    /// Size.
    pub size: PipeSize,
    /// Soil class name.
    pub soil_type: &'static str,
    /// Soil density, kg/m³ (given to the fit).
    pub soil_density: f64,
    /// True E_m, Pa.
    pub soil_modulus: f64,
    /// True ν_m.
    pub soil_poisson: f64,
    /// True ξ.
    pub contact: f64,
    /// Hidden effect and its value, if any.
    pub hidden: Option<(Effect, f64)>,
    /// Deliberate defect.
    pub defect: Defect,
    /// Measurements.
    pub measurements: Vec<SynthMeasurement>,
    /// Polyline, projected metres.
    pub geometry: Vec<(f64, f64)>,
    /// Length, m.
    pub length_m: f64,
    /// Installation year.
    pub install_year: u32,
    /// Soil zone (`synth --zones`), if any.
    pub soil_zone: Option<String>,
    /// The zone's true soil (E_m Pa, ν_m), about which this segment's soil scatters.
    pub zone_soil: Option<(f64, f64)>,
    /// The soil class the inventory states (`soil_type` of segments.csv): `soil_type`, unless
    /// the label is wrong (`synth --wrong-labels`).
    pub soil_label: &'static str,
    /// Geological unit (`synth --units`), if any.
    pub unit: Option<usize>,
    /// Whether its measurements are kept in measurements.csv (`synth --measured-fraction`);
    /// the others' measurements are what a later campaign would take.
    pub measured: bool,
    /// True mean phase speed over the leak band of the pipe as it is (its soil, contact and
    /// any hidden effect), m/s; `None` if the forward model fails in the band. With two
    /// campaigns, the speed at the first.
    pub leak_band_speed: Option<f64>,
    /// The "table speed": the same for the inventory's pipe in the table soil
    /// ([`TABLE_SOIL_MODULUS`], [`TABLE_SOIL_POISSON`], [`TABLE_CONTACT`], the inventory's
    /// density).
    pub table_leak_band_speed: Option<f64>,
    /// The second campaign (`synth --campaigns 2`) of a measured segment, with what changed.
    pub second: Option<SecondCampaign>,
}

/// What changed in a pipe between the two campaigns of `synth --campaigns 2`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Change {
    /// Nothing: the second campaign measures the same pipe (fresh noise only).
    None,
    /// The soil's Young's modulus E_m moved (drying or freezing stiffen it, wetting softens it).
    SoilChange,
    /// Free air entered the water (model §8 E3, Wood's equation P60–P61).
    AirInWater,
    /// The load-bearing wall thinned (model §8 E4, eq. P62): iron, steel and AC only.
    WallThinning,
    /// The wall loss factor η_p rose (model §8 E2, eq. P9): cracked joints, degraded lining.
    PipeLoss,
}

impl Change {
    /// Name in truth.csv (`change_effect`): `none`, `soil_change`, or the effect's name.
    pub fn as_str(self) -> &'static str {
        match self {
            Change::None => "none",
            Change::SoilChange => "soil_change",
            Change::AirInWater => Effect::AirInWater.name(),
            Change::WallThinning => Effect::WallThinning.name(),
            Change::PipeLoss => Effect::PipeLoss.name(),
        }
    }
}

/// The second campaign of a measured segment: the same frequencies as the first, fresh noise,
/// and the pipe as it is a year later.
#[derive(Debug, Clone, PartialEq)]
pub struct SecondCampaign {
    /// What changed.
    pub change: Change,
    /// The changed parameter's new value: E_m in Pa (`soil_change`), the air fraction φ
    /// (`air_in_water`), the wall ratio h/h₀ (`wall_thinning`), the wall loss factor η_p
    /// (`pipe_loss`); `None` when nothing changed.
    pub change_value: Option<f64>,
    /// The second campaign's measurements (the first campaign's defect repeated, if any: a
    /// wrong spacing or a spreadsheet's units stay with the utility's records).
    pub measurements: Vec<SynthMeasurement>,
    /// True leak-band speed after the change ([`leak_band_speed_of`]), m/s.
    pub leak_band_speed_after: Option<f64>,
    /// Detectability of the change at the stated noise: z of [`change_z`].
    pub change_z: f64,
}

/// Campaign name of the first campaign of `synth --campaigns 2`.
pub const FIRST_CAMPAIGN: &str = "FD-2026";
/// Campaign name of the second campaign, a year later.
pub const SECOND_CAMPAIGN: &str = "FD-2027";
/// Default fraction of the re-measured pipes that changed between two campaigns.
pub const DEFAULT_CHANGED_FRACTION: f64 = 0.3;
/// Most campaigns `synth --campaigns` writes.
pub const MAX_CAMPAIGNS: u32 = 2;

/// Options of a synthetic network.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Number of segments.
    pub segments: usize,
    /// Seed.
    pub seed: u64,
    /// Fraction of segments with a deliberate defect.
    pub defect_fraction: f64,
    /// Model that generates the data.
    pub model: Model,
    /// Contact reading that generates the data.
    pub contact_mode: ContactMode,
    /// Hidden effect (for discrepancy studies), with its value range.
    pub hidden_effect: Option<(Effect, f64, f64)>,
    /// Fraction of segments given the hidden effect (the rest are controls).
    pub hidden_fraction: f64,
    /// Easting, northing of the south-west corner of the street grid (EPSG:27700 metres).
    pub origin: (f64, f64),
    /// EPSG code of the coordinates.
    pub srid: u32,
    /// Soil zones (0: none): the segments are split into this many contiguous zones, each one
    /// soil unit (model §7.11).
    pub zones: usize,
    /// Scatter of the segments' soil about their zone's: (log10 E_m decades, ν_m), one sigma.
    pub zone_scatter: (f64, f64),
    /// Geological units (0: none, every segment draws its own soil class): a Voronoi partition
    /// of the map with a correlated soil inside each unit ([`field`], model §7.12).
    pub units: usize,
    /// Correlation length of the soil field inside the units, m.
    pub correlation_length_m: f64,
    /// Fraction of segments whose measurements are kept (exactly `round(F n)` of them).
    pub measured_fraction: f64,
    /// Fraction of segments whose `soil_type` label is wrong (exactly `round(F n)`, each given
    /// the class of another unit, or another class without units).
    pub wrong_label_fraction: f64,
    /// Campaigns of measurements (1 or 2): with 2, every measured segment is measured again a
    /// year later ([`SecondCampaign`]).
    pub campaigns: usize,
    /// Fraction of the measured segments that changed between the campaigns (exactly
    /// `round(F m)` of the m measured ones); used with two campaigns only.
    pub changed_fraction: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            segments: 200,
            seed: 1,
            defect_fraction: 0.03,
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            hidden_effect: None,
            hidden_fraction: 1.0,
            // A street grid in central Southampton, British National Grid.
            origin: (441_800.0, 111_900.0),
            srid: 27700,
            zones: 0,
            zone_scatter: (ZONE_SCATTER_E_DECADES, ZONE_SCATTER_NU),
            units: 0,
            correlation_length_m: DEFAULT_CORRELATION_LENGTH_M,
            measured_fraction: 1.0,
            wrong_label_fraction: 0.0,
            campaigns: 1,
            changed_fraction: DEFAULT_CHANGED_FRACTION,
        }
    }
}

impl SynthOptions {
    /// `segments` segments of seed `seed`, without defects, every one hiding `effect` at a
    /// value drawn from its [`default_hidden_range`]; `None` for an effect without one.
    pub fn hiding(effect: Effect, segments: usize, seed: u64) -> Option<Self> {
        let (lo, hi) = default_hidden_range(effect)?;
        Some(Self {
            segments,
            seed,
            defect_fraction: 0.0,
            hidden_effect: Some((effect, lo, hi)),
            ..Self::default()
        })
    }
}

/// The value range a hidden effect is drawn from by default: values whose signature is
/// visible at 1 %/5 % noise in some segments (model §8): soil loss 0.05–0.3, air 2e-5–5e-4
/// (log-uniform), effective wall 0.5–0.85 of nominal, wall loss factor 0.04–0.15.
pub fn default_hidden_range(effect: Effect) -> Option<(f64, f64)> {
    match effect {
        Effect::SoilDamping => Some((0.05, 0.3)),
        Effect::AirInWater => Some((2e-5, 5e-4)),
        Effect::WallThinning => Some((0.5, 0.85)),
        Effect::PipeLoss => Some((0.04, 0.15)),
        Effect::ViscoelasticWall => Some((0.03, 0.15)),
        Effect::FullModel | Effect::InventoryError | Effect::MeasurementUnits => None,
    }
}

fn pick_material<R: Rng + ?Sized>(rng: &mut R) -> Material {
    let total: f64 = MATERIAL_MIX.iter().map(|m| m.1).sum();
    let mut u = rng.gen::<f64>() * total;
    for (m, w) in MATERIAL_MIX {
        if u < w {
            return m;
        }
        u -= w;
    }
    Material::DuctileIron
}

fn log_uniform<R: Rng + ?Sized>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    (lo.ln() + rng.gen::<f64>() * (hi.ln() - lo.ln())).exp()
}

/// The measurement band of a material, Hz: iron, steel and AC carry leak noise to 1.5 kHz;
/// plastics attenuate strongly above a few hundred Hz (model §1, \[R8\]).
pub fn band_hz(material: Material) -> (f64, f64) {
    if material.is_plastic() {
        (60.0, 600.0)
    } else {
        (100.0, 1500.0)
    }
}

/// The pipe of a synthetic segment, from the material's typical values.
pub fn pipe_of(material: Material, s: &PipeSize) -> Pipe {
    Pipe::from_outside_diameter(material.typical(), s.od_mm * 1e-3, s.wall_mm * 1e-3)
        .expect("catalogue sizes are valid")
}

/// Measured frequencies: `m` distinct values spread over the band, rounded to 1 Hz.
fn frequencies<R: Rng + ?Sized>(rng: &mut R, band: (f64, f64), m: usize) -> Vec<f64> {
    let mut f: Vec<f64> = (0..m)
        .map(|i| {
            let lo = band.0 + (band.1 - band.0) * i as f64 / m as f64;
            let hi = band.0 + (band.1 - band.0) * (i + 1) as f64 / m as f64;
            (lo + rng.gen::<f64>() * (hi - lo)).round()
        })
        .collect();
    f.dedup();
    f
}

/// Noisy measurements of `sys` at `freqs` (Hz): 1 % on Re k, 5 % on the attenuation, with those
/// standard deviations stated. `None` if the forward model fails.
pub fn measure<R: Rng + ?Sized>(
    sys: &System,
    freqs: &[f64],
    rng: &mut R,
) -> Option<Vec<SynthMeasurement>> {
    Some(with_noise(freqs, &noiseless(sys, freqs)?, rng))
}

/// The noiseless wavenumbers k1 of `sys` at `freqs` (Hz); `None` if the forward model fails
/// or the wave grows. The data come from the reference path (29-point ramp, reference
/// tolerance, Muller), so they do not depend on the inversion's speed settings.
pub fn noiseless(sys: &System, freqs: &[f64]) -> Option<Vec<Complex64>> {
    let omegas: Vec<f64> = freqs.iter().map(|&f| hz_to_omega(f)).collect();
    solve_curve(sys, &omegas, Continuation::default())
        .into_iter()
        .map(|r| r.ok().filter(|r| !r.flags.growing_wave).map(|r| r.k1))
        .collect()
}

/// The stated one-sigma of Re k and of the attenuation of a measurement whose noiseless
/// wavenumber is `k`: [`NOISE_K_RE`] and [`NOISE_ATTENUATION`] of each.
fn stated_sigma(k: Complex64) -> (f64, f64) {
    (NOISE_K_RE * k.re, NOISE_ATTENUATION * (-k.im))
}

/// Measurements at `freqs` of the noiseless wavenumbers `k`, with Gaussian noise of the
/// stated sigmas ([`stated_sigma`]).
fn with_noise<R: Rng + ?Sized>(
    freqs: &[f64],
    k: &[Complex64],
    rng: &mut R,
) -> Vec<SynthMeasurement> {
    freqs
        .iter()
        .zip(k)
        .map(|(&f, &k)| {
            let (s_re, s_att) = stated_sigma(k);
            SynthMeasurement {
                frequency_hz: f,
                k_re: k.re + s_re * normal(rng),
                attenuation: (-k.im + s_att * normal(rng)).max(1e-9),
                k_re_std: s_re,
                attenuation_std: s_att,
            }
        })
        .collect()
}

/// Detectability of a change between two campaigns at the same frequencies, eq. P93 (model
/// §7.14): with the noiseless wavenumbers `a` before and `b` after and the stated sigmas of
/// each, z = sqrt(Σ_f [(Δk_re)²/(σ_re,A² + σ_re,B²) + (Δα)²/(σ_α,A² + σ_α,B²)]), α = −Im k.
/// It is the length, in standard deviations, of the difference two noisy campaigns show on
/// average; z ≈ 2–3 is where a test at the 95 % level starts to see it.
pub fn change_z(a: &[Complex64], b: &[Complex64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&ka, &kb)| {
            let ((sa_re, sa_att), (sb_re, sb_att)) = (stated_sigma(ka), stated_sigma(kb));
            let re = (kb.re - ka.re).powi(2) / (sa_re.powi(2) + sb_re.powi(2));
            let att = (kb.im - ka.im).powi(2) / (sa_att.powi(2) + sb_att.powi(2));
            re + if att.is_finite() { att } else { 0.0 }
        })
        .sum::<f64>()
        .sqrt()
}

/// Largest ν_m a scattered zone soil is given (below the fit's bound 0.499).
const ZONE_NU_MAX: f64 = 0.49;

/// Name of synthetic zone `z` in `segments.csv`: `Z01`, `Z02`, …
pub fn zone_name(z: usize) -> String {
    format!("Z{:02}", z + 1)
}

/// The street-grid edge of segment slot `i`: blocks 120 m × 90 m, `cols` blocks a row, even
/// slots along a block's south edge, odd ones along its west edge. Returns its two ends.
fn slot_ends(opts: &SynthOptions, cols: usize, i: usize) -> ((f64, f64), (f64, f64)) {
    let (row, col) = (i / cols, i % cols);
    let (x0, y0) = (
        opts.origin.0 + 120.0 * col as f64,
        opts.origin.1 + 90.0 * row as f64,
    );
    if i % 2 == 0 {
        ((x0, y0), (x0 + 120.0, y0))
    } else {
        ((x0, y0), (x0, y0 + 90.0))
    }
}

/// The midpoint of a slot's street edge (before the small jitter of the drawn geometry).
fn slot_midpoint(opts: &SynthOptions, cols: usize, i: usize) -> (f64, f64) {
    let (a, b) = slot_ends(opts, cols, i);
    (0.5 * (a.0 + b.0), 0.5 * (a.1 + b.1))
}

/// Mean phase speed over the leak band (the fits' definition, [`leak_band_speed_of`]) of
/// `sys` and of the table's view of the same inventory pipe (the table soil of model §7.12 at
/// the inventory's density, no hidden effect).
fn truth_speeds(
    opts: &SynthOptions,
    sys: &System,
    inventory_pipe: Pipe,
    density: f64,
) -> (Option<f64>, Option<f64>) {
    let table = Soil::new(TABLE_SOIL_MODULUS, TABLE_SOIL_POISSON, density, 0.0)
        .and_then(|soil| {
            System::new(
                Fluid::water(),
                inventory_pipe,
                soil,
                TABLE_CONTACT,
                opts.model,
                opts.contact_mode,
            )
        })
        .ok();
    (
        leak_band_speed_of(sys),
        table.as_ref().and_then(leak_band_speed_of),
    )
}

/// The geological units and soil field of the network `opts` generates (`None` without
/// units): the units' means, for comparisons with the truth.
pub fn geology(opts: &SynthOptions) -> Option<field::Geology> {
    let cols = ((opts.segments as f64).sqrt().ceil() as usize).max(2);
    (opts.units > 0).then(|| {
        let sites: Vec<(f64, f64)> = (0..opts.segments)
            .map(|i| slot_midpoint(opts, cols, i))
            .collect();
        field::Geology::draw(
            crate::seed::derive(opts.seed, GEOLOGY_SEED_STREAM),
            opts.units,
            &sites,
            opts.correlation_length_m,
        )
    })
}

/// Generate a network. Deterministic for given options.
pub fn generate(opts: &SynthOptions) -> Vec<SynthSegment> {
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let mut out = Vec::with_capacity(opts.segments);
    // Streets: a grid of blocks 120 m × 90 m; segment i runs along a block edge.
    let cols = ((opts.segments as f64).sqrt().ceil() as usize).max(2);
    // Zones: a soil class and a soil per zone, and the per-segment scatter, from their own
    // stream, so that networks without zones are unchanged.
    let mut zone_rng = ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, ZONE_SEED_STREAM));
    let zone_soils: Vec<(SoilClass, f64, f64)> = (0..opts.zones)
        .map(|_| {
            let class = SOILS[zone_rng.gen_range(0..SOILS.len())];
            let e = log_uniform(&mut zone_rng, class.1 .0, class.1 .1);
            let nu = zone_rng.gen_range(class.2 .0..class.2 .1);
            (class, e, nu)
        })
        .collect();
    // Geological units and their soil field (P78), also from their own streams.
    let geology = geology(opts);
    let mut pipe_soil_rng =
        ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, PIPE_SOIL_SEED_STREAM));
    // The true system of each segment, its true material and its outlier's index, for the
    // second campaign.
    let mut states: Vec<TrueState> = Vec::with_capacity(opts.segments);
    let mut i = 0usize;
    let mut attempts = 0usize;
    while out.len() < opts.segments && attempts < opts.segments * 20 {
        attempts += 1;
        let material = pick_material(&mut rng);
        let sz = sizes(material)[rng.gen_range(0..sizes(material).len())];
        let (mut soil_type, e_r, nu_r, rho_r) = SOILS[rng.gen_range(0..SOILS.len())];
        let mut e = log_uniform(&mut rng, e_r.0, e_r.1);
        let mut nu = rng.gen_range(nu_r.0..nu_r.1);
        let mut rho = rng.gen_range(rho_r.0..rho_r.1).round();
        // Zone of segment i: contiguous blocks of the street grid (eq. P67 for its soil).
        let zone = (!zone_soils.is_empty()).then(|| i * zone_soils.len() / opts.segments.max(1));
        if let Some(z) = zone {
            let (class, ez, nuz) = zone_soils[z];
            soil_type = class.0;
            e = ez * 10f64.powf(opts.zone_scatter.0 * normal(&mut zone_rng));
            nu = (nuz + opts.zone_scatter.1 * normal(&mut zone_rng)).clamp(0.0, ZONE_NU_MAX);
            rho = zone_rng.gen_range(class.3 .0..class.3 .1).round();
        }
        // Unit of segment i and its soil from the field at the slot's midpoint (P78).
        let unit = geology.as_ref().map(|g| {
            let at = slot_midpoint(opts, cols, i);
            let class = g.units[g.unit_at(at)].class;
            rho = pipe_soil_rng.gen_range(class.3 .0..class.3 .1).round();
            let (u, eu, nuu) = g.pipe_soil(at, rho, &mut pipe_soil_rng);
            soil_type = class.0;
            (e, nu) = (eu, nuu);
            u
        });
        let xi = rng.gen::<f64>();
        let pipe = pipe_of(material, &sz);
        let soil = Soil::new(e, nu, rho, 0.0).expect("soil classes are valid");
        let mut sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            xi,
            opts.model,
            opts.contact_mode,
        )
        .expect("valid system");
        let hidden = opts.hidden_effect.and_then(|(eff, lo, hi)| {
            // Only drawn when a hidden effect is asked for, so networks without one do not
            // change with this option.
            if opts.hidden_fraction < 1.0 && rng.gen::<f64>() >= opts.hidden_fraction {
                return None;
            }
            let v = if eff == Effect::AirInWater {
                log_uniform(&mut rng, lo.max(1e-7), hi)
            } else {
                rng.gen_range(lo..hi)
            };
            Some((eff, v))
        });
        // Drawn for every segment (the same stream whatever the material), applied only where
        // the material can have it: a plastic wall does not thin.
        let hidden = hidden.filter(|(eff, _)| eff.applies_to(material));
        if let Some((eff, v)) = hidden {
            sys = eff.apply(&sys, v).expect("hidden effect in range");
        }
        let defect = if rng.gen::<f64>() < opts.defect_fraction {
            match rng.gen_range(0..4) {
                0 => Defect::Outlier,
                1 => Defect::UnitMixUp,
                2 => Defect::WrongMaterial,
                _ => Defect::TooFew,
            }
        } else {
            Defect::None
        };
        let m = if defect == Defect::TooFew {
            1
        } else {
            rng.gen_range(4..=8)
        };
        let mut band = band_hz(material);
        band.1 = band.1.min(0.45 * pipe.ring_frequency_hz());
        let freqs = frequencies(&mut rng, band, m);
        let mut meas = match measure(&sys, &freqs, &mut rng) {
            Some(v) => v,
            None => continue, // the forward model fails there (e.g. grazing): draw again
        };
        let mut inv_material = material;
        let mut outlier = None;
        match defect {
            Defect::Outlier => {
                let j = rng.gen_range(0..meas.len());
                meas[j].k_re *= 1.25;
                outlier = Some(j);
            }
            Defect::UnitMixUp => {
                for x in &mut meas {
                    x.attenuation *= crate::units::DB_PER_NP;
                    x.attenuation_std *= crate::units::DB_PER_NP;
                }
            }
            Defect::WrongMaterial => {
                inv_material = if material.is_plastic() {
                    Material::DuctileIron
                } else {
                    Material::Pvc
                };
            }
            _ => {}
        }
        // Keep the inventory size valid for the (possibly wrong) material.
        let sz_inv = if inv_material == material {
            sz
        } else {
            sizes(inv_material)[0]
        };
        let ((x0, y0), (x1, y1)) = slot_ends(opts, cols, i);
        let mid = (
            (x0 + x1) / 2.0 + rng.gen_range(-3.0..3.0),
            (y0 + y1) / 2.0 + rng.gen_range(-3.0..3.0),
        );
        let geometry = vec![(x0, y0), mid, (x1, y1)];
        let length_m = geometry
            .windows(2)
            .map(|w| ((w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt())
            .sum();
        let (leak_band_speed, table_leak_band_speed) =
            truth_speeds(opts, &sys, pipe_of(inv_material, &sz_inv), rho);
        out.push(SynthSegment {
            id: format!("WM{:05}", 10001 + i),
            material: inv_material,
            size: sz_inv,
            soil_type,
            soil_density: rho,
            soil_modulus: e,
            soil_poisson: nu,
            contact: xi,
            hidden,
            defect,
            measurements: meas,
            geometry,
            length_m,
            install_year: if material.is_plastic() {
                rng.gen_range(1975..2020)
            } else {
                rng.gen_range(1890..1985)
            },
            soil_zone: zone.map(zone_name),
            zone_soil: zone.map(|z| (zone_soils[z].1, zone_soils[z].2)),
            soil_label: soil_type,
            unit,
            measured: true,
            leak_band_speed,
            table_leak_band_speed,
            second: None,
        });
        states.push(TrueState {
            sys,
            material,
            outlier,
        });
        i += 1;
    }
    keep_measured_fraction(opts, &mut out);
    mislabel(opts, geology.as_ref(), &mut out);
    if opts.campaigns >= 2 {
        second_campaign(opts, &mut out, &states);
    }
    out
}

/// What the second campaign needs of a generated segment that its record does not hold.
struct TrueState {
    /// The true system (soil, contact, hidden effect) at the first campaign.
    sys: System,
    /// The true material (the inventory's may be wrong).
    material: Material,
    /// Index of the first campaign's outlier, if the segment has that defect.
    outlier: Option<usize>,
}

/// Attempts at drawing a change the forward model can solve at the segment's frequencies
/// before the pipe is left unchanged (a softer soil can bring the shear speed close to the
/// pipe's, where no bound wave exists).
const CHANGE_ATTEMPTS: usize = 50;

/// Measure every measured segment again a year later, at the same frequencies with fresh noise
/// (its own stream), after changing exactly `round(F m)` of the m measured pipes, chosen at
/// random. The first campaign's measurements are untouched.
fn second_campaign(opts: &SynthOptions, segments: &mut [SynthSegment], states: &[TrueState]) {
    let mut noise =
        ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, SECOND_NOISE_SEED_STREAM));
    let mut change_rng =
        ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, CHANGE_SEED_STREAM));
    let measured: Vec<usize> = (0..segments.len())
        .filter(|&k| segments[k].measured)
        .collect();
    let mut changed = vec![false; segments.len()];
    for c in field::choose(
        &mut change_rng,
        measured.len(),
        field::count_of(opts.changed_fraction, measured.len()),
    ) {
        changed[measured[c]] = true;
    }
    for &k in &measured {
        let (seg, st) = (&mut segments[k], &states[k]);
        let freqs: Vec<f64> = seg.measurements.iter().map(|m| m.frequency_hz).collect();
        let Some(before) = noiseless(&st.sys, &freqs) else {
            continue; // cannot happen: the first campaign was measured from it
        };
        let mut after = (Change::None, None, st.sys, before.clone());
        if changed[k] {
            for _ in 0..CHANGE_ATTEMPTS {
                let (change, value) = draw_change(&mut change_rng, st);
                let Some(sys) = apply_change(&st.sys, change, value) else {
                    continue;
                };
                if let Some(kb) = noiseless(&sys, &freqs) {
                    after = (change, Some(value), sys, kb);
                    break;
                }
            }
        }
        let (change, change_value, sys_after, k_after) = after;
        let mut meas = with_noise(&freqs, &k_after, &mut noise);
        repeat_defect(seg.defect, st.outlier, &mut meas);
        seg.second = Some(SecondCampaign {
            change,
            change_value,
            measurements: meas,
            leak_band_speed_after: if change == Change::None {
                seg.leak_band_speed
            } else {
                leak_band_speed_of(&sys_after)
            },
            change_z: change_z(&before, &k_after),
        });
    }
}

/// The first campaign's measurement defect again in the second: the outlier at the same
/// frequency (a wrong sensor spacing in the records), the attenuation in dB/m (a spreadsheet's
/// habit). A wrong inventory material stays in the inventory; a single frequency stays single.
fn repeat_defect(defect: Defect, outlier: Option<usize>, meas: &mut [SynthMeasurement]) {
    match defect {
        Defect::Outlier => {
            if let Some(m) = outlier.and_then(|j| meas.get_mut(j)) {
                m.k_re *= 1.25;
            }
        }
        Defect::UnitMixUp => {
            for x in meas {
                x.attenuation *= crate::units::DB_PER_NP;
                x.attenuation_std *= crate::units::DB_PER_NP;
            }
        }
        _ => {}
    }
}

/// Smallest and largest |log10| step of E_m of a `soil_change`, decades: 0.03–0.3 decade
/// (7 %–100 %), up or down with equal chance. A season's drying or wetting moves a clay's
/// stiffness by tens of per cent and freezing by far more; below 0.03 decade the change is
/// lost in the zone scatter of 0.04 decade (model §7.11).
pub const SOIL_CHANGE_DECADES: (f64, f64) = (0.03, 0.3);
/// Range of the free-air fraction φ that entered the water, log-uniform, at the default line
/// pressure of 4 bar absolute: 1e-5 (air drawn in at a repair; Wood's equation P60–P61 takes
/// about 5 % off the water's bulk modulus, 1–3 % off the leak-band speed of an iron pipe and
/// under 1 % off a plastic one, whose speed the wall sets) to 1e-3 (a main left with an air
/// pocket: half the speed of an iron pipe, 15 % off a plastic one). Log-uniform because air
/// contents spread over decades; the range reaches below the detectable so that some changes
/// are small.
pub const CHANGE_AIR_RANGE: (f64, f64) = (1e-5, 1e-3);
/// Range of the wall ratio h/h₀ after thinning (eq. P62): 0.9 is a tenth of the wall lost in
/// a year of aggressive corrosion or graphitisation, 0.6 a pipe near its failure.
pub const CHANGE_WALL_RATIO: (f64, f64) = (0.6, 0.9);
/// Range of the rise of the wall loss factor η_p (eq. P9): 0.01 (small, near the typical
/// iron value, hard to see at 5 % noise on α) to 0.1 (joints and lining degraded).
pub const CHANGE_PIPE_LOSS_RISE: (f64, f64) = (0.01, 0.1);

/// Draw a change of the pipe `st` and its value, uniformly among the causes its true material
/// can have (a plastic wall does not thin).
fn draw_change<R: Rng + ?Sized>(rng: &mut R, st: &TrueState) -> (Change, f64) {
    let causes: &[Change] = if Effect::WallThinning.applies_to(st.material) {
        &[
            Change::SoilChange,
            Change::AirInWater,
            Change::WallThinning,
            Change::PipeLoss,
        ]
    } else {
        &[Change::SoilChange, Change::AirInWater, Change::PipeLoss]
    };
    let change = causes[rng.gen_range(0..causes.len())];
    let value = match change {
        Change::SoilChange => {
            let step = rng.gen_range(SOIL_CHANGE_DECADES.0..SOIL_CHANGE_DECADES.1);
            let sign = if rng.gen::<bool>() { 1.0 } else { -1.0 };
            let (lo, hi) = crate::invert::problem::E_BOUNDS;
            (st.sys.soil.youngs_modulus * 10f64.powf(sign * step)).clamp(lo, hi)
        }
        Change::AirInWater => log_uniform(rng, CHANGE_AIR_RANGE.0, CHANGE_AIR_RANGE.1),
        Change::WallThinning => rng.gen_range(CHANGE_WALL_RATIO.0..CHANGE_WALL_RATIO.1),
        Change::PipeLoss => {
            let upper = Effect::PipeLoss.parameter().map_or(0.3, |p| p.upper);
            (st.sys.pipe.loss_factor
                + rng.gen_range(CHANGE_PIPE_LOSS_RISE.0..CHANGE_PIPE_LOSS_RISE.1))
            .min(upper)
        }
        Change::None => 0.0,
    };
    (change, value)
}

/// `sys` after `change` to `value`, through the effects the hidden effects use (model §8);
/// `None` if the value is out of the model's range.
fn apply_change(sys: &System, change: Change, value: f64) -> Option<System> {
    match change {
        Change::None => Some(*sys),
        Change::SoilChange => {
            let s = &sys.soil;
            let soil = Soil::new(value, s.poisson, s.density, s.loss_factor).ok()?;
            Some(System { soil, ..*sys })
        }
        Change::AirInWater => Effect::AirInWater.apply(sys, value).ok(),
        Change::WallThinning => Effect::WallThinning.apply(sys, value).ok(),
        Change::PipeLoss => Effect::PipeLoss.apply(sys, value).ok(),
    }
}

/// Keep the measurements of exactly `round(F n)` segments, chosen at random (F the measured
/// fraction); the others are marked unmeasured (their measurements stay in the segment, as
/// the ones a later campaign would take).
fn keep_measured_fraction(opts: &SynthOptions, segments: &mut [SynthSegment]) {
    if opts.measured_fraction >= 1.0 {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, MEASURED_SEED_STREAM));
    let keep = field::choose(
        &mut rng,
        segments.len(),
        field::count_of(opts.measured_fraction, segments.len()),
    );
    for s in segments.iter_mut() {
        s.measured = false;
    }
    for k in keep {
        segments[k].measured = true;
    }
}

/// Give exactly `round(F n)` segments, chosen at random, a wrong `soil_label`: the class of
/// another unit (isolated mistakes of the map: a label that exists nearby), or without units
/// another class of [`SOILS`].
fn mislabel(opts: &SynthOptions, geology: Option<&field::Geology>, segments: &mut [SynthSegment]) {
    if opts.wrong_label_fraction <= 0.0 {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, LABEL_SEED_STREAM));
    let mut labels: Vec<&'static str> = match geology {
        Some(g) => g.units.iter().map(|u| u.class.0).collect(),
        None => SOILS.iter().map(|c| c.0).collect(),
    };
    labels.sort_unstable();
    labels.dedup();
    if labels.len() < 2 {
        labels = SOILS.iter().map(|c| c.0).collect();
    }
    let wrong = field::choose(
        &mut rng,
        segments.len(),
        field::count_of(opts.wrong_label_fraction, segments.len()),
    );
    for k in wrong {
        let others: Vec<&'static str> = labels
            .iter()
            .copied()
            .filter(|&l| l != segments[k].soil_type)
            .collect();
        segments[k].soil_label = others[rng.gen_range(0..others.len())];
    }
}
