//! The paper's differential evolution (Lu et al., Sensors 2022; docs/model.md §7),
//! classic DE/rand/1/bin of Storn & Price 1997:
//!
//! * initialisation: `NP` points drawn uniformly in the box;
//! * P54: mutation factor `F_g = 2 − g/G_max` for generation `g = 1, …, G_max`
//!   (generalised to `F_g = F_start − (F_start − F_end)·g/G_max`);
//! * P55: donor `b = x_r1 + F_g (x_r2 − x_r3)`;
//! * P56: each donor component clamped to its bounds;
//! * P57: binomial crossover, `u_q = b_q` if `rand_q ≤ CR` or `q = m` (one random dimension
//!   `m` forced), else `x_j,q`;
//! * P58: greedy selection, `u` replaces `x_j` if `f(u) < f(x_j)`;
//! * P59: stop when `|min f after g − min f after g − t| < ε` or `g = G_max`; the best member
//!   of the final population is returned.
//!
//! Choices the paper leaves open, fixed here: `t = 20` generations and `ε = 1e-6`
//! (absolute, [`PAPER_STAGNATION_GENERATIONS`](super::PAPER_STAGNATION_GENERATIONS),
//! [`PAPER_STAGNATION_EPS`](super::PAPER_STAGNATION_EPS)); `r1, r2, r3` mutually distinct
//! and different from the target `j`; synchronous generation update (all trials of
//! generation `g` built from the population at the start of `g`); a non-finite objective
//! value counts as +∞; `rand_q` is drawn for every component, including `m`.

use rand::Rng;

use super::{distinct_index, DifferentialEvolution, Population, Run};
use crate::optimize::{Bounds, Objective};

/// Uniform random initial population in the box.
pub(crate) fn initialise<R: Rng + ?Sized>(pop: &mut Population, bounds: &Bounds, rng: &mut R) {
    for i in 0..pop.np {
        for (q, v) in pop.row_mut(i).iter_mut().enumerate() {
            *v = bounds.lower()[q] + rng.gen::<f64>() * bounds.width(q);
        }
    }
}

/// Mutation factor of generation `g` (P54).
pub(crate) fn mutation_factor(cfg: &DifferentialEvolution, g: usize) -> f64 {
    cfg.f_start - (cfg.f_start - cfg.f_end) * g as f64 / cfg.max_generations as f64
}

/// One synchronous generation `g` (P55–P58). Stops building trials when the evaluation
/// budget is used up.
pub(crate) fn generation<O: Objective + ?Sized, R: Rng + ?Sized>(
    cfg: &DifferentialEvolution,
    g: usize,
    pop: &mut Population,
    bounds: &Bounds,
    run: &mut Run<'_, O>,
    rng: &mut R,
) {
    let (np, dim) = (pop.np, pop.dim);
    let f_g = mutation_factor(cfg, g);
    let mut trials = vec![0.0; np * dim];
    let mut trial_f = Vec::with_capacity(np);
    for j in 0..np {
        if run.exhausted() {
            break;
        }
        let r1 = distinct_index(rng, np, &[j]);
        let r2 = distinct_index(rng, np, &[j, r1]);
        let r3 = distinct_index(rng, np, &[j, r1, r2]);
        let m = rng.gen_range(0..dim);
        let u = &mut trials[j * dim..(j + 1) * dim];
        for (q, uq) in u.iter_mut().enumerate() {
            // P55 donor, P56 clamp.
            let b = (pop.x[r1 * dim + q] + f_g * (pop.x[r2 * dim + q] - pop.x[r3 * dim + q]))
                .clamp(bounds.lower()[q], bounds.upper()[q]);
            // P57 binomial crossover.
            let rand_q: f64 = rng.gen();
            *uq = if rand_q <= cfg.crossover_rate || q == m {
                b
            } else {
                pop.x[j * dim + q]
            };
        }
        trial_f.push(run.eval(u));
    }
    // P58 greedy selection, applied after all trials exist (synchronous update).
    for (j, &fu) in trial_f.iter().enumerate() {
        if fu < pop.f[j] {
            pop.f[j] = fu;
            pop.x[j * dim..(j + 1) * dim].copy_from_slice(&trials[j * dim..(j + 1) * dim]);
        }
    }
}
