//! Where to measure next (model §7.12, P83): greedy selection of unmeasured segments by the
//! expected reduction of the network's weighted relative speed variance,
//!
//! gain(j | P) = Σ_i w_i g_iᵀ ΔS_i g_i / ĉ_i²,   ΔS_i = c_ij (v_j)⁻¹ c_jiᵀ,
//!
//! where g_i = ∂ĉ_i/∂u is how pipe i's predicted leak-band speed follows its soil (from the
//! prediction's quadrature), c_ij the field's posterior covariance of u_i with the hypothetical
//! measurement y_j = u_j + η_j of pipe j, and v_j that measurement's variance, all conditioned
//! on the earlier picks P (the Gaussian posterior's rank-2 updates, closed form). A pick's gain
//! only falls as picks are added (the variance reduction is submodular), so the greedy search
//! re-evaluates lazily (Krause, Singh & Guestrin 2008): only the candidate on top.
//!
//! The hypothetical measurement of pipe j carries the information of a fit of a pipe like it in
//! this network: the entrywise median of the stored information of the fitted pipes of its
//! material (of all fitted pipes when none of its material is fitted) — the frequency plans and
//! noise the network's campaigns actually had.

use std::cmp::Ordering;
use std::collections::{BTreeMap, BinaryHeap};

use rayon::prelude::*;

use super::model::{dist, index_of, Field, Index, Sym2};
use super::Site;

/// What a candidate's measurement is taken to be, as `plan` states it to the user (the
/// information of [`typical_information`]).
pub const HYPOTHETICAL_MEASUREMENT: &str = "each candidate is valued as if it were measured the \
way the network's fitted pipes of its material were (a typical one of their fits: their \
frequencies and their noise), or like all fitted pipes when none of its material is fitted";

/// The length of pipe in which `plan` expresses a gain: a gain g is as much as removing a
/// relative speed error of √(g / L) from L metres of pipe.
pub const GAIN_REFERENCE_LENGTH_M: f64 = 100.0;

/// `expected_gain` in the user's units: the fall of Σ w (σ / ĉ)² over the network, w in the
/// weight's unit (metres of pipe without risk weights), told as the speed error it would
/// remove from [`GAIN_REFERENCE_LENGTH_M`] of pipe (`gain` finite and ≥ 0).
pub fn gain_in_words(gain: f64, weight_unit: &str) -> String {
    let rel = (gain.max(0.0) / GAIN_REFERENCE_LENGTH_M).sqrt();
    format!(
        "expected_gain is how much the measurement would lower the network's sum of weight x \
         (speed error / speed)^2, the weight in {weight_unit}: {gain:.3} is as much as removing a \
         {:.1} % error of the leak-band speed from {GAIN_REFERENCE_LENGTH_M:.0} m of pipe",
        100.0 * rel
    )
}

/// A segment's weight w_i in P83: its `risk_weight` where the inventory gives one, else its
/// length in metres (1 when it has none).
pub fn weight_of(site: &Site) -> f64 {
    site.risk_weight
        .unwrap_or_else(|| site.length.filter(|l| *l > 0.0).unwrap_or(1.0))
}

/// Unmeasured segments whose variance a measurement can reduce: the nearest this many to it
/// (the field's posterior correlation falls as e^(−d/ℓ); further pipes gain little).
pub const AFFECTED: usize = 48;

/// Earlier picks further than this many correlation lengths from a candidate are left out of
/// its conditioning (their correlation with it is below e⁻⁵).
pub const PICK_REACH_LENGTHS: f64 = 5.0;

/// One candidate: an unmeasured segment with a predicted speed.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// Index into the sites.
    pub site: usize,
    /// Its midpoint, m.
    pub pos: [f64; 2],
    /// Its soil class.
    pub class: usize,
    /// Its weight ([`weight_of`]: risk weight, else length in m).
    pub weight: f64,
    /// Predicted leak-band speed ĉ, m/s.
    pub speed: f64,
    /// ∂ĉ/∂u, m/s.
    pub gradient: [f64; 2],
    /// Posterior covariance of its u.
    pub cov: Sym2,
    /// Noise of a hypothetical measurement of it: t_k T + I⁻¹ of a fit like it.
    pub noise: Sym2,
    /// Its kriging weights (2 × 2k, row-major) and neighbours (field members).
    weights: (Vec<f64>, Vec<usize>),
}

/// The posterior cross-covariance of the field w between two candidates (i ≠ j):
/// √(b_i b_j) B ρ(d_ij) − A_i c(N_i, x_j) (class multipliers of B as in the field).
fn cross(field: &Field, a: &Candidate, b: &Candidate) -> Sym2 {
    let mut k = field.kernel_classes(a.pos, a.class, b.pos, b.class);
    let (w, nb) = &a.weights;
    let n2 = 2 * nb.len();
    for (p, &m) in nb.iter().enumerate() {
        let Some(pm) = field.obs[m].pos else {
            continue;
        };
        let c = field.kernel_classes(pm, field.obs[m].class, b.pos, b.class);
        // (A c)[r][s] = Σ_t A[r][2p + t] c[t][s]
        let mut red = [[0.0; 2]; 2];
        for (r, row) in red.iter_mut().enumerate() {
            for (s, v) in row.iter_mut().enumerate() {
                *v = w[r * n2 + 2 * p] * c.at(0, s) + w[r * n2 + 2 * p + 1] * c.at(1, s);
            }
        }
        k = Sym2::new(
            k.pp - red[0][0],
            k.ps - 0.5 * (red[0][1] + red[1][0]),
            k.ss - red[1][1],
        );
    }
    k
}

/// Cov(u_a, y_b) before conditioning on picks: the posterior variance S_a when a = b.
fn cov_u_y(field: &Field, cands: &[Candidate], a: usize, b: usize) -> [[f64; 2]; 2] {
    let s = if a == b {
        cands[a].cov
    } else {
        cross(field, &cands[a], &cands[b])
    };
    [[s.pp, s.ps], [s.ps, s.ss]]
}

/// The greedy plan.
pub struct Planner<'a> {
    field: &'a Field,
    cands: Vec<Candidate>,
    tree: Index,
}

/// A dense small matrix helper: 2×2 blocks into a DMatrix.
fn block_matrix(blocks: &[Vec<[[f64; 2]; 2]>], rows: usize, cols: usize) -> nalgebra::DMatrix<f64> {
    let mut m = nalgebra::DMatrix::zeros(2 * rows, 2 * cols);
    for (r, row) in blocks.iter().enumerate() {
        for (c, b) in row.iter().enumerate() {
            for a in 0..2 {
                for d in 0..2 {
                    m[(2 * r + a, 2 * c + d)] = b[a][d];
                }
            }
        }
    }
    m
}

/// Heap entry: a candidate and its (upper bound on the) gain; ties to the lower index.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    gain: f64,
    cand: usize,
    /// Number of picks the gain was computed with.
    at: usize,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        self.gain
            .total_cmp(&o.gain)
            .then_with(|| o.cand.cmp(&self.cand))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The median information of fitted pipes by material (entrywise, then clipped to positive
/// semi-definite), and of all of them.
pub fn typical_information(
    sites: &[Site],
    field: &Field,
) -> (BTreeMap<String, Sym2>, Option<Sym2>) {
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let summarise = |infos: &[Sym2]| -> Option<Sym2> {
        if infos.is_empty() {
            return None;
        }
        let mut pp: Vec<f64> = infos.iter().map(|i| i.pp).collect();
        let mut ps: Vec<f64> = infos.iter().map(|i| i.ps).collect();
        let mut ss: Vec<f64> = infos.iter().map(|i| i.ss).collect();
        let (pp, ps, ss) = (median(&mut pp), median(&mut ps), median(&mut ss));
        let lim = (pp.max(0.0) * ss.max(0.0)).sqrt();
        Some(Sym2::new(pp.max(0.0), ps.clamp(-lim, lim), ss.max(0.0)))
    };
    let mut by: BTreeMap<String, Vec<Sym2>> = BTreeMap::new();
    for s in sites {
        if let Some(m) = s.member {
            by.entry(s.material.clone())
                .or_default()
                .push(field.obs[m].info);
        }
    }
    let all: Vec<Sym2> = by.values().flatten().copied().collect();
    (
        by.iter()
            .filter_map(|(k, v)| summarise(v).map(|s| (k.clone(), s)))
            .collect(),
        summarise(&all),
    )
}

/// A candidate's inputs: site index, posterior covariance, speed, gradient, information of
/// its hypothetical measurement.
pub struct CandidateInput {
    /// Index into the sites.
    pub site: usize,
    /// Midpoint, m.
    pub pos: [f64; 2],
    /// Soil class (index into the field's classes).
    pub class: usize,
    /// Weight.
    pub weight: f64,
    /// Predicted speed, m/s.
    pub speed: f64,
    /// ∂ĉ/∂u.
    pub gradient: [f64; 2],
    /// Posterior covariance of u.
    pub cov: Sym2,
    /// Information of a measurement of it.
    pub info: Sym2,
}

impl<'a> Planner<'a> {
    /// A planner over the candidates.
    pub fn new(field: &'a Field, inputs: Vec<CandidateInput>) -> Planner<'a> {
        let cands: Vec<Candidate> = inputs
            .into_par_iter()
            .map(|c| {
                let probe = super::model::Observation {
                    pos: Some(c.pos),
                    class: 0,
                    u: [0.0; 2],
                    info: c.info,
                    key: 0,
                    suspect: false,
                };
                Candidate {
                    site: c.site,
                    pos: c.pos,
                    class: c.class,
                    weight: c.weight,
                    speed: c.speed,
                    gradient: c.gradient,
                    cov: c.cov,
                    noise: field.scatter(c.class).add(&probe.noise()),
                    weights: field.weights(c.pos, c.class),
                }
            })
            .collect();
        let tree = index_of(cands.iter().map(|c| Some(c.pos)));
        Planner { field, cands, tree }
    }

    /// The candidates.
    pub fn candidates(&self) -> &[Candidate] {
        &self.cands
    }

    /// The gain of measuring candidate `j` after the picks `picks` (P83).
    pub fn gain(&self, j: usize, picks: &[usize]) -> f64 {
        let cj = &self.cands[j];
        let reach = PICK_REACH_LENGTHS * self.field.hyper.ell;
        let local: Vec<usize> = picks
            .iter()
            .copied()
            .filter(|&p| p != j && dist(self.cands[p].pos, cj.pos) <= reach)
            .collect();
        if picks.contains(&j) {
            return 0.0;
        }
        // Var(y_L) and its inverse.
        let nl = local.len();
        let cov_y = |a: usize, b: usize| -> [[f64; 2]; 2] {
            let mut m = cov_u_y(self.field, &self.cands, a, b);
            if a == b {
                let n = self.cands[a].noise;
                m[0][0] += n.pp;
                m[0][1] += n.ps;
                m[1][0] += n.ps;
                m[1][1] += n.ss;
            }
            m
        };
        let vl_inv = if nl > 0 {
            let blocks: Vec<Vec<[[f64; 2]; 2]>> = local
                .iter()
                .map(|&a| local.iter().map(|&b| cov_y(a, b)).collect())
                .collect();
            match block_matrix(&blocks, nl, nl).cholesky() {
                Some(c) => Some(c.inverse()),
                None => return 0.0,
            }
        } else {
            None
        };
        // Conditioned on L: c(a, j) − c(a, L) V⁻¹ c(L, j).
        let cond = |a_cov_j: [[f64; 2]; 2],
                    a_cov_l: &nalgebra::DMatrix<f64>,
                    l_cov_j: &nalgebra::DMatrix<f64>| {
            let mut m = nalgebra::DMatrix::from_fn(2, 2, |r, c| a_cov_j[r][c]);
            if let Some(vi) = &vl_inv {
                m -= a_cov_l * vi * l_cov_j;
            }
            m
        };
        let row = |a: usize, uy: bool| -> nalgebra::DMatrix<f64> {
            // Cov(u_a or y_a, y_L): 2 × 2nl.
            let blocks: Vec<Vec<[[f64; 2]; 2]>> = vec![local
                .iter()
                .map(|&b| {
                    if uy {
                        cov_u_y(self.field, &self.cands, a, b)
                    } else {
                        cov_y(a, b)
                    }
                })
                .collect()];
            block_matrix(&blocks, 1, nl)
        };
        let l_cov_j = row(j, false).transpose();
        let vj = cond(cov_y(j, j), &row(j, false), &l_cov_j);
        let Some(vj_inv) = vj.clone().cholesky().map(|c| c.inverse()) else {
            return 0.0;
        };
        let mut gain = 0.0;
        for g in self.tree.nearest_neighbor_iter(&cj.pos).take(AFFECTED) {
            let i = g.data as usize;
            let ci = &self.cands[i];
            let cij = cond(
                cov_u_y(self.field, &self.cands, i, j),
                &row(i, true),
                &l_cov_j,
            );
            let delta = &cij * &vj_inv * cij.transpose();
            let gv = nalgebra::Vector2::new(ci.gradient[0], ci.gradient[1]);
            let dvar = (gv.transpose() * delta * gv)[(0, 0)];
            if dvar.is_finite() && ci.speed > 0.0 {
                gain += ci.weight * dvar.max(0.0) / (ci.speed * ci.speed);
            }
        }
        gain
    }

    /// Pick `count` candidates greedily, each conditional on the earlier ones (lazy: a gain
    /// computed with fewer picks is an upper bound). Returns (candidate, gain) best first.
    pub fn pick(&self, count: usize) -> Vec<(usize, f64)> {
        let initial: Vec<f64> = (0..self.cands.len())
            .into_par_iter()
            .map(|j| self.gain(j, &[]))
            .collect();
        let mut heap: BinaryHeap<Entry> = initial
            .into_iter()
            .enumerate()
            .map(|(cand, gain)| Entry { gain, cand, at: 0 })
            .collect();
        let mut picks: Vec<usize> = Vec::new();
        let mut out = Vec::new();
        while out.len() < count {
            let Some(top) = heap.pop() else {
                break;
            };
            if top.at == picks.len() {
                picks.push(top.cand);
                out.push((top.cand, top.gain));
                continue;
            }
            let gain = self.gain(top.cand, &picks);
            heap.push(Entry {
                gain,
                cand: top.cand,
                at: picks.len(),
            });
        }
        out
    }
}

/// Why no plan could be made.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The database.
    #[error(transparent)]
    Db(#[from] crate::db::DbError),
    /// No field to plan with.
    #[error("no soil field yet: run calibrate first (the plan needs fitted segments and the field's predictions)")]
    NoField,
    /// Nothing to measure.
    #[error("no unmeasured segment with a predicted speed and a geometry to choose from")]
    NoCandidates,
}

/// Choose the next `count` segments to measure (P83) from the stored field, and store the plan.
/// Returns the picks, best first.
pub fn plan(
    conn: &mut rusqlite::Connection,
    count: usize,
    jobs: usize,
) -> Result<Vec<crate::db::field::PlanPick>, PlanError> {
    use crate::db::field as store;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .ok();
    let (last, field, sites) = super::stored_field(conn, &pool)?.ok_or(PlanError::NoField)?;
    let (by_material, overall) = typical_information(&sites, &field);
    let mut inputs = Vec::new();
    let mut current_std = BTreeMap::new();
    for (i, s) in sites.iter().enumerate() {
        let (Some(pos), None) = (s.pos, s.fitted_speed) else {
            continue;
        };
        let Some((p, _)) = store::prediction_for(conn, &s.segment_id)? else {
            continue;
        };
        let (Some((speed, std)), Some(gradient)) = (p.leak_band_speed, p.leak_band_speed_gradient)
        else {
            continue;
        };
        let Some(info) = by_material.get(&s.material).copied().or(overall) else {
            continue;
        };
        current_std.insert(i, std);
        let cov = field.posterior(Some(pos), s.class.unwrap_or(0), None).cov;
        inputs.push(CandidateInput {
            site: i,
            pos,
            class: s.class.unwrap_or(0),
            weight: weight_of(s),
            speed,
            gradient,
            cov,
            info,
        });
    }
    if inputs.is_empty() {
        return Err(PlanError::NoCandidates);
    }
    let picks = super::in_pool(&pool, || {
        let planner = Planner::new(&field, inputs);
        planner
            .pick(count)
            .into_iter()
            .map(|(c, gain)| {
                (
                    planner.candidates()[c].site,
                    planner.candidates()[c].weight,
                    gain,
                )
            })
            .collect::<Vec<_>>()
    });
    let out: Vec<store::PlanPick> = picks
        .into_iter()
        .enumerate()
        .map(|(r, (site, weight, gain))| store::PlanPick {
            rank: r as i64 + 1,
            segment_id: sites[site].segment_id.clone(),
            expected_gain: gain,
            leak_band_speed_std_m_per_s: current_std.get(&site).copied(),
            weight,
        })
        .collect();
    store::replace_plan(conn, last.id, &out)?;
    Ok(out)
}
