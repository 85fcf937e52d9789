//! SHADE: success-history based adaptive differential evolution (Tanabe & Fukunaga 2013,
//! "Success-History Based Parameter Adaptation for Differential Evolution", IEEE CEC).
//!
//! Per generation and individual `i`:
//!
//! * pick a memory slot `r ∈ 0..H`; draw `CR_i ~ N(M_CR[r], 0.1)` clipped to `[0, 1]` and
//!   `F_i ~ Cauchy(M_F[r], 0.1)`, redrawn while `≤ 0` and capped at 1;
//! * current-to-pbest/1 mutation `v = x_i + F_i (x_pbest − x_i) + F_i (x_r1 − x̃_r2)`, with
//!   `x_pbest` drawn from the best `max(2, round(p_i·NP))` members, `p_i ~ U[2/NP, p_max]`,
//!   `r1 ≠ i` from the population and `x̃_r2` (≠ `x_i`, `x_r1`) from the population united
//!   with the external archive `A` of recently replaced parents;
//! * bound handling by the midpoint between parent and violated bound,
//!   `v_q = (lower_q + x_i,q)/2` (or with `upper_q`), which keeps diversity near a bound
//!   instead of piling points onto it as clamping does;
//! * binomial crossover with one forced dimension, then selection `f(u) ≤ f(x_i)`;
//!   strictly better trials record `(CR_i, F_i, |Δf|)` and send their parent to the archive
//!   (trimmed at random to `archive_rate·NP`);
//! * at the end of the generation one memory slot (cyclically) is updated with the
//!   `|Δf|`-weighted arithmetic mean of the successful `CR` and the weighted Lehmer mean
//!   `Σ w F² / Σ w F` of the successful `F`.
//!
//! After each generation the driver may shrink the population linearly in the evaluations
//! used, dropping the worst members and resizing the archive (L-SHADE's linear population
//! size reduction, Tanabe & Fukunaga 2014).
//!
//! The generation is synchronous: trials are built from the population at its start.
//! The initial population is a Latin hypercube (one point per stratum in every
//! dimension), which covers the box more evenly than independent uniform draws.
//! If a parent's value is non-finite and its trial's is finite, the improvement is
//! infinite; such improvements then share the whole weight of the memory update equally.

use rand::seq::SliceRandom;
use rand::Rng;

use super::{distinct_index, DifferentialEvolution, Population, Run};
use crate::optimize::{Bounds, Objective};

/// Standard deviation of the normal distribution of `CR_i` (Tanabe & Fukunaga 2013).
pub const SHADE_CR_SD: f64 = 0.1;
/// Scale of the Cauchy distribution of `F_i` (Tanabe & Fukunaga 2013).
pub const SHADE_F_SCALE: f64 = 0.1;
/// Redraws of a non-positive `F_i` before falling back to the memory value itself.
const F_MAX_REDRAWS: usize = 100;

/// Latin-hypercube initial population: in every dimension the `NP` members occupy the `NP`
/// equal strata of the interval once each (independent random permutations per
/// dimension), at a uniform random position within the stratum.
pub(crate) fn initialise<R: Rng + ?Sized>(pop: &mut Population, bounds: &Bounds, rng: &mut R) {
    let np = pop.np;
    let mut perm: Vec<usize> = (0..np).collect();
    for q in 0..pop.dim {
        perm.shuffle(rng);
        let (lo, w) = (bounds.lower()[q], bounds.width(q));
        for (i, &s) in perm.iter().enumerate() {
            let v = lo + (s as f64 + rng.gen::<f64>()) / np as f64 * w;
            pop.x[i * pop.dim + q] = v.min(bounds.upper()[q]);
        }
    }
}

/// Adaptive state carried between generations.
pub(crate) struct State {
    m_cr: Vec<f64>,
    m_f: Vec<f64>,
    next_slot: usize,
    archive: Vec<f64>,
    archive_cap: usize,
    archive_rate: f64,
    pbest_max: f64,
}

impl State {
    pub(crate) fn new(cfg: &DifferentialEvolution, np: usize) -> Self {
        Self {
            m_cr: vec![cfg.crossover_rate; cfg.memory_size],
            m_f: vec![cfg.initial_f; cfg.memory_size],
            next_slot: 0,
            archive: Vec::new(),
            archive_cap: (cfg.archive_rate * np as f64).round() as usize,
            archive_rate: cfg.archive_rate,
            pbest_max: cfg.pbest_max,
        }
    }
}

impl State {
    /// Removes random archive members until the archive fits its capacity.
    fn trim_archive<R: Rng + ?Sized>(&mut self, dim: usize, rng: &mut R) {
        while self.archive.len() / dim > self.archive_cap {
            let n = self.archive.len() / dim;
            let k = rng.gen_range(0..n);
            // Swap-remove row k.
            self.archive.copy_within((n - 1) * dim..n * dim, k * dim);
            self.archive.truncate((n - 1) * dim);
        }
    }

    /// Resizes the archive capacity to `archive_rate · np` after a population reduction.
    pub(crate) fn shrink_archive<R: Rng + ?Sized>(&mut self, np: usize, dim: usize, rng: &mut R) {
        self.archive_cap = (self.archive_rate * np as f64).round() as usize;
        self.trim_archive(dim, rng);
    }
}

/// Standard normal deviate (Box–Muller).
fn std_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1 = 1.0 - rng.gen::<f64>(); // (0, 1]
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Standard Cauchy deviate.
fn std_cauchy<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    (std::f64::consts::PI * (rng.gen::<f64>() - 0.5)).tan()
}

/// One synchronous SHADE generation. Stops building trials when the evaluation budget is
/// used up.
pub(crate) fn generation<O: Objective + ?Sized, R: Rng + ?Sized>(
    st: &mut State,
    pop: &mut Population,
    bounds: &Bounds,
    run: &mut Run<'_, O>,
    rng: &mut R,
) {
    let (np, dim) = (pop.np, pop.dim);
    let mut order: Vec<usize> = (0..np).collect();
    order.sort_by(|&a, &b| pop.f[a].total_cmp(&pop.f[b]));
    let p_min = 2.0 / np as f64;
    let p_max = st.pbest_max.max(p_min);
    let n_archive = st.archive.len() / dim;

    let mut trials = vec![0.0; np * dim];
    let mut trial_f = Vec::with_capacity(np);
    let mut params = Vec::with_capacity(np);
    for i in 0..np {
        if run.exhausted() {
            break;
        }
        let slot = rng.gen_range(0..st.m_cr.len());
        let cr = (st.m_cr[slot] + SHADE_CR_SD * std_normal(rng)).clamp(0.0, 1.0);
        let mut f = 0.0;
        for _ in 0..F_MAX_REDRAWS {
            f = st.m_f[slot] + SHADE_F_SCALE * std_cauchy(rng);
            if f > 0.0 {
                break;
            }
        }
        if f.is_nan() || f <= 0.0 {
            f = st.m_f[slot].max(f64::MIN_POSITIVE);
        }
        let f = f.min(1.0);
        let p = rng.gen_range(p_min..=p_max);
        let n_best = ((p * np as f64).round() as usize).clamp(2, np);
        let pbest = order[rng.gen_range(0..n_best)];
        let r1 = distinct_index(rng, np, &[i]);
        let r2 = distinct_index(rng, np + n_archive, &[i, r1]);
        let jrand = rng.gen_range(0..dim);
        let xi = &pop.x[i * dim..(i + 1) * dim];
        let xr2 = if r2 < np {
            &pop.x[r2 * dim..(r2 + 1) * dim]
        } else {
            &st.archive[(r2 - np) * dim..(r2 - np + 1) * dim]
        };
        let u = &mut trials[i * dim..(i + 1) * dim];
        for q in 0..dim {
            let mut v =
                xi[q] + f * (pop.x[pbest * dim + q] - xi[q]) + f * (pop.x[r1 * dim + q] - xr2[q]);
            let (lo, hi) = (bounds.lower()[q], bounds.upper()[q]);
            if v < lo {
                v = 0.5 * (lo + xi[q]);
            } else if v > hi {
                v = 0.5 * (hi + xi[q]);
            }
            let take_mutant = rng.gen::<f64>() < cr || q == jrand;
            u[q] = if take_mutant { v } else { xi[q] };
        }
        trial_f.push(run.eval(u));
        params.push((cr, f));
    }

    let mut s_cr = Vec::new();
    let mut s_f = Vec::new();
    let mut s_df = Vec::new();
    for (i, &fu) in trial_f.iter().enumerate() {
        let fx = pop.f[i];
        if fu <= fx {
            if fu < fx {
                st.archive.extend_from_slice(&pop.x[i * dim..(i + 1) * dim]);
                s_cr.push(params[i].0);
                s_f.push(params[i].1);
                s_df.push(fx - fu);
            }
            pop.f[i] = fu;
            pop.x[i * dim..(i + 1) * dim].copy_from_slice(&trials[i * dim..(i + 1) * dim]);
        }
    }
    st.trim_archive(dim, rng);
    if !s_f.is_empty() {
        let any_inf = s_df.iter().any(|d: &f64| d.is_infinite());
        let weights: Vec<f64> = if any_inf {
            s_df.iter()
                .map(|d| if d.is_infinite() { 1.0 } else { 0.0 })
                .collect()
        } else {
            s_df.clone()
        };
        let total: f64 = weights.iter().sum();
        if total > 0.0 {
            let mean_cr: f64 = weights.iter().zip(&s_cr).map(|(w, c)| w * c).sum::<f64>() / total;
            let num: f64 = weights.iter().zip(&s_f).map(|(w, f)| w * f * f).sum();
            let den: f64 = weights.iter().zip(&s_f).map(|(w, f)| w * f).sum();
            let slot = st.next_slot;
            st.m_cr[slot] = mean_cr;
            if den > 0.0 {
                st.m_f[slot] = num / den;
            }
            st.next_slot = (slot + 1) % st.m_cr.len();
        }
    }
}
