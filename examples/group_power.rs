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
//!   The level is 0.05/(4 effects × 10 groups); every statistic's threshold is the empirical
//!   quantile of NULL_REPS clean groups.
//! * `null [REPS]`: the lr_sum null: simulated tail frequencies against the χ̄² mixture.
//!
//! Run: `cargo run --release --example group_power -- curves 20000 2000`.

use pipewave::diagnose::stats::sum_chibar_sf;
use pipewave::synth::normal;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
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

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let a = |i: usize, d: f64| -> f64 { args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d) };
    match args.get(1).map(String::as_str) {
        Some("curves") => curves(a(2, 20000.0) as usize, a(3, 2000.0) as usize, a(4, 1.0)),
        Some("null") => null_check(a(2, 100000.0) as usize),
        _ => eprintln!("usage: group_power curves [NULL_REPS] [ALT_REPS] [SHRINK] | null [REPS]"),
    }
}
