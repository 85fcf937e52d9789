//! The independent two-campaign generator (`pipewave-lab campaigns`).
//!
//! Each segment is drawn from its own ChaCha8 stream ([`segment_rng`]): a pipe from the lab's
//! catalogue, a soil, a contact coefficient, a frequency plan per campaign, a noise law per
//! campaign and, for a chosen fraction of the segments, one cause of change applied to the
//! second campaign's pipe. The noiseless wavenumbers are roots of pipewave's dispersion relation
//! (docs/model.md P31–P32, `full` model P33, `reciprocal` contact P34) found by its reference
//! continuation (P41–P43); the effects are those of docs/model.md §8 (E2 P9, E3 P60–P61,
//! E4 P62), applied through `pipewave::physics::effects`.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use num_complex::Complex64;
use pipewave::invert::assemble::leak_band_speed_of;
use pipewave::physics::effects::Effect;
use pipewave::physics::{
    solve_curve, ContactMode, Continuation, Fluid, Material, MaterialProps, Model, Pipe, Soil,
    System,
};
use rand::seq::SliceRandom;
use rand::Rng;
use rayon::prelude::*;

use crate::catalogue::{
    draw_contact, draw_wall, pick, sizes, Size, SoilClass, Wall, MATERIAL_SHARES, SOIL_CLASSES,
};
use crate::draw::{log_uniform, network_rng, segment_rng, std_normal, uniform};

/// The earlier campaign's name.
pub const CAMPAIGN_A: &str = "IG-A";
/// The later campaign's name.
pub const CAMPAIGN_B: &str = "IG-B";
/// Lowest frequency of any plan, Hz.
pub const F_MIN_HZ: f64 = 50.0;
/// Highest frequency of any plan, Hz.
pub const F_MAX_HZ: f64 = 1000.0;
/// Share of the pipes whose second campaign is measured at other frequencies.
pub const OTHER_PLAN_FRACTION: f64 = 0.10;
/// Draws of one segment before the generator gives up (a draw is rejected when a root is not
/// clean: near grazing P44, out of validity P7, a growing wave, or no leak-band mean).
pub const MAX_ATTEMPTS: usize = 200;

/// Options of one generated network.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Number of segments (each measured in both campaigns).
    pub segments: usize,
    /// Seed of the ChaCha8 streams.
    pub seed: u64,
    /// Fraction of the segments that changed between the campaigns (round(F·N) of them).
    pub changed_fraction: f64,
}

/// A cause of change between the campaigns, applied to the second campaign's pipe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cause {
    /// The soil's E_m multiplied by a factor, half the time with a shift of ν_m.
    SoilChange,
    /// Free air in the water, volume fraction φ (model §8 E3, P60–P61).
    AirInWater,
    /// Effective wall ratio r_h (model §8 E4, P62); metal and AC pipes only.
    WallThinning,
    /// A raised wall loss factor η_p (model §8 E2, P9).
    PipeLoss,
}

impl Cause {
    /// Every cause.
    pub const ALL: [Cause; 4] = [
        Cause::SoilChange,
        Cause::AirInWater,
        Cause::WallThinning,
        Cause::PipeLoss,
    ];

    /// The name used in truth.csv and by pipewave's `change_effect`.
    pub fn name(self) -> &'static str {
        match self {
            Cause::SoilChange => "soil_change",
            Cause::AirInWater => "air_in_water",
            Cause::WallThinning => "wall_thinning",
            Cause::PipeLoss => "pipe_loss",
        }
    }

    /// Whether a pipe of `material` can have this cause: a polymer wall does not thin.
    pub fn applies_to(self, material: Material) -> bool {
        self != Cause::WallThinning || !is_plastic(material)
    }
}

/// PVC, MDPE and HDPE.
pub fn is_plastic(material: Material) -> bool {
    matches!(material, Material::Pvc | Material::Mdpe | Material::Hdpe)
}

/// A drawn change: its cause, the value truth.csv reports and a description of the draw.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// The cause.
    pub cause: Cause,
    /// truth.csv `change_value`: E_m after (Pa), φ, r_h or η_p after.
    pub value: f64,
    /// What was drawn, e.g. `E_m x0.62; nu_m +0.031`.
    pub detail: String,
}

/// Spacing of a frequency plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Spacing {
    /// Geometric.
    Log,
    /// Arithmetic.
    Linear,
    /// Arithmetic with each point moved by up to ±35 % of the step.
    Jittered,
}

impl Spacing {
    fn name(self) -> &'static str {
        match self {
            Spacing::Log => "log",
            Spacing::Linear => "linear",
            Spacing::Jittered => "jittered",
        }
    }
}

/// The frequencies of one campaign of one segment, ascending, Hz (rounded to 0.1 Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Frequencies, Hz.
    pub frequencies: Vec<f64>,
    /// How they were drawn (`log`, `linear`, `jittered`; for campaign B also `same`,
    /// `shifted xS` or `redrawn <spacing>`).
    pub kind: String,
}

/// The noise law of one campaign of one segment. The stated σ is the σ of the Gaussian draw.
///
/// σ_re(f) = r (1 + e u²) Re k, with u ∈ [−1, 1] the position of f in the campaign's band on a
/// log scale (the band edges are noisier); σ_α(f) = min(√((q α)² + (p σ_re)²), α/4): a relative
/// part plus a floor tied to the phase error, capped at a quarter of α so that a negative
/// attenuation (redrawn, P5 needs α ≥ 0) has probability 3e-5 and the cap leaves the draw
/// Gaussian to that level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseLaw {
    /// r: relative σ of Re k at the band's centre.
    pub rel_re: f64,
    /// e: rise of the relative σ towards the band edges.
    pub edge: f64,
    /// q: relative σ of α.
    pub rel_att: f64,
    /// p: floor of σ_α as a fraction of σ_re.
    pub att_floor: f64,
    /// The campaign's band (lowest, highest frequency), Hz.
    pub band: (f64, f64),
}

impl NoiseLaw {
    pub(crate) fn draw<R: Rng>(rng: &mut R, plan: &Plan) -> Self {
        let f = &plan.frequencies;
        NoiseLaw {
            rel_re: log_uniform(rng, 0.003, 0.03),
            edge: uniform(rng, 0.0, 0.8),
            rel_att: log_uniform(rng, 0.04, 0.25),
            att_floor: uniform(rng, 0.1, 0.5),
            band: (f[0], f[f.len() - 1]),
        }
    }

    /// (σ_re, σ_α) at frequency f for the noiseless wavenumber k (α = −Im k, P2).
    pub fn sigma(&self, f: f64, k: Complex64) -> (f64, f64) {
        let (lo, hi) = self.band;
        let u = if hi > lo {
            2.0 * (f.ln() - lo.ln()) / (hi.ln() - lo.ln()) - 1.0
        } else {
            0.0
        };
        let s_re = self.rel_re * (1.0 + self.edge * u * u) * k.re;
        let alpha = -k.im;
        let s_att = (self.rel_att * alpha)
            .hypot(self.att_floor * s_re)
            .min(0.25 * alpha);
        (s_re, s_att)
    }
}

/// One measured wavenumber of one campaign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Noiseless wavenumber k1 (Im < 0, P1–P2).
    pub k_true: Complex64,
    /// Measured Re k, rad/m.
    pub k_re: f64,
    /// Measured attenuation α, Np/m (P5).
    pub attenuation: f64,
    /// Stated (true) σ of k_re.
    pub k_re_std: f64,
    /// Stated (true) σ of α.
    pub attenuation_std: f64,
}

/// One generated segment with both campaigns and its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Segment id.
    pub id: String,
    /// Material.
    pub material: Material,
    /// Catalogue size.
    pub size: Size,
    /// Wall properties (written as overrides).
    pub wall: Wall,
    /// Soil class name.
    pub soil_type: &'static str,
    /// Length, m.
    pub length_m: f64,
    /// Install year.
    pub install_year: u32,
    /// The system of campaign A.
    pub before: System,
    /// The system of campaign B (equal to `before` when unchanged).
    pub after: System,
    /// The change, if any.
    pub change: Option<Change>,
    /// Campaign A's plan.
    pub plan_a: Plan,
    /// Campaign B's plan.
    pub plan_b: Plan,
    /// Campaign A's noise law.
    pub noise_a: NoiseLaw,
    /// Campaign B's noise law.
    pub noise_b: NoiseLaw,
    /// Campaign A's rows.
    pub rows_a: Vec<Row>,
    /// Campaign B's rows.
    pub rows_b: Vec<Row>,
    /// Leak-band speed before (noiseless), m/s.
    pub speed_before: f64,
    /// Leak-band speed after (noiseless), m/s.
    pub speed_after: f64,
    /// Detectability z (P93).
    pub z: f64,
    /// Draws rejected before this one.
    pub rejected: usize,
}

impl Segment {
    /// True when both campaigns share their frequencies.
    pub fn shared_frequencies(&self) -> bool {
        self.plan_a.frequencies == self.plan_b.frequencies
    }

    /// The change's name, `none` when unchanged.
    pub fn effect_name(&self) -> &'static str {
        self.change.as_ref().map_or("none", |c| c.cause.name())
    }
}

/// The buried pipe of a drawn wall, size, soil and contact ξ in water, with the full model
/// (model §3, P13) and reciprocal contact, and the top of its frequency plan: 0.9 of the
/// validity limit (P7), at most [`F_MAX_HZ`]. None when that leaves a band narrower than
/// 2.5 × [`F_MIN_HZ`].
pub fn buried_pipe(
    wall: &Wall,
    size: &Size,
    soil: Soil,
    contact: f64,
) -> Result<Option<(System, f64)>> {
    let props = MaterialProps {
        youngs_modulus: wall.youngs,
        poisson: wall.poisson,
        density: wall.density,
        loss_factor: wall.loss,
    };
    let pipe = Pipe::from_outside_diameter(props, size.od_mm / 1000.0, size.wall_mm / 1000.0)?;
    let fluid = Fluid::water();
    let system = System::new(
        fluid,
        pipe,
        soil,
        contact,
        Model::Full,
        ContactMode::Reciprocal,
    )?;
    let f_max = (0.9 * validity_limit_hz(&pipe, &fluid)).min(F_MAX_HZ);
    Ok((f_max >= 2.5 * F_MIN_HZ).then_some((system, f_max)))
}

/// Highest frequency the membrane-shell model is valid at (P7), Hz: half the ring frequency
/// and half the first higher fluid mode's cut-on, whichever is lower.
pub fn validity_limit_hz(pipe: &Pipe, fluid: &Fluid) -> f64 {
    let f_ring = pipe.ring_frequency_hz();
    let f_cut = 3.8317 * fluid.sound_speed() / (2.0 * std::f64::consts::PI * pipe.mean_radius);
    0.5 * f_ring.min(f_cut)
}

/// A plan of n points between lo and hi with the given spacing, rounded to 0.1 Hz.
fn plan_points<R: Rng>(rng: &mut R, n: usize, lo: f64, hi: f64, spacing: Spacing) -> Vec<f64> {
    let t = |j: usize| j as f64 / (n - 1) as f64;
    let raw: Vec<f64> = match spacing {
        Spacing::Log => (0..n).map(|j| lo * (hi / lo).powf(t(j))).collect(),
        Spacing::Linear => (0..n).map(|j| lo + (hi - lo) * t(j)).collect(),
        Spacing::Jittered => {
            let step = (hi - lo) / (n - 1) as f64;
            (0..n)
                .map(|j| {
                    let x = lo + step * j as f64;
                    if j == 0 || j == n - 1 {
                        x
                    } else {
                        x + uniform(rng, -0.35, 0.35) * step
                    }
                })
                .collect()
        }
    };
    raw.iter().map(|f| (f * 10.0).round() / 10.0).collect()
}

/// A campaign's plan: 5–12 points in a band drawn per segment within 50 Hz – `f_max`: the low
/// end log-uniform on 50–250 Hz, the band 2.5–10 times as wide, log-spaced (45 %), linear
/// (40 %) or jittered linear (15 %).
pub(crate) fn draw_plan<R: Rng>(rng: &mut R, f_max: f64) -> Plan {
    let n = rng.gen_range(5..=12);
    let mut lo = log_uniform(rng, F_MIN_HZ, 250.0);
    let hi = (lo * log_uniform(rng, 2.5, 10.0)).min(f_max);
    if hi < 2.5 * lo {
        lo = (hi / 2.5).max(F_MIN_HZ);
    }
    let u = rng.gen::<f64>();
    let spacing = if u < 0.45 {
        Spacing::Log
    } else if u < 0.85 {
        Spacing::Linear
    } else {
        Spacing::Jittered
    };
    Plan {
        frequencies: plan_points(rng, n, lo, hi, spacing),
        kind: spacing.name().to_string(),
    }
}

/// Campaign B's plan: A's for 90 % of the pipes; for the others half the time A's shifted by
/// a factor 1.04–1.2 up or down (the other way if that leaves 50 Hz – `f_max`, redrawn if both
/// do), otherwise a fresh plan.
fn draw_plan_b<R: Rng>(rng: &mut R, a: &Plan, f_max: f64) -> Plan {
    if rng.gen::<f64>() >= OTHER_PLAN_FRACTION {
        return Plan {
            frequencies: a.frequencies.clone(),
            kind: "same".into(),
        };
    }
    if rng.gen::<f64>() < 0.5 {
        let s = log_uniform(rng, 1.04, 1.2);
        let up = rng.gen::<bool>();
        for factor in if up { [s, 1.0 / s] } else { [1.0 / s, s] } {
            let f: Vec<f64> = a
                .frequencies
                .iter()
                .map(|f| (f * factor * 10.0).round() / 10.0)
                .collect();
            if f[0] >= F_MIN_HZ && f[f.len() - 1] <= f_max {
                return Plan {
                    frequencies: f,
                    kind: format!("shifted x{factor:.4}"),
                };
            }
        }
    }
    let fresh = draw_plan(rng, f_max);
    Plan {
        kind: format!("redrawn {}", fresh.kind),
        ..fresh
    }
}

/// Draw the change of a pipe of `material` in `sys`: a cause among those its material can
/// have (uniformly), at a size of its own law, and the changed system.
fn draw_change<R: Rng>(rng: &mut R, sys: &System, material: Material) -> Result<(Change, System)> {
    let causes: Vec<Cause> = Cause::ALL
        .into_iter()
        .filter(|c| c.applies_to(material))
        .collect();
    let cause = *causes.choose(rng).expect("every material has a cause");
    Ok(match cause {
        Cause::SoilChange => {
            // Drying or freezing stiffens, wetting softens: E_m × 1.2–3 or ÷ 1.2–3
            // (log-uniform), and half the time ν_m moves by up to ±0.05 (kept in 0.2–0.49).
            let mag = log_uniform(rng, 1.2, 3.0);
            let factor = if rng.gen::<bool>() { mag } else { 1.0 / mag };
            let dnu = if rng.gen::<bool>() {
                uniform(rng, -0.05, 0.05)
            } else {
                0.0
            };
            let s = sys.soil;
            let nu = (s.poisson + dnu).clamp(0.2, 0.49);
            let soil = Soil::new(s.youngs_modulus * factor, nu, s.density, s.loss_factor)?;
            let detail = format!("E_m x{factor:.4}; nu_m {:+.4}", nu - s.poisson);
            (
                Change {
                    cause,
                    value: soil.youngs_modulus,
                    detail,
                },
                System { soil, ..*sys },
            )
        }
        Cause::AirInWater => {
            // φ log-uniform 2e-5 – 2e-3 at 4 bar absolute, isothermal (P60–P61).
            let phi = log_uniform(rng, 2e-5, 2e-3);
            let after = Effect::AirInWater.apply(sys, phi)?;
            (
                Change {
                    cause,
                    value: phi,
                    detail: format!("phi {phi:.3e}"),
                },
                after,
            )
        }
        Cause::WallThinning => {
            // r_h uniform on 0.55–0.92 (P62).
            let r = uniform(rng, 0.55, 0.92);
            let after = Effect::WallThinning.apply(sys, r)?;
            (
                Change {
                    cause,
                    value: r,
                    detail: format!("r_h {r:.4}"),
                },
                after,
            )
        }
        Cause::PipeLoss => {
            // η_p raised by a log-uniform 0.01–0.12 (P9), at most 0.3.
            let eta = (sys.pipe.loss_factor + log_uniform(rng, 0.01, 0.12)).min(0.3);
            let after = Effect::PipeLoss.apply(sys, eta)?;
            (
                Change {
                    cause,
                    value: eta,
                    detail: format!("eta_p {:.4} -> {eta:.4}", sys.pipe.loss_factor),
                },
                after,
            )
        }
    })
}

/// Noiseless wavenumbers of `sys` at `frequencies` (Hz) by the reference continuation
/// (P41–P43), or None unless every root is clean (no growing wave, not near grazing P44, within
/// validity P7, slower than the fluid) and decays (α > 0).
pub fn noiseless(sys: &System, frequencies: &[f64]) -> Option<Vec<Complex64>> {
    let omegas: Vec<f64> = frequencies
        .iter()
        .map(|f| 2.0 * std::f64::consts::PI * f)
        .collect();
    solve_curve(sys, &omegas, Continuation::default())
        .into_iter()
        .map(|r| {
            r.ok()
                .filter(|root| root.flags.is_clean() && root.k1.im < 0.0 && root.k1.re > 0.0)
                .map(|root| root.k1)
        })
        .collect()
}

/// Measured rows of one campaign: k_re and α each with an independent Gaussian error of the
/// stated σ (P5: α ≥ 0; a negative α, probability ≤ 3e-5, is drawn again).
pub(crate) fn measure<R: Rng>(
    rng: &mut R,
    plan: &Plan,
    k: &[Complex64],
    law: &NoiseLaw,
) -> Option<Vec<Row>> {
    let mut rows = Vec::with_capacity(k.len());
    for (&f, &kt) in plan.frequencies.iter().zip(k) {
        let (s_re, s_att) = law.sigma(f, kt);
        // pipewave refuses a σ below 1e-6 k_re (docs/interface.md); such a draw is rejected.
        if s_att < 1e-5 * kt.re {
            return None;
        }
        let k_re = kt.re + s_re * std_normal(rng);
        let mut att = -kt.im + s_att * std_normal(rng);
        while att < 0.0 {
            att = -kt.im + s_att * std_normal(rng);
        }
        rows.push(Row {
            frequency_hz: f,
            k_true: kt,
            k_re,
            attenuation: att,
            k_re_std: s_re,
            attenuation_std: s_att,
        });
    }
    Some(rows)
}

/// Detectability z of P93 at the frequencies `f` of campaign A: k_a the noiseless wavenumbers
/// before, k_b after (at the same frequencies), σ of each campaign from its own law.
pub fn detectability(
    f: &[f64],
    k_a: &[Complex64],
    k_b: &[Complex64],
    law_a: &NoiseLaw,
    law_b: &NoiseLaw,
) -> f64 {
    let mut sum = 0.0;
    for ((&fi, &ka), &kb) in f.iter().zip(k_a).zip(k_b) {
        let (sra, saa) = law_a.sigma(fi, ka);
        let (srb, sab) = law_b.sigma(fi, kb);
        let d_re = kb.re - ka.re;
        let d_att = (-kb.im) - (-ka.im);
        sum += d_re * d_re / (sra * sra + srb * srb) + d_att * d_att / (saa * saa + sab * sab);
    }
    sum.sqrt()
}

/// One draw of segment `index`; None when a root or the leak-band mean is not clean.
fn try_segment<R: Rng>(rng: &mut R, index: usize, changed: bool) -> Result<Option<Segment>> {
    let material = pick(rng, &MATERIAL_SHARES);
    let size = *sizes(material).choose(rng).expect("catalogue");
    let wall = draw_wall(rng, material);
    let class: SoilClass = pick(rng, &SOIL_CLASSES);
    let soil = Soil::new(
        log_uniform(rng, class.youngs.0, class.youngs.1),
        uniform(rng, class.poisson.0, class.poisson.1),
        uniform(rng, class.density.0, class.density.1),
        0.0,
    )?;
    let contact = draw_contact(rng);
    let length_m = (log_uniform(rng, 40.0, 600.0) * 10.0).round() / 10.0;
    let install_year = rng.gen_range(match material {
        Material::CastIron => 1890..=1965,
        Material::AsbestosCement => 1945..=1985,
        Material::Steel => 1930..=1995,
        Material::DuctileIron => 1965..=2020,
        _ => 1970..=2022,
    });
    let Some((before, f_max)) = buried_pipe(&wall, &size, soil, contact)? else {
        return Ok(None);
    };
    let plan_a = draw_plan(rng, f_max);
    let plan_b = draw_plan_b(rng, &plan_a, f_max);
    let (change, after) = if changed {
        let (c, s) = draw_change(rng, &before, material)?;
        (Some(c), s)
    } else {
        (None, before)
    };
    let noise_a = NoiseLaw::draw(rng, &plan_a);
    let noise_b = NoiseLaw::draw(rng, &plan_b);

    let Some(k_a) = noiseless(&before, &plan_a.frequencies) else {
        return Ok(None);
    };
    let Some(k_b) = noiseless(&after, &plan_b.frequencies) else {
        return Ok(None);
    };
    // The after-change curve at A's frequencies, for z when the plans differ.
    let k_b_at_a = if plan_a.frequencies == plan_b.frequencies {
        k_b.clone()
    } else {
        match noiseless(&after, &plan_a.frequencies) {
            Some(k) => k,
            None => return Ok(None),
        }
    };
    let Some(speed_before) = leak_band_speed_of(&before) else {
        return Ok(None);
    };
    let speed_after = if changed {
        match leak_band_speed_of(&after) {
            Some(v) => v,
            None => return Ok(None),
        }
    } else {
        speed_before
    };
    let Some(rows_a) = measure(rng, &plan_a, &k_a, &noise_a) else {
        return Ok(None);
    };
    let Some(rows_b) = measure(rng, &plan_b, &k_b, &noise_b) else {
        return Ok(None);
    };
    let z = detectability(&plan_a.frequencies, &k_a, &k_b_at_a, &noise_a, &noise_b);
    Ok(Some(Segment {
        id: format!("LAB{:05}", index + 1),
        material,
        size,
        wall,
        soil_type: class.name,
        length_m,
        install_year,
        before,
        after,
        change,
        plan_a,
        plan_b,
        noise_a,
        noise_b,
        rows_a,
        rows_b,
        speed_before,
        speed_after,
        z,
        rejected: 0,
    }))
}

/// Draw segment `index` (redrawing until clean, at most [`MAX_ATTEMPTS`] times).
pub fn draw_segment(seed: u64, index: usize, changed: bool) -> Result<Segment> {
    let mut rng = segment_rng(seed, index);
    for attempt in 0..MAX_ATTEMPTS {
        if let Some(mut s) = try_segment(&mut rng, index, changed)? {
            s.rejected = attempt;
            return Ok(s);
        }
    }
    bail!("segment {index}: no clean draw in {MAX_ATTEMPTS} attempts")
}

/// Which segments changed: exactly round(F·N), chosen by a shuffle of the network's stream.
pub fn changed_set(opts: &Options) -> Vec<bool> {
    let n = opts.segments;
    let m = ((opts.changed_fraction * n as f64).round() as usize).min(n);
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut network_rng(opts.seed));
    let mut changed = vec![false; n];
    for &i in &idx[..m] {
        changed[i] = true;
    }
    changed
}

/// Generate a network (in parallel; the result does not depend on the number of threads).
pub fn generate(opts: &Options) -> Result<Vec<Segment>> {
    if !(0.0..=1.0).contains(&opts.changed_fraction) {
        bail!(
            "--changed-fraction must be within 0-1, got {}",
            opts.changed_fraction
        );
    }
    if opts.segments == 0 {
        bail!("--segments must be at least 1");
    }
    let changed = changed_set(opts);
    (0..opts.segments)
        .into_par_iter()
        .map(|i| draw_segment(opts.seed, i, changed[i]))
        .collect()
}

/// The measurement date of segment `index` in campaign A (May 2025) or B (June 2026).
pub fn measured_on(index: usize, campaign_b: bool) -> String {
    if campaign_b {
        format!("2026-06-{:02}", 1 + index % 25)
    } else {
        format!("2025-05-{:02}", 5 + index % 20)
    }
}

/// segments.csv in pipewave's import format (docs/interface.md), with the drawn wall as
/// overrides.
pub fn segments_csv(segs: &[Segment]) -> String {
    let mut s = String::from(
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,\
         pipe_youngs_modulus_pa,pipe_poisson,pipe_density_kg_m3,pipe_loss_factor,length_m,\
         soil_type,install_year\n",
    );
    for g in segs {
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            g.id,
            g.material.code(),
            g.size.od_mm,
            g.size.wall_mm,
            g.before.soil.density,
            g.wall.youngs,
            g.wall.poisson,
            g.wall.density,
            g.wall.loss,
            g.length_m,
            g.soil_type,
            g.install_year
        )
        .expect("write to string");
    }
    s
}

/// measurements.csv: one row per segment, campaign and frequency (docs/interface.md).
pub fn measurements_csv(segs: &[Segment]) -> String {
    let mut s = String::from(
        "segment_id,campaign,measured_on,frequency_hz,k_re_rad_per_m,attenuation_np_per_m,\
         k_re_std,attenuation_std\n",
    );
    for (i, g) in segs.iter().enumerate() {
        for (campaign, rows, b) in [
            (CAMPAIGN_A, &g.rows_a, false),
            (CAMPAIGN_B, &g.rows_b, true),
        ] {
            let date = measured_on(i, b);
            for r in rows {
                writeln!(
                    s,
                    "{},{},{},{},{},{},{},{}",
                    g.id,
                    campaign,
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
    }
    s
}

/// The columns of truth.csv, in order.
pub const TRUTH_COLUMNS: [&str; 25] = [
    "segment_id",
    "material",
    "soil_youngs_modulus_pa",
    "soil_poisson",
    "contact",
    "change_effect",
    "change_value",
    "leak_band_speed_before_m_per_s",
    "leak_band_speed_after_m_per_s",
    "change_z",
    "change_detail",
    "soil_youngs_modulus_after_pa",
    "soil_poisson_after",
    "soil_density_kg_m3",
    "soil_type",
    "outer_diameter_mm",
    "wall_thickness_mm",
    "pipe_loss_factor",
    "plan_a",
    "plan_b",
    "n_frequencies_a",
    "n_frequencies_b",
    "shared_frequencies",
    "k_re_rel_std_a",
    "k_re_rel_std_b",
];

/// truth.csv: the drawn soil before the change, the change and the noiseless leak-band speeds
/// and z (P93).
pub fn truth_csv(segs: &[Segment]) -> String {
    let mut s = TRUTH_COLUMNS.join(",");
    s.push('\n');
    for g in segs {
        let (value, detail) = g
            .change
            .as_ref()
            .map_or((String::new(), String::new()), |c| {
                (c.value.to_string(), c.detail.clone())
            });
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},\"{}\",{},{},{},{},{},{},{},{},\"{}\",{},{},{},{},{}",
            g.id,
            g.material.code(),
            g.before.soil.youngs_modulus,
            g.before.soil.poisson,
            g.before.contact,
            g.effect_name(),
            value,
            g.speed_before,
            g.speed_after,
            g.z,
            detail,
            g.after.soil.youngs_modulus,
            g.after.soil.poisson,
            g.before.soil.density,
            g.soil_type,
            g.size.od_mm,
            g.size.wall_mm,
            g.wall.loss,
            g.plan_a.kind,
            g.plan_b.kind,
            g.plan_a.frequencies.len(),
            g.plan_b.frequencies.len(),
            u8::from(g.shared_frequencies()),
            g.noise_a.rel_re,
            g.noise_b.rel_re
        )
        .expect("write to string");
    }
    s
}

/// Counts of a generated network, for the summary and the tests.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Segments.
    pub segments: usize,
    /// Unchanged segments.
    pub unchanged: usize,
    /// Changed segments.
    pub changed: usize,
    /// Changed with z ≥ 5.
    pub changed_z5: usize,
    /// Per cause: (name, changed, of which z ≥ 5).
    pub by_cause: Vec<(&'static str, usize, usize)>,
    /// Changed pipes per z class 0–2, 2–3, 3–5, ≥ 5.
    pub z_classes: [usize; 4],
    /// Segments whose campaigns do not share frequencies.
    pub other_plans: usize,
    /// Draws rejected (not clean) in all.
    pub rejected: usize,
}

/// The z class of a change: 0 for z < 2, 1 for 2–3, 2 for 3–5, 3 for ≥ 5.
pub fn z_class(z: f64) -> usize {
    if z >= 5.0 {
        3
    } else if z >= 3.0 {
        2
    } else if z >= 2.0 {
        1
    } else {
        0
    }
}

/// Count a network.
pub fn summarize(segs: &[Segment]) -> Summary {
    let mut s = Summary {
        segments: segs.len(),
        by_cause: Cause::ALL.iter().map(|c| (c.name(), 0, 0)).collect(),
        ..Summary::default()
    };
    for g in segs {
        s.rejected += g.rejected;
        if !g.shared_frequencies() {
            s.other_plans += 1;
        }
        match &g.change {
            None => s.unchanged += 1,
            Some(c) => {
                s.changed += 1;
                s.z_classes[z_class(g.z)] += 1;
                let row = s
                    .by_cause
                    .iter_mut()
                    .find(|r| r.0 == c.cause.name())
                    .expect("cause row");
                row.1 += 1;
                if g.z >= 5.0 {
                    s.changed_z5 += 1;
                    row.2 += 1;
                }
            }
        }
    }
    s
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{} segments: {} unchanged, {} changed ({} with z >= 5); {} measured at other \
             frequencies in {}; {} draws rejected",
            self.segments,
            self.unchanged,
            self.changed,
            self.changed_z5,
            self.other_plans,
            CAMPAIGN_B,
            self.rejected
        )?;
        writeln!(
            f,
            "changed by z: 0-2 {}, 2-3 {}, 3-5 {}, >=5 {}",
            self.z_classes[0], self.z_classes[1], self.z_classes[2], self.z_classes[3]
        )?;
        for (name, n, n5) in &self.by_cause {
            writeln!(f, "  {name:<14} {n:>5} changed, {n5:>5} with z >= 5")?;
        }
        Ok(())
    }
}

/// Write segments.csv, measurements.csv and truth.csv into `dir` (created if missing).
pub fn write(dir: &Path, segs: &[Segment]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in [
        ("segments.csv", segments_csv(segs)),
        ("measurements.csv", measurements_csv(segs)),
        ("truth.csv", truth_csv(segs)),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
