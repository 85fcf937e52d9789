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
//! * `groups SEEDS [BASE]`: the adopted test on refitted synthetic groups of 40 members. Per
//!   seed, one group per effect (soil_damping, air_in_water, pipe_loss on a material of the
//!   synthetic network's mix; wall_thinning on cast iron) hidden in 20–40 % of the members at a
//!   magnitude near the one-segment floor (the per-member naming rate printed shows where it
//!   sits), and one clean group; each tested as one of 8 groups of a run. Prints per group the
//!   detected effect, its p-value, the true effect's rank, and the totals.
//!
//! Run: `cargo run --release --example group_power -- curves 20000 2000`.

use pipewave::diagnose::group::{member_scores, pooled_test};
use pipewave::diagnose::stats::sum_chibar_sf;
use pipewave::diagnose::{diagnose_segment, DiagnoseSettings};
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::stats::normal;
use pipewave::synth::trial::effect_trial;
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

/// Hidden magnitudes near the one-segment floor (drawn uniformly; air log-uniformly).
fn env_f64(name: &str, d: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

fn near_floor(e: Effect) -> (f64, f64) {
    let f = env_f64;
    // ±20 % about the floor measured by `floor` (deviation from the neutral value).
    let band = |m: f64| (0.8 * m, 1.2 * m);
    match e {
        Effect::SoilDamping => band(f("FLOOR_SOIL", 0.08)),
        Effect::AirInWater => band(f("FLOOR_AIR", 5e-6)),
        Effect::WallThinning => {
            let (lo, hi) = band(f("FLOOR_THIN", 0.06));
            (1.0 - hi, 1.0 - lo)
        }
        _ => band(f("FLOOR_LOSS", 0.01)),
    }
}

/// Per effect: one-segment floors measured by `floor`: for 24 members each at a reference
/// magnitude m0, the median √gain of the true effect δ0; the floor is m0·z_floor/δ0 (the gain's
/// square root grows in proportion to the magnitude in the local model).
fn floor(n: usize) {
    let settings = DiagnoseSettings {
        candidates: Effect::PHYSICAL.to_vec(),
        ..DiagnoseSettings::default()
    };
    for (e, m0) in [
        (Effect::SoilDamping, env_f64("FLOOR_SOIL", 0.05)),
        (Effect::AirInWater, env_f64("FLOOR_AIR", 2e-5)),
        (Effect::WallThinning, env_f64("FLOOR_THIN", 0.08)),
        (Effect::PipeLoss, env_f64("FLOOR_LOSS", 0.03)),
    ] {
        let mut rng = ChaCha8Rng::seed_from_u64(90_000 + e as u64);
        let trials: Vec<_> = (0..n)
            .map(|_| {
                let material = if e == Effect::WallThinning {
                    Material::CastIron
                } else {
                    mix_material(&mut rng)
                };
                let v = if e == Effect::WallThinning {
                    1.0 - m0
                } else {
                    m0
                };
                loop {
                    if let Some(t) = effect_trial(&mut rng, material, Some((e, v))) {
                        break t;
                    }
                }
            })
            .collect();
        let mut d0: Vec<f64> = trials
            .par_iter()
            .map(|t| {
                let d = diagnose_segment(&t.data, None, &settings);
                member_scores(&d)
                    .iter()
                    .find(|p| p.0 == e)
                    .map(|p| p.1.sqrt())
                    .unwrap_or(0.0)
            })
            .collect();
        d0.sort_by(|a, b| a.total_cmp(b));
        let med = d0[d0.len() / 2];
        println!(
            "{}: magnitude {m0} -> median sqrt(gain) {med:.2}; floor magnitude {:.3e}",
            e.name(),
            m0 * z_floor() / med
        );
    }
}

fn mix_material<R: Rng>(rng: &mut R) -> Material {
    let total: f64 = MATERIAL_MIX.iter().map(|m| m.1).sum();
    let mut u = rng.gen::<f64>() * total;
    for (m, w) in MATERIAL_MIX {
        if u < w {
            return m;
        }
        u -= w;
    }
    Material::CastIron
}

fn real_groups(seeds: u64, base: u64) {
    let settings = DiagnoseSettings {
        candidates: Effect::PHYSICAL.to_vec(),
        ..DiagnoseSettings::default()
    };
    let kinds = [
        Some(Effect::SoilDamping),
        Some(Effect::AirInWater),
        Some(Effect::WallThinning),
        Some(Effect::PipeLoss),
        None,
    ];
    let (mut det, mut n_eff, mut fa, mut n_clean, mut in_set) = (0, 0, 0, 0, 0);
    let (mut own_hit, mut own_n) = (0, 0);
    for s in 0..seeds {
        for (k, e) in kinds.into_iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(base + 100_000 + 10 * s + k as u64);
            let material = match e {
                Some(Effect::WallThinning) => Material::CastIron,
                _ => mix_material(&mut rng),
            };
            let n_aff = if e.is_some() {
                rng.gen_range(8..=16)
            } else {
                0
            };
            let trials: Vec<_> = (0..N)
                .map(|i| {
                    let hidden = e.filter(|_| i < n_aff).map(|e| {
                        let (lo, hi) = near_floor(e);
                        let v = if e == Effect::AirInWater {
                            (lo.ln() + rng.gen::<f64>() * (hi.ln() - lo.ln())).exp()
                        } else {
                            rng.gen_range(lo..hi)
                        };
                        (e, v)
                    });
                    loop {
                        if let Some(t) = effect_trial(&mut rng, material, hidden) {
                            break t;
                        }
                    }
                })
                .collect();
            let res: Vec<(Vec<(Effect, f64)>, bool)> = trials
                .par_iter()
                .map(|t| {
                    let d = diagnose_segment(&t.data, None, &settings);
                    let own = t.hidden.is_some_and(|(h, _)| d.named == Some(h));
                    (member_scores(&d), own)
                })
                .collect();
            let scores: Vec<_> = res.iter().map(|r| r.0.clone()).collect();
            own_hit += res.iter().filter(|r| r.1).count();
            own_n += n_aff;
            let g = pooled_test("g", &(0..N).collect::<Vec<_>>(), &scores, 8);
            let mut gains: Vec<f64> = e
                .map(|e| {
                    scores[..n_aff]
                        .iter()
                        .filter_map(|m| m.iter().find(|p| p.0 == e).map(|p| p.1))
                        .collect()
                })
                .unwrap_or_default();
            gains.sort_by(|a, b| a.total_cmp(b));
            let med_gain = gains.get(gains.len() / 2).copied().unwrap_or(f64::NAN);
            let rank = e.and_then(|e| g.pooled.iter().position(|p| p.effect == e));
            match e {
                Some(e) => {
                    n_eff += 1;
                    det += (g.effect == Some(e)) as usize;
                    in_set += (g.effect == Some(e) || g.ambiguous_with.contains(&e)) as usize;
                }
                None => {
                    n_clean += 1;
                    fa += g.effect.is_some() as usize;
                }
            }
            println!(
                "seed {s} {} {} in {n_aff}/{N}: detected {} (p {:.2e}, level {:.1e}, true rank {:?}, carrying {}, median gain of the affected {med_gain:.1}, own naming {}/{n_aff})",
                material.code(),
                e.map(|e| e.name()).unwrap_or("clean"),
                g.effect.map(|e| e.name()).unwrap_or("none"),
                g.p_value(),
                g.level,
                rank.map(|r| r + 1),
                g.carrying.len(),
                res[..n_aff].iter().filter(|r| r.1).count()
            );
        }
    }
    println!(
        "groups with an effect: detected (right effect first, p below level) {det}/{n_eff}, right effect detected or in the reported set {in_set}/{n_eff}; clean groups: false alarms {fa}/{n_clean}; affected members named by their own diagnosis {own_hit}/{own_n}"
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let a = |i: usize, d: f64| -> f64 { args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d) };
    match args.get(1).map(String::as_str) {
        Some("curves") => curves(a(2, 20000.0) as usize, a(3, 2000.0) as usize, a(4, 1.0)),
        Some("null") => null_check(a(2, 100000.0) as usize),
        Some("floor") => floor(a(2, 24.0) as usize),
        Some("groups") => real_groups(a(2, 4.0) as u64, a(3, 0.0) as u64),
        _ => eprintln!("usage: group_power curves [NULL_REPS] [ALT_REPS] [SHRINK] | null [REPS] | groups SEEDS [BASE]"),
    }
}
