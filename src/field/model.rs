//! The Gaussian soil field of the network (model §7.12, P78–P80) in the two coordinates the
//! fits determine, u = (ln c_P, ln c_S):
//!
//! u_s = μ_k(s) + w(x_s) + ε_s,  Cov(w(x), w(x′)) = B e^(−|x − x′|/ℓ),  ε_s ~ N(0, T),
//!
//! observed through each fit as û_s with information I_s (P79). A fit's noise is I_s⁻¹, taken
//! as (I_s + ε·1)⁻¹ with ε = [`UNSEEN_PRECISION`]: a direction the data do not see keeps a
//! variance so large that it carries no weight, which is the information form of P80 without
//! a pseudo-inverse. The class means μ_k have a broad Gaussian prior about a typical soil and
//! are integrated out of the marginal likelihood exactly (they enter linearly), so a class with
//! no measured member keeps the prior and one seen only by metal pipes keeps the prior in c_S.
//!
//! Scale: every conditional is taken on the m = [`NEIGHBOURS`] nearest measured segments
//! (Vecchia 1988; Datta et al. 2016): the likelihood as the product of each member's density
//! given its nearest predecessors in a fixed order, the predictions given their nearest
//! members. Cost O(n m³), memory O(n m).

use nalgebra::{DMatrix, DVector, SMatrix};
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;

use crate::optimize::simplex::NelderMead;
use crate::optimize::{Bounds, FnObjective};

/// Measured neighbours each conditional is taken on (m of the nearest-neighbour GP; 16–32
/// reproduce the full GP's predictions to well below their error for an exponential kernel).
pub const NEIGHBOURS: usize = 16;

/// Precision added to every fit's information (in 1/(ln units)²): a direction the fit does not
/// see gets a standard deviation of 1/√ε = 30 in ln(speed), a factor e³⁰, i.e. no weight.
pub const UNSEEN_PRECISION: f64 = 1.0 / 900.0;

/// The typical soil the class means are drawn towards where no fit sees them (the
/// correlator's table soil of model §7.12: E_m = 5e7 Pa, ν_m = 0.33, ρ_m = 1900 kg/m³):
/// ln c_P and ln c_S, with c_P = 197.5 m/s and c_S = 99.5 m/s (P63, P64).
pub const TYPICAL_LN_SPEEDS: [f64; 2] = [5.285_7, 4.600_2];

/// Standard deviation of the class means' prior about [`TYPICAL_LN_SPEEDS`], ln units: a factor
/// e either way, wider than the range of c_P and c_S between soft clay and dense gravel.
pub const CLASS_PRIOR_SD: f64 = 1.0;

/// Fewer measured segments than this and the hyper-parameters are not estimated: the defaults
/// below are used and the field says so.
pub const MIN_MEMBERS_FOR_HYPER: usize = 12;

/// Default field variance of ln c_P and ln c_S (a 20 % spread inside a class), used with too
/// few members to estimate it.
pub const DEFAULT_FIELD_VAR: f64 = 0.04;
/// Default per-pipe scatter variance (7 % in speed: trench and backfill).
pub const DEFAULT_SCATTER_VAR: f64 = 0.005;
/// Default correlation between the field's ln c_P and ln c_S.
pub const DEFAULT_FIELD_CORR: f64 = 0.5;

/// Predecessors each member is conditioned on in the marginal likelihood (the hyper-parameter
/// search evaluates it a few hundred times; an exponential kernel's Vecchia likelihood is
/// already close to the exact one with 10, and the predictions keep [`NEIGHBOURS`]).
pub const LIKELIHOOD_NEIGHBOURS: usize = 10;

/// Evaluation budget of the marginal-likelihood search over the six hyper-parameters.
pub const HYPER_EVALUATIONS: usize = 250;

/// The search stops when the log-likelihood improved by less than this over
/// [`HYPER_STALL_EVALUATIONS`] evaluations: a change of 0.01 moves no hyper-parameter by more
/// than a small fraction of its own uncertainty.
pub const HYPER_STALL_TOL: f64 = 1e-2;
/// See [`HYPER_STALL_TOL`].
pub const HYPER_STALL_EVALUATIONS: usize = 50;

/// χ² of a member's u against its leave-one-out prediction from its neighbours beyond which
/// the field cannot explain it: χ²₂ at p = 0.001 (a field that describes its members well
/// screens about one in a thousand). Such a fit (e.g. a metal fit in a rock-like second basin
/// of its misfit, its ln c_P off by 1–3 while its information claims σ 0.05–0.3) has its
/// information scaled down before the hyper-parameters are refitted (P79–P80).
pub const SCREEN_CHI2: f64 = 13.8;

/// The screening's χ² for a member whose own fit says its information may mislead
/// ([`Observation::suspect`]): χ²₂ at p = 0.10. Measured on synthetic networks against the truth,
/// such fits state information that the truth lies far outside (χ² > 13.8 in it) in 30–100 % of
/// cases, the others in 1–3 % (docs/field-validation.md, "Members whose fit doubts itself").
pub const SCREEN_CHI2_SUSPECT: f64 = 4.605;

/// The χ² a screened member is brought to by scaling its information: the expectation of χ²₂,
/// i.e. its claimed noise is widened (a Birge ratio against its neighbourhood, as P88 does
/// against its own residuals) until its distance from the field is typical.
pub const SCREEN_TARGET_CHI2: f64 = 2.0;

/// Rounds of screening and refitting the hyper-parameters (each round's screening uses the
/// previous round's field, whose per-pipe scatter the screened fits no longer inflate).
pub const SCREEN_ROUNDS: usize = 2;

/// Smallest factor the screening may shrink the per-pipe scatter T by (see
/// [`Field::robust_scatter_factor`]): a factor 1000 reaches from an inflated T of a few tenths
/// down to a trench scatter of one per cent.
pub const MIN_SCREEN_SCATTER_FACTOR: f64 = 1e-3;

/// A direction of a fit's information counts as seen when its eigenvalue is at least this (ln
/// units⁻²): the fit pins that direction to within a factor e, the width of the class prior.
/// Along an unseen direction the fitted value does not scatter as its noise claims (the fit
/// reports wherever its search stopped), so it adds nothing to the χ² and the member's χ² has
/// one degree of freedom per seen direction.
pub const SEEN_INFORMATION: f64 = 1.0 / (CLASS_PRIOR_SD * CLASS_PRIOR_SD);

/// Standard deviation of the prior of each class's ln multiplier of B and of T: a factor 1.65
/// either way at one sigma. It holds the multipliers near 1 where a class has few members and
/// breaks the degeneracy between the common B, T and the multipliers.
pub const CLASS_SCALE_PRIOR_SD: f64 = 0.5;

/// A class with fewer members keeps multipliers 1 (too few to estimate a spread of its own).
pub const MIN_MEMBERS_FOR_CLASS_SCALE: usize = 5;

/// Range of the class multipliers searched.
const CLASS_SCALE_RANGE: (f64, f64) = (0.05, 20.0);

/// Members whose marginal likelihood (P80) the hyper-parameter searches maximise: the first
/// this many of the conditioning order, a random subset (the order is a hash of the segment
/// ids). Every member still enters the class means, the screening and the predictions (P80,
/// P82); only θ of P78 and the class multipliers are estimated on the subset. Adequate because
/// θ has six components (and two multipliers per class): the likelihood of n members pins
/// each to a relative standard error of about √(2/n), 9 % at 250, while the cost of each of
/// the searches' several hundred evaluations falls in proportion (at 1,000 members by 75 %,
/// at 10,000 by 97.5 %). On the 10,000-segment network of docs/field.md, 250 members instead
/// of 500 leave the unmeasured pipes' errors as they were (plastic median 1.19 → 1.18 %,
/// p90 3.95 → 3.98 %, truth within 2σ 96.7 → 96.9 %).
/// The subset's nearest-neighbour spacing grows by √(n/250), so ℓ alone is less sharply
/// determined and trades against B; the kriging predictions and their variances rest mainly
/// on B/ℓ for an exponential kernel (Stein 1999), which the subset still pins.
pub const HYPER_MEMBERS: usize = 250;

/// Bracket width in ln τ at which [`Field::robust_scatter_factor`] (the screening of P79–P80)
/// stops: 1 % in τ. The factor rests on the median of the members' χ² distribution functions,
/// itself uncertain by about 0.5/√n in probability (1.6 % at n = 1000, several per cent in
/// τ), so a finer τ would be noise.
const ROBUST_LN_TAU_TOL: f64 = 0.01;

/// Most steps of that search (it stops by [`ROBUST_LN_TAU_TOL`] in five to eight).
const ROBUST_MAX_STEPS: usize = 30;

/// Evaluation budget of each refit after screening (warm-started from the previous optimum).
const REFIT_EVALUATIONS: usize = 150;

/// Range of the variances searched (ln units²): from a 0.1 % spread to a factor e^1.4.
const VAR_RANGE: (f64, f64) = (1e-6, 2.0);
/// Range of the field's correlation between ln c_P and ln c_S.
const CORR_RANGE: (f64, f64) = (-0.95, 0.95);

/// A symmetric 2 × 2 matrix [[pp, ps], [ps, ss]] in (ln c_P, ln c_S).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sym2 {
    /// (ln c_P, ln c_P) entry.
    pub pp: f64,
    /// Off-diagonal entry.
    pub ps: f64,
    /// (ln c_S, ln c_S) entry.
    pub ss: f64,
}

impl Sym2 {
    /// From its three entries.
    pub const fn new(pp: f64, ps: f64, ss: f64) -> Self {
        Sym2 { pp, ps, ss }
    }

    /// k times the identity.
    pub const fn diag(k: f64) -> Self {
        Sym2::new(k, 0.0, k)
    }

    /// Entry (i, j), i, j ∈ {0, 1}.
    pub fn at(&self, i: usize, j: usize) -> f64 {
        match (i, j) {
            (0, 0) => self.pp,
            (1, 1) => self.ss,
            _ => self.ps,
        }
    }

    /// The sum.
    pub fn add(&self, o: &Sym2) -> Sym2 {
        Sym2::new(self.pp + o.pp, self.ps + o.ps, self.ss + o.ss)
    }

    /// Times a scalar.
    pub fn scale(&self, k: f64) -> Sym2 {
        Sym2::new(k * self.pp, k * self.ps, k * self.ss)
    }

    /// D S D with D = diag(`d`): a covariance's standard deviations multiplied by `d` per axis,
    /// its correlation kept.
    pub fn scale_axes(&self, d: [f64; 2]) -> Sym2 {
        Sym2::new(
            self.pp * d[0] * d[0],
            self.ps * d[0] * d[1],
            self.ss * d[1] * d[1],
        )
    }

    /// Determinant.
    pub fn det(&self) -> f64 {
        self.pp * self.ss - self.ps * self.ps
    }

    /// The inverse, `None` unless positive definite.
    pub fn inverse(&self) -> Option<Sym2> {
        let d = self.det();
        (self.pp > 0.0 && d > 0.0).then(|| Sym2::new(self.ss / d, -self.ps / d, self.pp / d))
    }

    /// The quadratic form vᵀ S v.
    pub fn quad(&self, v: [f64; 2]) -> f64 {
        self.pp * v[0] * v[0] + 2.0 * self.ps * v[0] * v[1] + self.ss * v[1] * v[1]
    }

    /// S v.
    pub fn mul(&self, v: [f64; 2]) -> [f64; 2] {
        [
            self.pp * v[0] + self.ps * v[1],
            self.ps * v[0] + self.ss * v[1],
        ]
    }

    /// The lower Cholesky factor [[l00, 0], [l10, l11]], `None` unless positive definite.
    pub fn cholesky(&self) -> Option<[f64; 3]> {
        if self.pp.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let l00 = self.pp.sqrt();
        let l10 = self.ps / l00;
        let r = self.ss - l10 * l10;
        (r > 0.0).then(|| [l00, l10, r.sqrt()])
    }
}

/// One measured segment as the field sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Its midpoint, m (None: no geometry; it then informs its class mean only).
    pub pos: Option<[f64; 2]>,
    /// Its soil class (index into the field's classes).
    pub class: usize,
    /// The fitted (ln c_P, ln c_S).
    pub u: [f64; 2],
    /// The fit's information about u (P79), divided by its variance factor.
    pub info: Sym2,
    /// A key fixing its place in the conditioning order (a hash of the segment id, so the
    /// order does not depend on how the segments were read).
    pub key: u64,
    /// Its fit says its information may mislead: a wave near grazing (a cusp of the misfit,
    /// model §5.6, whose curvature claims more than the misfit holds), or a metal pipe's soil
    /// undetermined (its one determined speed, c_P, not pinned: often a second basin). Screened
    /// at [`SCREEN_CHI2_SUSPECT`] instead of [`SCREEN_CHI2`].
    pub suspect: bool,
}

impl Observation {
    /// The fit's noise covariance (I_s + ε·1)⁻¹.
    pub fn noise(&self) -> Sym2 {
        self.noise_scaled(1.0)
    }

    /// The noise with the information multiplied by `s`: (s I_s + ε·1)⁻¹.
    pub fn noise_scaled(&self, s: f64) -> Sym2 {
        self.info
            .scale(s)
            .add(&Sym2::diag(UNSEEN_PRECISION))
            .inverse()
            .unwrap_or(Sym2::diag(1.0 / UNSEEN_PRECISION))
    }
}

/// The field's hyper-parameters θ = (B, ℓ, T) of P78 (the class means are integrated out).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hyper {
    /// Field covariance B of (ln c_P, ln c_S).
    pub b: Sym2,
    /// Correlation length ℓ, m.
    pub ell: f64,
    /// Per-pipe scatter T (diagonal).
    pub t: Sym2,
}

impl Hyper {
    /// The defaults used when too few segments are measured to estimate them.
    pub fn defaults(ell: f64) -> Hyper {
        let c = DEFAULT_FIELD_CORR * DEFAULT_FIELD_VAR;
        Hyper {
            b: Sym2::new(DEFAULT_FIELD_VAR, c, DEFAULT_FIELD_VAR),
            ell,
            t: Sym2::diag(DEFAULT_SCATTER_VAR),
        }
    }

    /// Field covariance between two points a distance `d` (m) apart: B e^(−d/ℓ) (P78).
    pub fn kernel(&self, d: f64) -> Sym2 {
        self.b.scale((-d / self.ell).exp())
    }
}

/// Euclidean distance, m (the plain root of the squares: map coordinates are far from
/// overflow, and `hypot`'s care costs several times as much in the conditionals' loops).
pub fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    (dx * dx + dy * dy).sqrt()
}

/// A spatial index of points carrying their index.
pub type Index = RTree<GeomWithData<[f64; 2], u32>>;

/// The index of the positioned points of `pos` (bulk-loaded: the same tree for the same
/// points, whatever the thread count).
pub fn index_of(pos: impl Iterator<Item = Option<[f64; 2]>>) -> Index {
    let pts: Vec<_> = pos
        .enumerate()
        .filter_map(|(i, p)| p.map(|p| GeomWithData::new(p, i as u32)))
        .collect();
    RTree::bulk_load(pts)
}

/// The conditional of a target given neighbours: A = c C⁻¹ (2 × 2k, the kriging weights) and
/// V = C_tt − A cᵀ, where C is the neighbours' covariance (field + their noise) and c the
/// target's cross-covariance with them.
struct Conditional {
    a: DMatrix<f64>,
    v: Sym2,
}

/// What the conditionals are taken with: the hyper-parameters, the members, each member's
/// noise (its class's scatter t_k T plus its fit's (s_i I_i + ε)⁻¹) and the square root of its
/// class's multiplier of B. A class multiplier b_k scales the field inside class k as
/// w_k(x) = √b_k w(x), so Cov(w(x), w(x′)) = √(b_k b_k′) B e^(−|x − x′|/ℓ): positive definite
/// across class boundaries (P78 with a class-dependent amplitude).
struct Terms<'a> {
    hyper: &'a Hyper,
    obs: &'a [Observation],
    noise: &'a [Sym2],
    root_b: &'a [f64],
}

impl Terms<'_> {
    /// The field covariance between members i and j (i ≠ j) at distance `d` apart.
    fn between_at(&self, i: usize, j: usize, d: f64) -> Sym2 {
        self.hyper.kernel(d).scale(self.root_b[i] * self.root_b[j])
    }

    /// Member i's own variance: b_i B + its noise.
    fn own(&self, i: usize) -> Sym2 {
        self.hyper
            .b
            .scale(self.root_b[i] * self.root_b[i])
            .add(&self.noise[i])
    }
}

/// The distances a conditional's covariances take (m): the target's to each neighbour, then
/// each pair of neighbours (p, q < p) row by row; ∞ where either has no position (then the
/// kernel e^(−d/ℓ) is 0: independent). They do not depend on θ, so the marginal likelihood's
/// Vecchia conditionals take them from [`Vecchia`], computed once per field.
fn distances(obs: &[Observation], pos: Option<[f64; 2]>, nbrs: &[usize]) -> Vec<f64> {
    let d = |a: Option<[f64; 2]>, b: Option<[f64; 2]>| match (a, b) {
        (Some(a), Some(b)) => dist(a, b),
        _ => f64::INFINITY,
    };
    let mut out = Vec::with_capacity(nbrs.len() * (nbrs.len() + 1) / 2);
    out.extend(nbrs.iter().map(|&i| d(pos, obs[i].pos)));
    for (p, &i) in nbrs.iter().enumerate() {
        out.extend(nbrs[..p].iter().map(|&j| d(obs[i].pos, obs[j].pos)));
    }
    out
}

/// The conditional of a target at `pos` (√ of its class's multiplier of B `root_b`) with
/// variance `target_var`, given the members `nbrs`.
fn conditional(
    t: &Terms,
    pos: Option<[f64; 2]>,
    root_b: f64,
    target_var: Sym2,
    nbrs: &[usize],
) -> Option<Conditional> {
    conditional_at(t, root_b, target_var, nbrs, &distances(t.obs, pos, nbrs))
}

/// [`conditional`] with the target's and neighbours' [`distances`] `d`: in fixed-size
/// matrices ([`conditional_stack`]) up to [`NEIGHBOURS`] neighbours, as every posterior has.
fn conditional_at(
    t: &Terms,
    root_b: f64,
    target_var: Sym2,
    nbrs: &[usize],
    d: &[f64],
) -> Option<Conditional> {
    let k = nbrs.len();
    if k == 0 || k > NEIGHBOURS {
        return conditional_dense(t, root_b, target_var, nbrs, d);
    }
    let (a, v) = conditional_stack::<POSTERIOR_DIM>(t, root_b, target_var, k, |p| nbrs[p], d)?;
    Some(Conditional {
        a: DMatrix::from_fn(2, 2 * k, |r, c| a[(r, c)]),
        v,
    })
}

/// The covariance C of the k neighbours' observed u (`nbr(p)` the p-th; field, scatter and
/// noise, P78–P79) and their cross-covariance cᵀ with the target's u (class scale `root_b`),
/// written element by element through `set_c` and `set_ct` into whatever matrices hold them.
/// `d` holds the target's distances to the neighbours, then those of each pair (p, q < p) at
/// k + p(p − 1)/2 + q.
fn fill_conditional(
    t: &Terms,
    root_b: f64,
    k: usize,
    nbr: impl Fn(usize) -> usize,
    d: &[f64],
    mut set_c: impl FnMut(usize, usize, f64),
    mut set_ct: impl FnMut(usize, usize, f64),
) {
    let mut pair = k;
    for p in 0..k {
        let i = nbr(p);
        for q in 0..=p {
            let s = if p == q {
                t.own(i)
            } else {
                pair += 1;
                t.between_at(i, nbr(q), d[pair - 1])
            };
            for a in 0..2 {
                for b in 0..2 {
                    set_c(2 * p + a, 2 * q + b, s.at(a, b));
                    set_c(2 * q + b, 2 * p + a, s.at(a, b));
                }
            }
        }
        let s = t.hyper.kernel(d[p]).scale(root_b * t.root_b[i]);
        for a in 0..2 {
            for b in 0..2 {
                set_ct(2 * p + a, b, s.at(a, b));
            }
        }
    }
}

/// Rows and columns of a posterior's conditional covariance: two per neighbour.
const POSTERIOR_DIM: usize = 2 * NEIGHBOURS;

/// [`conditional_at`] in heap matrices of the neighbours' own size.
fn conditional_dense(
    t: &Terms,
    root_b: f64,
    target_var: Sym2,
    nbrs: &[usize],
    d: &[f64],
) -> Option<Conditional> {
    let k = nbrs.len();
    if k == 0 {
        return Some(Conditional {
            a: DMatrix::zeros(2, 0),
            v: target_var,
        });
    }
    let mut c = DMatrix::<f64>::zeros(2 * k, 2 * k);
    let mut ct = DMatrix::<f64>::zeros(2 * k, 2);
    fill_conditional(
        t,
        root_b,
        k,
        |p| nbrs[p],
        d,
        |r, col, v| c[(r, col)] = v,
        |r, col, v| ct[(r, col)] = v,
    );
    let chol = c.cholesky()?;
    let x = chol.solve(&ct); // C⁻¹ cᵀ (2k × 2)
    let reduce = ct.transpose() * &x; // c C⁻¹ cᵀ
    let v = Sym2::new(
        target_var.pp - reduce[(0, 0)],
        target_var.ps - 0.5 * (reduce[(0, 1)] + reduce[(1, 0)]),
        target_var.ss - reduce[(1, 1)],
    );
    Some(Conditional {
        a: x.transpose(),
        v,
    })
}

/// The Vecchia structure: each member's nearest predecessors in a fixed order.
#[derive(Debug, Clone)]
pub struct Vecchia {
    /// Member indices in conditioning order.
    order: Vec<usize>,
    /// Offsets into `nbrs` per position of `order` (length n + 1).
    start: Vec<usize>,
    /// Neighbour member indices, flat.
    nbrs: Vec<u32>,
    /// Offsets into `dists` per position of `order` (length n + 1).
    dstart: Vec<usize>,
    /// Each member's [`distances`] to and between its neighbours, flat.
    dists: Vec<f64>,
}

impl Vecchia {
    /// Order the members by their keys and find each one's `m` nearest predecessors (members
    /// without a position have none, and are nobody's neighbour).
    pub fn new(obs: &[Observation], m: usize) -> Vecchia {
        let mut order: Vec<usize> = (0..obs.len()).collect();
        order.sort_by_key(|&i| (obs[i].key, i));
        let mut tree: Index = RTree::new();
        let mut start = Vec::with_capacity(obs.len() + 1);
        let mut nbrs = Vec::with_capacity(obs.len() * m);
        start.push(0);
        for &i in &order {
            if let Some(p) = obs[i].pos {
                nbrs.extend(tree.nearest_neighbor_iter(&p).take(m).map(|g| g.data));
                tree.insert(GeomWithData::new(p, i as u32));
            }
            start.push(nbrs.len());
        }
        let mut dstart = Vec::with_capacity(obs.len() + 1);
        let mut dists = Vec::with_capacity(obs.len() * m * (m + 1) / 2);
        dstart.push(0);
        for (p, &i) in order.iter().enumerate() {
            let nb: Vec<usize> = nbrs[start[p]..start[p + 1]]
                .iter()
                .map(|&j| j as usize)
                .collect();
            dists.extend(distances(obs, obs[i].pos, &nb));
            dstart.push(dists.len());
        }
        Vecchia {
            order,
            start,
            nbrs,
            dstart,
            dists,
        }
    }

    fn neighbours(&self, pos: usize) -> Vec<usize> {
        self.nbrs[self.start[pos]..self.start[pos + 1]]
            .iter()
            .map(|&j| j as usize)
            .collect()
    }
}

/// Sufficient statistics of one Vecchia pass: the Gaussian in the class means.
struct Pass {
    /// Σ Zᵀ V⁻¹ Z (2K × 2K).
    g: DMatrix<f64>,
    /// Σ Zᵀ V⁻¹ ỹ.
    r: DVector<f64>,
    /// Σ ỹᵀ V⁻¹ ỹ.
    s: f64,
    /// Σ ln det V.
    logdet: f64,
}

impl Pass {
    fn zero(nk: usize) -> Pass {
        Pass {
            g: DMatrix::zeros(2 * nk, 2 * nk),
            r: DVector::zeros(2 * nk),
            s: 0.0,
            logdet: 0.0,
        }
    }

    fn absorb(&mut self, o: Pass) {
        self.g += o.g;
        self.r += o.r;
        self.s += o.s;
        self.logdet += o.logdet;
    }
}

/// The design row Z = X_t − A X_N of a target in class `class` given neighbours `nbrs`: per
/// touched class, its 2 × 2 block.
fn design(
    class: usize,
    a: impl Fn(usize, usize) -> f64,
    nbrs: impl IntoIterator<Item = usize>,
    obs: &[Observation],
) -> Vec<(usize, [f64; 4])> {
    let mut z: Vec<(usize, [f64; 4])> = vec![(class, [1.0, 0.0, 0.0, 1.0])];
    for (p, j) in nbrs.into_iter().enumerate() {
        let k = obs[j].class;
        let blk = [
            -a(0, 2 * p),
            -a(0, 2 * p + 1),
            -a(1, 2 * p),
            -a(1, 2 * p + 1),
        ];
        match z.iter_mut().find(|(c, _)| *c == k) {
            Some((_, b)) => {
                for (x, y) in b.iter_mut().zip(blk) {
                    *x += y;
                }
            }
            None => z.push((k, blk)),
        }
    }
    z
}

/// Members per parallel chunk of a pass (fixed, so sums are taken in one order whatever the
/// thread count).
const PASS_CHUNK: usize = 256;

/// Rows and columns of a likelihood conditional's covariance: two per predecessor.
const LIKELIHOOD_DIM: usize = 2 * LIKELIHOOD_NEIGHBOURS;

/// The kriging weights A of a likelihood conditional: on the stack (at most
/// [`LIKELIHOOD_NEIGHBOURS`] predecessors, as every field's structure has), else on the heap.
/// The stack variant is the larger by design: a value lives for one member of one pass, and
/// boxing it would bring back the allocation it exists to avoid.
#[allow(clippy::large_enum_variant)]
enum Weights {
    Stack(SMatrix<f64, 2, LIKELIHOOD_DIM>),
    Heap(DMatrix<f64>),
}

impl Weights {
    fn at(&self, r: usize, c: usize) -> f64 {
        match self {
            Weights::Stack(a) => a[(r, c)],
            Weights::Heap(a) => a[(r, c)],
        }
    }
}

/// [`conditional_dense`] for k ≤ N/2 neighbours (`nbr(p)` the p-th) in N × N matrices on the
/// stack (no allocation; the marginal likelihood takes ~10⁶ of them per field, the
/// predictions and screenings tens of thousands). With k < N/2 neighbours the covariance is
/// padded with the identity and the cross-covariance with zeros: C' = diag(C, 1) has the
/// Cholesky factor diag(L, 1) and C'⁻¹ c'ᵀ = (C⁻¹ cᵀ, 0), so A (its first 2k columns; the
/// rest are 0) and V are those of the k neighbours exactly.
fn conditional_stack<const N: usize>(
    t: &Terms,
    root_b: f64,
    target_var: Sym2,
    k: usize,
    nbr: impl Fn(usize) -> usize,
    d: &[f64],
) -> Option<(SMatrix<f64, 2, N>, Sym2)> {
    let mut c = SMatrix::<f64, N, N>::identity();
    let mut ct = SMatrix::<f64, N, 2>::zeros();
    fill_conditional(
        t,
        root_b,
        k,
        nbr,
        d,
        |r, col, v| c[(r, col)] = v,
        |r, col, v| ct[(r, col)] = v,
    );
    let chol = c.cholesky()?;
    let x = chol.solve(&ct);
    let reduce = ct.transpose() * x;
    let v = Sym2::new(
        target_var.pp - reduce[(0, 0)],
        target_var.ps - 0.5 * (reduce[(0, 1)] + reduce[(1, 0)]),
        target_var.ss - reduce[(1, 1)],
    );
    Some((x.transpose(), v))
}

/// One Vecchia pass over the first `limit` members of the conditioning order: `None` when a
/// conditional is not positive definite. A member's predecessors come before it in the
/// order, so the pass over a prefix is the Vecchia likelihood of exactly those members.
fn pass(t: &Terms, v: &Vecchia, nk: usize, limit: usize) -> Option<Pass> {
    let obs = t.obs;
    let positions: Vec<usize> = (0..v.order.len().min(limit)).collect();
    let parts: Vec<Option<Pass>> = positions
        .par_chunks(PASS_CHUNK)
        .map(|chunk| {
            let mut acc = Pass::zero(nk);
            for &pos in chunk {
                let i = v.order[pos];
                let nb = &v.nbrs[v.start[pos]..v.start[pos + 1]];
                let o = &obs[i];
                let d = &v.dists[v.dstart[pos]..v.dstart[pos + 1]];
                let (a, cv) = if nb.len() <= LIKELIHOOD_NEIGHBOURS {
                    let (a, cv) = conditional_stack::<LIKELIHOOD_DIM>(
                        t,
                        t.root_b[i],
                        t.own(i),
                        nb.len(),
                        |p| nb[p] as usize,
                        d,
                    )?;
                    (Weights::Stack(a), cv)
                } else {
                    let c = conditional_dense(t, t.root_b[i], t.own(i), &v.neighbours(pos), d)?;
                    (Weights::Heap(c.a), c.v)
                };
                let vinv = cv.inverse()?;
                let mut yt = o.u;
                for (p, &j) in nb.iter().enumerate() {
                    let uj = obs[j as usize].u;
                    for (r, y) in yt.iter_mut().enumerate() {
                        *y -= a.at(r, 2 * p) * uj[0] + a.at(r, 2 * p + 1) * uj[1];
                    }
                }
                acc.s += vinv.quad(yt);
                acc.logdet += cv.det().ln();
                let z = design(
                    o.class,
                    |r, c| a.at(r, c),
                    nb.iter().map(|&j| j as usize),
                    obs,
                );
                // Zᵀ V⁻¹ for each touched class block: blockᵀ V⁻¹.
                let zt_vinv: Vec<(usize, [f64; 4])> = z
                    .iter()
                    .map(|(k, b)| {
                        // (bᵀ V⁻¹)[r][c] = Σ_a b[a][r] V⁻¹[a][c]
                        let mut m = [0.0; 4];
                        for r in 0..2 {
                            for c in 0..2 {
                                m[2 * r + c] = b[r] * vinv.at(0, c) + b[2 + r] * vinv.at(1, c);
                            }
                        }
                        (*k, m)
                    })
                    .collect();
                for (k, m) in &zt_vinv {
                    for r in 0..2 {
                        acc.r[2 * k + r] += m[2 * r] * yt[0] + m[2 * r + 1] * yt[1];
                    }
                    for (l, b) in &z {
                        for r in 0..2 {
                            for c in 0..2 {
                                acc.g[(2 * k + r, 2 * l + c)] +=
                                    m[2 * r] * b[c] + m[2 * r + 1] * b[2 + c];
                            }
                        }
                    }
                }
            }
            Some(acc)
        })
        .collect();
    let mut total = Pass::zero(nk);
    for p in parts {
        total.absorb(p?);
    }
    Some(total)
}

/// The class means' prior precision (diagonal) and mean.
fn class_prior(nk: usize) -> (f64, DVector<f64>) {
    let prec = 1.0 / (CLASS_PRIOR_SD * CLASS_PRIOR_SD);
    let m0 = DVector::from_fn(2 * nk, |i, _| TYPICAL_LN_SPEEDS[i % 2]);
    (prec, m0)
}

/// A class mean given to the field from outside rather than estimated by it: a declared soil
/// zone's soil from the hierarchical model of its members (model §7.11–7.12, P67–P68).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassMean {
    /// (ln c_P, ln c_S) at [`Self::density`].
    pub mean: [f64; 2],
    /// Its covariance (the zone's posterior error).
    pub cov: Sym2,
    /// The soil density the speeds are given at, kg/m³: a pipe of density ρ in the class has
    /// the mean shifted by −½ ln(ρ/ρ_k) in both speeds (P63–P64 at fixed E_m, ν_m).
    pub density: f64,
}

impl ClassMean {
    /// The shift of both ln speeds from the class's density to `rho` (P63–P64: c ∝ ρ^(−1/2)
    /// at fixed E_m and ν_m); 0 where either density is unusable.
    pub fn shift(&self, rho: f64) -> f64 {
        let d = -0.5 * (rho / self.density).ln();
        if d.is_finite() {
            d
        } else {
            0.0
        }
    }
}

/// The class means' posterior given a pass: mean and covariance (2K), and the log marginal
/// likelihood. The classes with a given mean ([`ClassMean`]) take it and its covariance as
/// they are: the pass's Gaussian in the means, s − 2 rᵀμ + μᵀ G μ, is conditioned on them,
/// and only the other classes' means are integrated out under their prior, so the given means'
/// members are not counted a second time in their own class mean.
fn class_posterior(
    p: &Pass,
    nk: usize,
    given: &[Option<ClassMean>],
) -> Option<(DVector<f64>, DMatrix<f64>, f64)> {
    let (prec, m0) = class_prior(nk);
    let given_of = |k: usize| given.get(k).and_then(Option::as_ref);
    let free: Vec<usize> = (0..2 * nk).filter(|&i| given_of(i / 2).is_none()).collect();
    let mut fixed = DVector::zeros(2 * nk);
    for k in 0..nk {
        if let Some(g) = given_of(k) {
            fixed[2 * k] = g.mean[0];
            fixed[2 * k + 1] = g.mean[1];
        }
    }
    let g_fixed = &p.g * &fixed;
    let s = p.s - 2.0 * p.r.dot(&fixed) + fixed.dot(&g_fixed);
    let nf = free.len();
    let mut m = DMatrix::from_fn(nf, nf, |a, b| p.g[(free[a], free[b])]);
    for i in 0..nf {
        m[(i, i)] += prec;
    }
    let m0f = DVector::from_fn(nf, |a, _| m0[free[a]]);
    let rr = DVector::from_fn(nf, |a, _| p.r[free[a]] - g_fixed[free[a]]) + &m0f * prec;
    let (mean_f, cov_f, logdet_m) = if nf == 0 {
        (DVector::zeros(0), DMatrix::zeros(0, 0), 0.0)
    } else {
        let chol = m.cholesky()?;
        let logdet: f64 = chol.l().diagonal().iter().map(|d| 2.0 * d.ln()).sum();
        (chol.solve(&rr), chol.inverse(), logdet)
    };
    // log p(û | θ) with the free μ integrated out under their prior:
    // −½[s + m0ᵀP₀ m0 − rrᵀ M⁻¹ rr + Σ ln det V + ln det M − ln det P₀] − n ln 2π.
    let quad = s + prec * m0f.dot(&m0f) - rr.dot(&mean_f);
    let loglik = -0.5 * (quad + p.logdet + logdet_m - nf as f64 * prec.ln());
    let mut mean = fixed;
    let mut cov = DMatrix::zeros(2 * nk, 2 * nk);
    for (a, &i) in free.iter().enumerate() {
        mean[i] = mean_f[a];
        for (b, &j) in free.iter().enumerate() {
            cov[(i, j)] = cov_f[(a, b)];
        }
    }
    for k in 0..nk {
        if let Some(g) = given_of(k) {
            cov[(2 * k, 2 * k)] = g.cov.pp;
            cov[(2 * k, 2 * k + 1)] = g.cov.ps;
            cov[(2 * k + 1, 2 * k)] = g.cov.ps;
            cov[(2 * k + 1, 2 * k + 1)] = g.cov.ss;
        }
    }
    Some((mean, cov, loglik))
}

/// Log marginal likelihood of the observations at `hyper` (P80, Vecchia form, class means
/// integrated out), without the constant −n ln 2π; `None` where not defined. Every class
/// multiplier and information scale 1.
pub fn log_likelihood(hyper: &Hyper, obs: &[Observation], v: &Vecchia, nk: usize) -> Option<f64> {
    let scales = Scales::unit(nk, obs.len());
    log_likelihood_scaled(hyper, &scales, obs, v, nk, obs.len())
}

/// [`log_likelihood`] with class multipliers and information scales, of the first `limit`
/// members of the conditioning order.
fn log_likelihood_scaled(
    hyper: &Hyper,
    scales: &Scales,
    obs: &[Observation],
    v: &Vecchia,
    nk: usize,
    limit: usize,
) -> Option<f64> {
    let (noise, root_b) = scales.terms(hyper, obs);
    let t = Terms {
        hyper,
        obs,
        noise: &noise,
        root_b: &root_b,
    };
    let p = pass(&t, v, nk, limit)?;
    class_posterior(&p, nk, &scales.means).map(|x| x.2)
}

/// The per-class multipliers of B and T and the per-member information scales of a field.
#[derive(Debug, Clone, PartialEq)]
pub struct Scales {
    /// Per class: [multiplier of B, multiplier of T].
    pub class: Vec<[f64; 2]>,
    /// Per member: the factor its information is multiplied by (1: as fitted; below 1: the
    /// field could not explain it, see [`SCREEN_CHI2`]).
    pub information: Vec<f64>,
    /// Per class: its mean where given from outside (a declared zone's, model §7.11); the
    /// classes beyond the list, or `None`, have their means estimated by the field.
    pub means: Vec<Option<ClassMean>>,
}

impl Scales {
    /// All 1: every class as the common B and T, every fit's information as stored, every
    /// class mean estimated.
    pub fn unit(nk: usize, n: usize) -> Scales {
        Scales {
            class: vec![[1.0, 1.0]; nk],
            information: vec![1.0; n],
            means: Vec::new(),
        }
    }

    /// Class k's given mean, if any.
    pub fn given_mean(&self, k: usize) -> Option<&ClassMean> {
        self.means.get(k).and_then(Option::as_ref)
    }

    /// Class k's multipliers ([1, 1] for a class it does not know).
    pub fn of_class(&self, k: usize) -> [f64; 2] {
        self.class.get(k).copied().unwrap_or([1.0, 1.0])
    }

    /// Each member's noise t_k T + (s_i I_i + ε)⁻¹ and √b_k.
    fn terms(&self, hyper: &Hyper, obs: &[Observation]) -> (Vec<Sym2>, Vec<f64>) {
        obs.iter()
            .enumerate()
            .map(|(i, o)| {
                let [b, t] = self.of_class(o.class);
                let s = self.information.get(i).copied().unwrap_or(1.0);
                (hyper.t.scale(t).add(&o.noise_scaled(s)), b.sqrt())
            })
            .unzip()
    }
}

/// The hyper-parameters' search coordinates: ln ℓ, ln B_PP, ln B_SS, corr(B), ln T_PP, ln T_SS.
fn hyper_of(x: &[f64]) -> Hyper {
    let (bp, bs) = (x[1].exp(), x[2].exp());
    Hyper {
        b: Sym2::new(bp, x[3] * (bp * bs).sqrt(), bs),
        ell: x[0].exp(),
        t: Sym2::new(x[4].exp(), 0.0, x[5].exp()),
    }
}

/// A member's screening against its leave-one-out prediction (see [`Field::screen`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Screened {
    /// χ² of its fitted u with its full information.
    pub chi2: f64,
    /// The factor its information is scaled by: 1, or below 1 beyond [`SCREEN_CHI2`].
    pub scale: f64,
}

/// The marginal-likelihood searches of a field's construction.
struct HyperSearch<'a> {
    obs: &'a [Observation],
    v: &'a Vecchia,
    nk: usize,
    /// The members whose likelihood is maximised: the first this many of the conditioning
    /// order (see [`HYPER_MEMBERS`]).
    members: usize,
    /// Bounds of ℓ, m.
    bounds: (f64, f64),
}

impl HyperSearch<'_> {
    /// The common θ maximising the marginal likelihood at fixed scales, from `start`
    /// (Nelder–Mead in the coordinates of [`hyper_of`], initial steps times `step`).
    fn common(&self, start: Hyper, scales: &Scales, budget: usize, step: f64) -> Option<Hyper> {
        let (lo, hi) = self.bounds;
        let corr = start.b.ps / (start.b.pp * start.b.ss).sqrt();
        let lower = [
            lo.ln(),
            VAR_RANGE.0.ln(),
            VAR_RANGE.0.ln(),
            CORR_RANGE.0,
            VAR_RANGE.0.ln(),
            VAR_RANGE.0.ln(),
        ];
        let upper = [
            hi.ln(),
            VAR_RANGE.1.ln(),
            VAR_RANGE.1.ln(),
            CORR_RANGE.1,
            VAR_RANGE.1.ln(),
            VAR_RANGE.1.ln(),
        ];
        let x0: Vec<f64> = [
            start.ell.ln(),
            start.b.pp.ln(),
            start.b.ss.ln(),
            corr,
            start.t.pp.ln(),
            start.t.ss.ln(),
        ]
        .iter()
        .zip(lower.iter().zip(&upper))
        .map(|(x, (l, u))| {
            if x.is_finite() {
                x.clamp(*l, *u)
            } else {
                0.5 * (l + u)
            }
        })
        .collect();
        let objective = FnObjective::new(6, |x: &[f64]| {
            log_likelihood_scaled(
                &hyper_of(x),
                scales,
                self.obs,
                self.v,
                self.nk,
                self.members,
            )
            .map_or(f64::INFINITY, |l| -l)
        });
        let steps: Vec<f64> = [0.7, 1.0, 1.0, 0.3, 1.0, 1.0]
            .iter()
            .map(|s| s * step)
            .collect();
        let bounds = Bounds::new(lower.to_vec(), upper.to_vec()).ok()?;
        let r = NelderMead::new()
            .max_evaluations(budget)
            .and_then(|nm| nm.stall(HYPER_STALL_EVALUATIONS, HYPER_STALL_TOL))
            .ok()?
            .minimize(&objective, &bounds, &x0, &steps)
            .ok()?;
        r.f.is_finite().then(|| hyper_of(&r.x))
    }

    /// The class multipliers of B and T maximising the marginal likelihood times their prior
    /// (ln b_k, ln t_k ~ N(0, [`CLASS_SCALE_PRIOR_SD`]²)) at fixed θ and information scales;
    /// classes with fewer than [`MIN_MEMBERS_FOR_CLASS_SCALE`] members keep theirs.
    fn classes(&self, hyper: &Hyper, scales: &Scales) -> Vec<[f64; 2]> {
        let mut count = vec![0usize; self.nk];
        for &i in &self.v.order[..self.members.min(self.v.order.len())] {
            if let Some(c) = count.get_mut(self.obs[i].class) {
                *c += 1;
            }
        }
        let active: Vec<usize> = (0..self.nk)
            .filter(|&k| count[k] >= MIN_MEMBERS_FOR_CLASS_SCALE)
            .collect();
        let current = scales.class.clone();
        if active.is_empty() {
            return current;
        }
        let of = |x: &[f64]| -> Scales {
            let mut s = scales.clone();
            for (j, &k) in active.iter().enumerate() {
                s.class[k] = [x[2 * j].exp(), x[2 * j + 1].exp()];
            }
            s
        };
        let prior_var = CLASS_SCALE_PRIOR_SD * CLASS_SCALE_PRIOR_SD;
        let objective = FnObjective::new(2 * active.len(), |x: &[f64]| {
            let penalty = 0.5 * x.iter().map(|v| v * v).sum::<f64>() / prior_var;
            log_likelihood_scaled(hyper, &of(x), self.obs, self.v, self.nk, self.members)
                .map_or(f64::INFINITY, |l| penalty - l)
        });
        let (lo, hi) = (CLASS_SCALE_RANGE.0.ln(), CLASS_SCALE_RANGE.1.ln());
        let x0: Vec<f64> = active
            .iter()
            .flat_map(|&k| current[k].map(|m| m.ln().clamp(lo, hi)))
            .collect();
        let n = x0.len();
        let found = Bounds::new(vec![lo; n], vec![hi; n]).ok().and_then(|b| {
            NelderMead::new()
                .max_evaluations(REFIT_EVALUATIONS)
                .and_then(|nm| nm.stall(HYPER_STALL_EVALUATIONS, HYPER_STALL_TOL))
                .ok()?
                .minimize(&objective, &b, &x0, &vec![0.5; n])
                .ok()
        });
        match found.filter(|r| r.f.is_finite()) {
            Some(r) => of(&r.x).class,
            None => current,
        }
    }
}

/// How the hyper-parameters were chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HyperSource {
    /// Maximum marginal likelihood (P80).
    MarginalLikelihood,
    /// Too few measured segments: the stated defaults.
    Defaults,
}

impl HyperSource {
    /// As stored.
    pub fn as_str(self) -> &'static str {
        match self {
            HyperSource::MarginalLikelihood => "marginal_likelihood",
            HyperSource::Defaults => "defaults",
        }
    }
}

/// Per axis a of u = (ln c_P, ln c_S), the factor by which a prediction's standard deviation is
/// widened because θ's scale (B, T) is estimated from the members rather than known (P92): with
/// the scale unknown under a flat prior on its logarithm, the predictive distribution of a
/// Gaussian field is Student's t with ν degrees of freedom (Handcock & Stein 1993), ν the
/// number of members that inform the spread along a less the class means estimated from them;
/// the factor is the t's 95 % quantile over the normal's. A member informs axis a in
/// proportion w = V/(V + N), V its prior variance b_k B_aa + t_k T_aa and N its noise's N_aa
/// (1 for a fit that pins u_a far more closely than the field varies, 0 for one that does not
/// see a); a class's mean costs min(1, Σ w) of its members'. ν is at least 1, and the widened
/// variance at most the class prior's [`CLASS_PRIOR_SD`]², unless it was wider already.
pub fn predictive_widening(
    obs: &[Observation],
    noise: &[Sym2],
    hyper: &Hyper,
    scales: &Scales,
    nk: usize,
) -> [f64; 2] {
    let mut out = [1.0; 2];
    for (a, w_out) in out.iter_mut().enumerate() {
        let mut per_class = vec![0.0f64; nk.max(1)];
        for (o, n) in obs.iter().zip(noise) {
            let [b, t] = scales.of_class(o.class);
            let v = b * hyper.b.at(a, a) + t * hyper.t.at(a, a);
            // `noise` holds t_k T + (s I + ε)⁻¹: the fit's own part is the excess over t_k T.
            let own = (n.at(a, a) - t * hyper.t.at(a, a)).max(0.0);
            let w = v / (v + own);
            if let (true, Some(c)) = (w.is_finite(), per_class.get_mut(o.class)) {
                *c += w;
            }
        }
        let informing: f64 = per_class.iter().sum();
        let means: f64 = per_class.iter().map(|w| w.min(1.0)).sum();
        let dof = (informing - means).max(1.0);
        let factor = crate::stats::t_over_normal(dof, 0.95);
        let prior = hyper.b.at(a, a) + hyper.t.at(a, a);
        let cap = (CLASS_PRIOR_SD * CLASS_PRIOR_SD / prior).sqrt().max(1.0);
        *w_out = if factor.is_finite() {
            factor.clamp(1.0, cap)
        } else {
            1.0
        };
    }
    out
}

/// The number of directions of `info` with an eigenvalue of at least [`SEEN_INFORMATION`].
pub fn seen_directions(info: &Sym2) -> usize {
    let half_trace = 0.5 * (info.pp + info.ss);
    let root = (0.25 * (info.pp - info.ss).powi(2) + info.ps * info.ps).sqrt();
    [half_trace + root, half_trace - root]
        .iter()
        .filter(|&&l| l >= SEEN_INFORMATION)
        .count()
}

mod conditioned;

pub use conditioned::*;

#[cfg(test)]
mod tests;
