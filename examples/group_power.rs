//! Power of four pooled group statistics, compared at the same empirically measured
//! false-alarm rate on clean groups (docs/group-test.md).
//!
//! * `curves [NULL_REPS] [ALT_REPS] [SHRINK]`: the local (score-level) model of a group of 40
//!   members. Member i's one-sided evidence for an effect is the standardised efficient score
//!   Z_i ~ N(δ_i, 1); δ_i = 0 in clean members and m·z_floor in the affected fraction f, where
//!   z_floor is the magnitude at which one segment's own χ̄² test at its level (the diagnosis's
//!   α over 4 candidates) has 50 % power. The four statistics:
//!   - `score_sum`: Σ max(0, Z_i^s)², today's statistic. On real fits the score at the base fit
//!     captures only part of the χ² the refit removes; `SHRINK` (default 1: the local model,
//!     where score and likelihood ratio coincide) scales the affected members' score means
//!     (Z_i^s ~ N(SHRINK·δ_i, 1)) to show what that loss costs.
//!   - `lr_sum`: Σ of the members' likelihood-ratio gains max(0, Z_i)²; null Σ_k C(n,k)2⁻ⁿχ²_k.
//!   - `linear`: the pooled one-direction score Σ Z_i/√n (signed); null N(0, 1).
//!   - `mixture`: the likelihood ratio of "a fraction π of the members carry a common effect
//!     δ" against "none", maximised over π ∈ (0, 1] and δ > 0 (Z_i ≤ 0 enters censored, as the
//!     one-sided statistics only tell that the data pulled the wrong way); null by simulation.
//!
//!   The level is 0.05/(4 effects × 10 groups); every statistic's threshold is the empirical
//!   quantile of NULL_REPS clean groups.
//! * `null [REPS]`: the lr_sum null: simulated tail frequencies against the χ̄² mixture.
//!
//! * `floor [N]`: the one-segment floor of each effect on each material where it applies, from
//!   N segments per pass (two passes).
//! * `groups SEEDS [BASE] [CLEAN_PER_SEED]`: the adopted test (`diagnose`'s member gains and
//!   pooled test) on refitted synthetic groups of 40 members. Per seed, one group per effect
//!   (soil_damping, air_in_water, wall_thinning, pipe_loss), on a material of the synthetic
//!   network's mix where the effect applies, hidden in 20–40 % of the members at 0.8–1.2 × that
//!   material's floor, and CLEAN_PER_SEED clean groups; each tested as one of 8 groups of a run.
//!   Prints per group the detected effect, its p-value, the true effect's rank, a table per
//!   effect and material, and the totals.
//!
//! Run: `cargo run --release --example group_power -- curves 20000 2000`.

use std::collections::BTreeMap;

use pipewave::diagnose::group::{
    member_gains_and_refits, pooled_test, rank_twins_with, DiagnosedMembers,
};
use pipewave::diagnose::stats::sum_chibar_sf;
use pipewave::diagnose::{diagnose_segment, DiagnoseSettings, Diagnosis};
use pipewave::invert::FitResult;
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::stats::normal;
use pipewave::synth::trial::{effect_trial, Trial};
use pipewave::synth::MATERIAL_MIX;
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, Normal};

const N: usize = 40;
/// The per-segment level: the diagnosis's α over 4 candidate effects.
const SEGMENT_LEVEL: f64 = 1e-3 / 4.0;
/// The group level used for the comparison: 0.05 over 4 effects and 10 groups.
const GROUP_LEVEL: f64 = 0.05 / 40.0;

fn std_normal() -> Normal {
    Normal::new(0.0, 1.0).expect("N(0,1)")
}

/// z at which a one-sided χ̄² test at `level` has 50 % power: P(Z > z) = level.
fn z_floor() -> f64 {
    std_normal().inverse_cdf(1.0 - SEGMENT_LEVEL)
}

/// The four statistics of one group from its members' signed z (score-level z: `zs`).
fn statistics(z: &[f64], zs: &[f64], grid: &MixGrid) -> [f64; 4] {
    let score_sum: f64 = zs.iter().map(|v| v.max(0.0).powi(2)).sum();
    let lr_sum: f64 = z.iter().map(|v| v.max(0.0).powi(2)).sum();
    let linear: f64 = z.iter().sum::<f64>() / (z.len() as f64).sqrt();
    [score_sum, lr_sum, linear, grid.mixture_lr(z)]
}

/// Grid for the mixture likelihood ratio.
struct MixGrid {
    deltas: Vec<f64>,
    pis: Vec<f64>,
    /// log(2Φ(−δ)): a member pulling the wrong way (censored at Z ≤ 0).
    log_censored: Vec<f64>,
}

impl MixGrid {
    fn new() -> Self {
        let nd = std_normal();
        let deltas: Vec<f64> = (1..=24).map(|k| 0.25 * k as f64).collect();
        let pis: Vec<f64> = (1..=40).map(|k| k as f64 / 40.0).collect();
        let log_censored = deltas.iter().map(|d| (2.0 * nd.cdf(-d)).ln()).collect();
        MixGrid {
            deltas,
            pis,
            log_censored,
        }
    }

    /// 2·max_{π,δ} Σ log(1 − π + π·w_i(δ)), w_i the member's likelihood ratio at δ.
    fn mixture_lr(&self, z: &[f64]) -> f64 {
        let mut best = 0.0f64;
        let mut w = vec![0.0; z.len()];
        for (d, lc) in self.deltas.iter().zip(&self.log_censored) {
            for (wi, zi) in w.iter_mut().zip(z) {
                *wi = if *zi > 0.0 {
                    (d * zi - 0.5 * d * d).exp()
                } else {
                    lc.exp()
                };
            }
            for p in &self.pis {
                let l: f64 = w.iter().map(|wi| (1.0 - p + p * wi).ln()).sum();
                best = best.max(l);
            }
        }
        2.0 * best
    }
}

fn group<R: rand::Rng>(rng: &mut R, n_aff: usize, delta: f64, shrink: f64) -> (Vec<f64>, Vec<f64>) {
    let mut z = Vec::with_capacity(N);
    let mut zs = Vec::with_capacity(N);
    for i in 0..N {
        let e = normal(rng);
        let d = if i < n_aff { delta } else { 0.0 };
        z.push(d + e);
        zs.push(shrink * d + e);
    }
    (z, zs)
}

fn quantile(mut v: Vec<f64>, level: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let k = ((1.0 - level) * v.len() as f64).ceil() as usize;
    v[k.min(v.len() - 1)]
}

fn curves(null_reps: usize, alt_reps: usize, shrink: f64) {
    let grid = MixGrid::new();
    let zf = z_floor();
    let mut rng = ChaCha8Rng::seed_from_u64(45);
    let nulls: Vec<[f64; 4]> = (0..null_reps)
        .map(|_| {
            let (z, zs) = group(&mut rng, 0, 0.0, shrink);
            statistics(&z, &zs, &grid)
        })
        .collect();
    let thr: Vec<f64> = (0..4)
        .map(|k| quantile(nulls.iter().map(|s| s[k]).collect(), GROUP_LEVEL))
        .collect();
    println!(
        "{N} members; segment level {SEGMENT_LEVEL:.2e} (z_floor {zf:.3}); group level {GROUP_LEVEL:.2e}; score shrink {shrink}"
    );
    println!(
        "empirical thresholds from {null_reps} clean groups: score_sum {:.2}, lr_sum {:.2} (formula p there {:.2e}), linear {:.3}, mixture {:.2}",
        thr[0],
        thr[1],
        sum_chibar_sf(thr[1], N),
        thr[2],
        thr[3]
    );
    println!("power over {alt_reps} groups per cell (score_sum / lr_sum / linear / mixture):");
    print!("{:>9}", "fraction");
    let mags = [0.5, 0.75, 1.0, 1.5, 2.0];
    for m in mags {
        print!(" | {:^23}", format!("{m}x floor"));
    }
    println!();
    for frac in [0.1, 0.2, 0.3, 0.4, 0.5] {
        let n_aff = (frac * N as f64).round() as usize;
        print!("{:>8.0}%", 100.0 * frac);
        for m in mags {
            let mut hits = [0usize; 4];
            for _ in 0..alt_reps {
                let (z, zs) = group(&mut rng, n_aff, m * zf, shrink);
                let s = statistics(&z, &zs, &grid);
                for k in 0..4 {
                    hits[k] += (s[k] > thr[k]) as usize;
                }
            }
            let p: Vec<String> = hits
                .iter()
                .map(|h| format!("{:.2}", *h as f64 / alt_reps as f64))
                .collect();
            print!(" | {:^23}", p.join(" "));
        }
        println!();
    }
}

fn null_check(reps: usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(4545);
    let sums: Vec<f64> = (0..reps)
        .map(|_| (0..N).map(|_| normal(&mut rng).max(0.0).powi(2)).sum())
        .collect();
    println!("lr_sum over {N} clean members, {reps} groups: simulated vs formula tail");
    for x in [20.0, 30.0, 40.0, 50.0, 60.0] {
        let sim = sums.iter().filter(|s| **s > x).count() as f64 / reps as f64;
        println!(
            "  P(S > {x}): simulated {sim:.4}, formula {:.4}",
            sum_chibar_sf(x, N)
        );
    }
}

/// The four effects of the pooled test (one nested parameter on the bound of its range).
const EFFECTS: [Effect; 4] = [
    Effect::SoilDamping,
    Effect::AirInWater,
    Effect::WallThinning,
    Effect::PipeLoss,
];

/// The hidden value of `e` at deviation `m` from its neutral value on `material`: η_m, the air
/// fraction, 1 − the wall ratio, or the pipe loss factor above the material's typical one.
fn hidden_value(e: Effect, material: Material, m: f64) -> f64 {
    match e {
        Effect::WallThinning => 1.0 - m,
        Effect::PipeLoss => material.typical().loss_factor + m,
        _ => m,
    }
}

/// The largest deviation the effect's range allows on `material`.
fn max_deviation(e: Effect, material: Material) -> f64 {
    let p = e.parameter().expect("the four effects have a parameter");
    match e {
        Effect::WallThinning => 1.0 - p.lower,
        Effect::PipeLoss => p.upper - material.typical().loss_factor,
        _ => p.upper,
    }
}

/// One-segment floors (deviation from the neutral value) measured by
/// `group_power -- floor 20` (docs/group-test.md): the magnitude at which the median gain of a
/// segment carrying the effect alone is z_floor², i.e. its own one-sided test at the
/// diagnosis's level has 50 % power there. `None`: not reached inside the effect's range (soil
/// damping under metal and cement pipes: at η_m = 0.05 the median gain is 0–0.2, the soil
/// mostly radiating, where its loss is almost invisible).
fn floor_of(e: Effect, material: Material) -> Option<f64> {
    use Material::Steel as St;
    use Material::{AsbestosCement as Ac, CastIron as Ci, DuctileIron as Di, Hdpe, Mdpe, Pvc};
    let f = match (e, material) {
        (Effect::SoilDamping, Pvc) => 0.222,
        (Effect::SoilDamping, Mdpe) => 0.127,
        (Effect::SoilDamping, Hdpe) => 0.230,
        (Effect::SoilDamping, _) => return None,
        (Effect::AirInWater, Ci) => 8.74e-6,
        (Effect::AirInWater, Di) => 1.12e-5,
        (Effect::AirInWater, St) => 1.00e-5,
        (Effect::AirInWater, Pvc) => 1.95e-4,
        (Effect::AirInWater, Mdpe) => 1.67e-4,
        (Effect::AirInWater, Hdpe) => 2.94e-4,
        (Effect::AirInWater, Ac) => 1.70e-5,
        (Effect::WallThinning, Ci) => 0.151,
        (Effect::WallThinning, Di) => 0.122,
        (Effect::WallThinning, St) => 0.125,
        (Effect::WallThinning, Ac) => 0.0934,
        (Effect::WallThinning, _) => return None,
        (Effect::PipeLoss, Ci) => 0.0185,
        (Effect::PipeLoss, Di) => 0.0222,
        (Effect::PipeLoss, St) => 0.0179,
        (Effect::PipeLoss, Pvc) => 0.0299,
        (Effect::PipeLoss, Mdpe) => 0.0242,
        (Effect::PipeLoss, Hdpe) => 0.0498,
        (Effect::PipeLoss, Ac) => 0.0139,
        _ => return None,
    };
    Some(f)
}

/// The members' gains of one segment's diagnosis, as `diagnose` makes them, and whether its
/// own diagnosis named `hidden`.
fn member(settings: &DiagnoseSettings, t: &Trial) -> (Vec<(Effect, f64)>, bool) {
    let (g, own, _, _) = member_diagnosed(settings, t);
    (g, own)
}

/// A member's gains, whether its own diagnosis named the hidden effect, the diagnosis, and the
/// twin refits made for the pooled test.
type Member = (
    Vec<(Effect, f64)>,
    bool,
    Diagnosis,
    Vec<(Effect, FitResult)>,
);

/// [`member`] with the member's diagnosis kept (for the group-level twin refit).
fn member_diagnosed(settings: &DiagnoseSettings, t: &Trial) -> Member {
    let d = diagnose_segment(&t.data, None, settings);
    let own = t.hidden.is_some_and(|(h, _)| d.named == Some(h));
    let (gains, refits) = member_gains_and_refits(&d, settings);
    (gains, own, d, refits)
}

fn settings() -> DiagnoseSettings {
    DiagnoseSettings {
        candidates: Effect::PHYSICAL.to_vec(),
        ..DiagnoseSettings::default()
    }
}

fn draw_trial<R: Rng>(rng: &mut R, material: Material, hidden: Option<(Effect, f64)>) -> Trial {
    loop {
        if let Some(t) = effect_trial(rng, material, hidden) {
            break t;
        }
    }
}

/// Per effect and material: the one-segment floor. `n` segments carry the effect at a
/// reference deviation m0; with δ0 the median √gain of the effect (member_gains), the next
/// estimate is m1 = m0·z_floor/δ0 (√gain grows in proportion to the magnitude in the local
/// model). A second pass at m1 gives δ1, and the floor is read off the power law √gain = c·m^q
/// through the two passes (q from their ratio; the linear step when q ≤ 0, a noise-dominated
/// pair). Each pass prints the median gain and the share of segments whose own diagnosis names
/// the effect.
fn floor(n: usize) {
    let settings = settings();
    let zf = z_floor();
    println!(
        "z_floor {zf:.3} (median gain at the floor {:.2}); {n} segments per pass",
        zf * zf
    );
    for (ei, e) in EFFECTS.into_iter().enumerate() {
        for (mi, (material, _)) in MATERIAL_MIX.into_iter().enumerate() {
            if !e.applies_to(material) {
                continue;
            }
            let cap = max_deviation(e, material);
            let mut m = match e {
                Effect::SoilDamping => 0.05,
                Effect::AirInWater => 2e-5,
                Effect::WallThinning => 0.08,
                _ => 0.03,
            };
            let mut line = format!("{} {}:", e.name(), material.code());
            let mut passes: Vec<(f64, f64)> = Vec::new();
            for pass in 0..2u64 {
                let mut rng =
                    ChaCha8Rng::seed_from_u64(90_000 + 1000 * pass + 10 * ei as u64 + mi as u64);
                let v = hidden_value(e, material, m);
                let trials: Vec<Trial> = (0..n)
                    .map(|_| draw_trial(&mut rng, material, Some((e, v))))
                    .collect();
                let res: Vec<(f64, bool)> = trials
                    .par_iter()
                    .map(|t| {
                        let (g, own) = member(&settings, t);
                        let gain = g.iter().find(|p| p.0 == e).map(|p| p.1).unwrap_or(0.0);
                        (gain.max(0.0).sqrt(), own)
                    })
                    .collect();
                let mut d: Vec<f64> = res.iter().map(|r| r.0).collect();
                d.sort_by(|a, b| a.total_cmp(b));
                let med = d[d.len() / 2];
                let named = res.iter().filter(|r| r.1).count();
                passes.push((m, med));
                line += &format!(
                    " at {m:.3e}: median gain {:.2}, named {named}/{n};",
                    med * med
                );
                m = if med > 0.0 {
                    m * zf / med
                } else {
                    f64::INFINITY
                };
                if pass == 1 {
                    let ((m0, d0), (m1, d1)) = (passes[0], passes[1]);
                    let q = (d0 / d1).ln() / (m0 / m1).ln();
                    if q.is_finite() && q > 0.0 {
                        m = m1 * (zf / d1).powf(1.0 / q);
                    }
                }
                if m > cap {
                    break;
                }
            }
            if m > cap {
                println!("{line} floor above the range (max {cap:.3e})");
            } else {
                println!("{line} floor {m:.3e}");
            }
        }
    }
}

/// The material of a group carrying `e`: drawn from the synthetic network's mix among the
/// materials where `e` applies and its floor lies inside its range (`None`: a clean group,
/// any material).
fn group_material<R: Rng>(rng: &mut R, e: Option<Effect>) -> Material {
    let ok = |m: Material| e.is_none_or(|e| e.applies_to(m) && floor_of(e, m).is_some());
    let total: f64 = MATERIAL_MIX.iter().filter(|m| ok(m.0)).map(|m| m.1).sum();
    let mut u = rng.gen::<f64>() * total;
    for (m, w) in MATERIAL_MIX.into_iter().filter(|m| ok(m.0)) {
        if u < w {
            return m;
        }
        u -= w;
    }
    Material::CastIron
}

/// The adopted test on refitted synthetic groups of 40 members: per seed, one group per effect
/// (hidden in 8–16 of the 40 members, 20–40 %, at 0.8–1.2 × the floor of the group's material)
/// and `clean` groups without an effect; each tested as one of 8 groups of a run.
fn real_groups(seeds: u64, base: u64, clean: usize) {
    let settings = settings();
    let kinds: Vec<Option<Effect>> = EFFECTS
        .into_iter()
        .map(Some)
        .chain(std::iter::repeat_n(None, clean))
        .collect();
    // Per (effect, material): groups, right first and significant, right or reported with it,
    // any detection, own naming of the affected members, affected members.
    let mut cells: BTreeMap<(String, String), [usize; 6]> = BTreeMap::new();
    let (mut det, mut n_eff, mut fa, mut n_clean, mut in_set) = (0, 0, 0, 0, 0);
    let (mut own_hit, mut own_n) = (0, 0);
    let mut before_det = 0;
    let mut clean_p: Vec<f64> = Vec::new();
    for s in 0..seeds {
        for (k, e) in kinds.iter().copied().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(base + 100 * s + k as u64);
            let material = group_material(&mut rng, e);
            let n_aff = if e.is_some() {
                rng.gen_range(8..=16)
            } else {
                0
            };
            let trials: Vec<Trial> = (0..N)
                .map(|i| {
                    let hidden = e.filter(|_| i < n_aff).map(|e| {
                        let f =
                            floor_of(e, material).expect("groups only where the floor is known");
                        let m = (f * rng.gen_range(0.8..1.2)).min(max_deviation(e, material));
                        (e, hidden_value(e, material, m))
                    });
                    draw_trial(&mut rng, material, hidden)
                })
                .collect();
            let res: Vec<Member> = trials
                .par_iter()
                .map(|t| member_diagnosed(&settings, t))
                .collect();
            let scores: Vec<_> = res.iter().map(|r| r.0.clone()).collect();
            let named = res[..n_aff].iter().filter(|r| r.1).count();
            own_hit += named;
            own_n += n_aff;
            let mut g = pooled_test("g", &(0..N).collect::<Vec<_>>(), &scores, 8);
            let before = g.effect;
            let fits = DiagnosedMembers(
                res.iter().map(|r| (&r.2, &settings)).collect(),
                res.iter().map(|r| r.3.clone()).collect(),
            );
            rank_twins_with(&mut g, &scores, &fits);
            if let Some(t) = &g.twins {
                println!(
                    "  twins: {} {:.2} (fraction {:.2}, deviation {:.3e}) vs {} {:.2} (fraction {:.2}) over {} members; member-gain first {}",
                    t.first.name(),
                    t.first_gain,
                    t.first_fraction,
                    t.first_deviation,
                    t.second.name(),
                    t.second_gain,
                    t.second_fraction,
                    t.members,
                    before.map(|e| e.name()).unwrap_or("none")
                );
            }
            before_det += (e.is_some() && before == e) as usize;
            let rank = e.and_then(|e| g.pooled.iter().position(|p| p.effect == e));
            let key = (
                e.map(|e| e.name()).unwrap_or("clean").to_string(),
                material.code().to_string(),
            );
            let c = cells.entry(key).or_default();
            c[0] += 1;
            c[3] += g.effect.is_some() as usize;
            c[4] += named;
            c[5] += n_aff;
            match e {
                Some(e) => {
                    n_eff += 1;
                    let right = g.effect == Some(e);
                    let set = right || g.ambiguous_with.contains(&e);
                    det += right as usize;
                    in_set += set as usize;
                    c[1] += right as usize;
                    c[2] += set as usize;
                }
                None => {
                    n_clean += 1;
                    fa += g.effect.is_some() as usize;
                    clean_p.push(g.p_value());
                }
            }
            println!(
                "seed {s} {} {} in {n_aff}/{N}: detected {} with {:?} (p {:.2e}, level {:.1e}, true rank {:?}, carrying {}, own naming {named}/{n_aff})",
                material.code(),
                e.map(|e| e.name()).unwrap_or("clean"),
                g.effect.map(|e| e.name()).unwrap_or("none"),
                g.ambiguous_with.iter().map(|e| e.name()).collect::<Vec<_>>(),
                g.p_value(),
                g.level,
                rank.map(|r| r + 1),
                g.carrying.len(),
            );
        }
    }
    println!("| effect | material | groups | right first, p < level | right or reported with it | any detection | own naming |");
    for ((e, m), c) in &cells {
        println!(
            "| {e} | {m} | {} | {} | {} | {} | {}/{} |",
            c[0], c[1], c[2], c[3], c[4], c[5]
        );
    }
    clean_p.sort_by(|a, b| a.total_cmp(b));
    println!("right effect first and significant before the twins' common-magnitude refit: {before_det}/{n_eff}");
    println!(
        "groups with an effect: detected (right effect first, p below level) {det}/{n_eff}, right effect detected or in the reported set {in_set}/{n_eff}; clean groups: false alarms {fa}/{n_clean} (smallest p {:.2e}); affected members named by their own diagnosis {own_hit}/{own_n}",
        clean_p.first().copied().unwrap_or(f64::NAN)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let a = |i: usize, d: f64| -> f64 { args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d) };
    match args.get(1).map(String::as_str) {
        Some("curves") => curves(a(2, 20000.0) as usize, a(3, 2000.0) as usize, a(4, 1.0)),
        Some("null") => null_check(a(2, 100000.0) as usize),
        Some("floor") => floor(a(2, 20.0) as usize),
        Some("groups") => real_groups(a(2, 4.0) as u64, a(3, 0.0) as u64, a(4, 1.0) as usize),
        _ => eprintln!("usage: group_power curves [NULL_REPS] [ALT_REPS] [SHRINK] | null [REPS] | floor [N] | groups SEEDS [BASE] [CLEAN_PER_SEED]"),
    }
}
