//! The field conditioned on the network's measured segments (model §7.12, P78–P81): the fitted
//! field with its hyper-parameters and class means, each segment's posterior at a point, and
//! the kriging weights behind it.

use super::*;

/// The fitted field: hyper-parameters, class means, and the members it conditions on.
#[derive(Debug)]
pub struct Field {
    /// θ.
    pub hyper: Hyper,
    /// How θ was chosen.
    pub source: HyperSource,
    /// ln p(û | θ) at θ (without the −n ln 2π).
    pub log_likelihood: Option<f64>,
    /// Bounds of ℓ searched: a typical segment length and the network's extent, m.
    pub ell_bounds: (f64, f64),
    /// Class means' posterior mean (2K: ln c_P, ln c_S per class).
    pub class_mean: DVector<f64>,
    /// Their posterior covariance (2K × 2K).
    pub class_cov: DMatrix<f64>,
    /// The members.
    pub obs: Vec<Observation>,
    /// The class multipliers of B and T and the members' information scales.
    pub scales: Scales,
    /// The screening that set the information scales (empty when none was done: given θ or
    /// too few members).
    pub screened: Vec<Screened>,
    /// Each member's noise t_k T + (s_i I_i + ε)⁻¹.
    noise: Vec<Sym2>,
    /// Each member's √b_k.
    root_b: Vec<f64>,
    /// Spatial index of the positioned members.
    tree: Index,
    /// Per axis (ln c_P, ln c_S), the factor a prediction's standard deviation is widened by
    /// for θ estimated from few members (see [`predictive_widening`]).
    pub widening: [f64; 2],
}

/// The part of a pipe's posterior its classes share (see [`Field::kriging`]).
pub(super) struct Kriging {
    neighbours: Vec<(usize, f64)>,
    idx: Vec<usize>,
    unit: Option<Conditional>,
}

/// The field's posterior of one pipe's u (P80, plus its own scatter T).
#[derive(Debug, Clone, PartialEq)]
pub struct Posterior {
    /// Mean of (ln c_P, ln c_S).
    pub mean: [f64; 2],
    /// Covariance.
    pub cov: Sym2,
    /// The measured segments conditioned on, with their distances (m), nearest first.
    pub neighbours: Vec<(usize, f64)>,
}

impl Field {
    /// Fit the field to the members: θ by maximum marginal likelihood when there are at least
    /// [`MIN_MEMBERS_FOR_HYPER`] members (defaults otherwise), ℓ within `ell_bounds`.
    pub fn fit(obs: Vec<Observation>, nk: usize, ell_bounds: (f64, f64)) -> Field {
        Self::build(obs, nk, ell_bounds, None, Vec::new())
    }

    /// [`Self::fit`] with the means of some classes given (`means[k]`, a declared zone's soil
    /// from its members' hierarchical model, model §7.11): θ, the class multipliers and the
    /// screening are then taken about those means, and the other classes' means estimated.
    pub fn fit_with_means(
        obs: Vec<Observation>,
        nk: usize,
        ell_bounds: (f64, f64),
        means: Vec<Option<ClassMean>>,
    ) -> Field {
        Self::build(obs, nk, ell_bounds, None, means)
    }

    /// The field with given hyper-parameters (those of a stored update): only the class means
    /// are estimated.
    pub fn with_hyper(
        obs: Vec<Observation>,
        nk: usize,
        ell_bounds: (f64, f64),
        hyper: Hyper,
        source: HyperSource,
    ) -> Field {
        Self::build(obs, nk, ell_bounds, Some((hyper, source)), Vec::new())
    }

    /// The field with given hyper-parameters, class multipliers and information scales (those
    /// of a stored update): only the class means are estimated.
    pub fn with_scales(
        obs: Vec<Observation>,
        nk: usize,
        ell_bounds: (f64, f64),
        hyper: Hyper,
        source: HyperSource,
        scales: Scales,
    ) -> Field {
        let bounds = Self::clamp_bounds(ell_bounds);
        let scales = Scales {
            class: (0..nk).map(|k| scales.of_class(k)).collect(),
            information: (0..obs.len())
                .map(|i| scales.information.get(i).copied().unwrap_or(1.0))
                .collect(),
            means: (0..nk).map(|k| scales.given_mean(k).copied()).collect(),
        };
        let v = Vecchia::new(&obs, LIKELIHOOD_NEIGHBOURS);
        Self::assemble(obs, nk, bounds, hyper, source, scales, &v)
    }

    fn clamp_bounds(ell_bounds: (f64, f64)) -> (f64, f64) {
        (
            ell_bounds.0.max(1e-3),
            ell_bounds.1.max(ell_bounds.0 * 1.001),
        )
    }

    fn build(
        obs: Vec<Observation>,
        nk: usize,
        ell_bounds: (f64, f64),
        given: Option<(Hyper, HyperSource)>,
        means: Vec<Option<ClassMean>>,
    ) -> Field {
        let (lo, hi) = Self::clamp_bounds(ell_bounds);
        let v = Vecchia::new(&obs, LIKELIHOOD_NEIGHBOURS);
        let start = Hyper::defaults((lo * hi).sqrt());
        let mut scales = Scales::unit(nk, obs.len());
        scales.means = means;
        let Some((mut hyper, source)) = given.or_else(|| {
            (obs.len() < MIN_MEMBERS_FOR_HYPER).then_some((start, HyperSource::Defaults))
        }) else {
            // Maximum marginal likelihood (P80): the common θ; then rounds of screening the
            // members the field cannot explain and refitting θ and the class multipliers.
            let search = HyperSearch {
                obs: &obs,
                v: &v,
                nk,
                members: HYPER_MEMBERS,
                bounds: (lo, hi),
            };
            let Some(mut hyper) = search.common(start, &scales, HYPER_EVALUATIONS, 1.0) else {
                return Self::assemble(obs, nk, (lo, hi), start, HyperSource::Defaults, scales, &v);
            };
            let mut field = Self::assemble(
                obs,
                nk,
                (lo, hi),
                hyper,
                HyperSource::MarginalLikelihood,
                scales.clone(),
                &v,
            );
            let mut screened = Vec::new();
            for _ in 0..SCREEN_ROUNDS {
                screened = field.robust_screen().0;
                scales.information = screened.iter().map(|s| s.scale).collect();
                let obs = field.obs;
                let search = HyperSearch {
                    obs: &obs,
                    v: &v,
                    nk,
                    members: HYPER_MEMBERS,
                    bounds: (lo, hi),
                };
                if let Some(h) = search.common(hyper, &scales, REFIT_EVALUATIONS, 0.3) {
                    hyper = h;
                }
                scales.class = search.classes(&hyper, &scales);
                field = Self::assemble(
                    obs,
                    nk,
                    (lo, hi),
                    hyper,
                    HyperSource::MarginalLikelihood,
                    scales.clone(),
                    &v,
                );
            }
            field.screened = screened;
            return field;
        };
        hyper.ell = hyper.ell.clamp(lo, hi.max(lo));
        Self::assemble(obs, nk, (lo, hi), hyper, source, scales, &v)
    }

    /// The field at fixed θ and scales: the class means' posterior and the spatial index.
    fn assemble(
        obs: Vec<Observation>,
        nk: usize,
        ell_bounds: (f64, f64),
        hyper: Hyper,
        source: HyperSource,
        scales: Scales,
        v: &Vecchia,
    ) -> Field {
        let (noise, root_b) = scales.terms(&hyper, &obs);
        let t = Terms {
            hyper: &hyper,
            obs: &obs,
            noise: &noise,
            root_b: &root_b,
        };
        let post = pass(&t, v, nk, obs.len()).and_then(|p| class_posterior(&p, nk, &scales.means));
        let (class_mean, class_cov, log_likelihood) = match post {
            Some((m, c, l)) => (m, c, Some(l)),
            None => {
                let (prec, m0) = class_prior(nk);
                (m0, DMatrix::identity(2 * nk, 2 * nk) / prec, None)
            }
        };
        let tree = index_of(obs.iter().map(|o| o.pos));
        let widening = match source {
            HyperSource::MarginalLikelihood => {
                predictive_widening(&obs, &noise, &hyper, &scales, nk)
            }
            HyperSource::Defaults => [1.0, 1.0],
        };
        Field {
            widening,
            hyper,
            source,
            log_likelihood,
            ell_bounds,
            class_mean,
            class_cov,
            obs,
            scales,
            screened: Vec::new(),
            noise,
            root_b,
            tree,
        }
    }

    /// Each member's information scale (P79–P80 screening): 1 when its fitted u is within
    /// χ²₂ = [`SCREEN_CHI2`] of its leave-one-out prediction from the others, with its fit's
    /// full information; otherwise the factor s < 1 that brings that χ² down to
    /// [`SCREEN_TARGET_CHI2`], χ²(s) = dᵀ (S* + (s I + ε)⁻¹)⁻¹ d with d = û − m* and S* the
    /// prediction's covariance (field, class means and per-pipe scatter). χ²(s) falls
    /// monotonically to about 0 as s → 0, so s is found by bisection in ln s.
    pub fn screen(&self) -> Vec<Screened> {
        (0..self.obs.len())
            .into_par_iter()
            .with_min_len(PASS_CHUNK)
            .map(|i| {
                let o = &self.obs[i];
                let p = self.posterior(o.pos, o.class, Some(i));
                let d = [o.u[0] - p.mean[0], o.u[1] - p.mean[1]];
                let chi2 = |s: f64| {
                    p.cov
                        .add(&o.noise_scaled(s))
                        .inverse()
                        .map_or(0.0, |inv| inv.quad(d))
                };
                let full = chi2(1.0);
                let limit = if o.suspect {
                    SCREEN_CHI2_SUSPECT
                } else {
                    SCREEN_CHI2
                };
                if full <= limit {
                    return Screened {
                        chi2: full,
                        scale: 1.0,
                    };
                }
                // χ²(s) falls as s falls: the largest ln s bracketed with χ² at the target.
                let (lo, _) = crate::optimize::bisect((1e-12f64).ln(), 0.0, 60, |ln_s| {
                    chi2(ln_s.exp()) <= SCREEN_TARGET_CHI2
                });
                Screened {
                    chi2: full,
                    scale: lo.exp(),
                }
            })
            .collect()
    }

    /// The factor τ ≤ 1 of the per-pipe scatter T at which the members' leave-one-out χ² are
    /// typical in their bulk: the median over the members of F_k(χ²_i) equals ½, F_k the χ²
    /// distribution of k = the member's seen directions ([`SEEN_INFORMATION`]). A few failed fits
    /// (a metal fit in a second basin of its misfit, ln c_P off by 1–3) inflate the marginal
    /// likelihood's T until their own χ² looks ordinary and the screening misses them (masking);
    /// the median is untouched by them as long as they are fewer than half, so the screening
    /// against the field with τT sees them. τ = 1 when the bulk is not narrower than the field
    /// says (the likelihood's T is then not inflated by outliers). Found by bisection in ln τ
    /// (the χ² grow as T shrinks).
    pub fn robust_scatter_factor(&self) -> f64 {
        let dof: Vec<usize> = self
            .obs
            .iter()
            .zip(&self.scales.information)
            .map(|(o, &s)| seen_directions(&o.info.scale(s)))
            .collect();
        if dof.iter().all(|&k| k == 0) {
            return 1.0;
        }
        let median_cdf = |tau: f64| -> f64 {
            let field = self.with_scatter_factor(tau);
            let mut p: Vec<f64> = (0..self.obs.len())
                .into_par_iter()
                .with_min_len(PASS_CHUNK)
                .filter(|&i| dof[i] > 0)
                .map(|i| {
                    let o = &self.obs[i];
                    let post = field.posterior(o.pos, o.class, Some(i));
                    let d = [o.u[0] - post.mean[0], o.u[1] - post.mean[1]];
                    let noise = o.noise_scaled(field.scales.information[i]);
                    let chi2 = post
                        .cov
                        .add(&noise)
                        .inverse()
                        .map_or(0.0, |inv| inv.quad(d));
                    1.0 - crate::stats::chi2_upper_tail(chi2, dof[i] as f64)
                })
                .collect();
            p.sort_by(f64::total_cmp);
            crate::stats::quantile(&p, 0.5).unwrap_or(0.5)
        };
        let g = |x: f64| median_cdf(x.exp()) - 0.5;
        let (mut hi, mut g_hi) = (0.0f64, g(0.0));
        if g_hi >= 0.0 {
            return 1.0;
        }
        let (mut lo, mut g_lo) = (MIN_SCREEN_SCATTER_FACTOR.ln(), 0.0);
        g_lo += g(lo);
        if g_lo < 0.0 {
            return MIN_SCREEN_SCATTER_FACTOR;
        }
        // Illinois regula falsi in ln τ on the bracket g(lo) ≥ 0 > g(hi): the median's CDF is a
        // smooth, nearly linear function of ln τ across the bracket, so the secant through the
        // bracket's ends reaches the tolerance in a handful of passes where bisection takes ten;
        // halving the value kept at an end that stays twice keeps both ends moving.
        let mut kept = 0i8;
        for _ in 0..ROBUST_MAX_STEPS {
            if hi - lo <= ROBUST_LN_TAU_TOL {
                break;
            }
            let secant = (lo * g_hi - hi * g_lo) / (g_hi - g_lo);
            let x = if secant.is_finite() && secant > lo && secant < hi {
                secant
            } else {
                0.5 * (lo + hi)
            };
            let gx = g(x);
            if gx >= 0.0 {
                (lo, g_lo) = (x, gx);
                if kept == 1 {
                    g_hi *= 0.5;
                }
                kept = 1;
            } else {
                (hi, g_hi) = (x, gx);
                if kept == -1 {
                    g_lo *= 0.5;
                }
                kept = -1;
            }
        }
        (0.5 * (lo + hi)).exp()
    }

    /// This field with its per-pipe scatter T multiplied by `tau` (class means re-estimated).
    fn with_scatter_factor(&self, tau: f64) -> Field {
        let hyper = Hyper {
            t: self.hyper.t.scale(tau),
            ..self.hyper
        };
        Self::with_scales(
            self.obs.clone(),
            self.n_classes(),
            self.ell_bounds,
            hyper,
            self.source,
            self.scales.clone(),
        )
    }

    /// The screening against the field with its per-pipe scatter at its robust size
    /// ([`Self::robust_scatter_factor`], [`Self::screen`]), with the factor used.
    pub fn robust_screen(&self) -> (Vec<Screened>, f64) {
        let tau = self.robust_scatter_factor();
        if tau >= 1.0 {
            return (self.screen(), 1.0);
        }
        (self.with_scatter_factor(tau).screen(), tau)
    }

    /// Number of classes.
    pub fn n_classes(&self) -> usize {
        self.class_mean.len() / 2
    }

    /// The terms the conditionals are taken with.
    fn terms(&self) -> Terms<'_> {
        Terms {
            hyper: &self.hyper,
            obs: &self.obs,
            noise: &self.noise,
            root_b: &self.root_b,
        }
    }

    /// The prior variance of a pipe's u in class `class`: b_k B + t_k T (P78).
    pub fn prior_var(&self, class: usize) -> Sym2 {
        let [b, t] = self.scales.of_class(class);
        self.hyper.b.scale(b).add(&self.hyper.t.scale(t))
    }

    /// The per-pipe scatter of class `class`: t_k T.
    pub fn scatter(&self, class: usize) -> Sym2 {
        self.hyper.t.scale(self.scales.of_class(class)[1])
    }

    /// The field covariance between a pipe at `a` in class `ka` and one at `b` in class `kb`:
    /// √(b_ka b_kb) B e^(−|a − b|/ℓ).
    pub fn kernel_classes(&self, a: [f64; 2], ka: usize, b: [f64; 2], kb: usize) -> Sym2 {
        let r = (self.scales.of_class(ka)[0] * self.scales.of_class(kb)[0]).sqrt();
        self.hyper.kernel(dist(a, b)).scale(r)
    }

    /// The kriging weights A (2 × 2k) and neighbours of a pipe at `pos` in class `class` (as
    /// [`Self::posterior`] uses them), for the plan's cross-covariances.
    pub fn weights(&self, pos: [f64; 2], class: usize) -> (Vec<f64>, Vec<usize>) {
        let idx: Vec<usize> = self.neighbours_of(pos, None).iter().map(|n| n.0).collect();
        let root_b = self.scales.of_class(class)[0].sqrt();
        match conditional(
            &self.terms(),
            Some(pos),
            root_b,
            self.prior_var(class),
            &idx,
        ) {
            Some(c) if c.a.ncols() > 0 => {
                let k = idx.len();
                let mut a = Vec::with_capacity(4 * k);
                for r in 0..2 {
                    for col in 0..2 * k {
                        a.push(c.a[(r, col)]);
                    }
                }
                (a, idx)
            }
            _ => (Vec::new(), Vec::new()),
        }
    }

    /// Class k's mean (ln c_P, ln c_S) and its covariance.
    pub fn class(&self, k: usize) -> ([f64; 2], Sym2) {
        let c = &self.class_cov;
        (
            [self.class_mean[2 * k], self.class_mean[2 * k + 1]],
            Sym2::new(
                c[(2 * k, 2 * k)],
                c[(2 * k, 2 * k + 1)],
                c[(2 * k + 1, 2 * k + 1)],
            ),
        )
    }

    /// The posterior of a pipe whose class is uncertain (labels are evidence, model §7.12): the
    /// mixture over `classes` (class, probability) of the class posteriors of
    /// [`Self::posterior`], by its mean and covariance: m = Σ p_k m_k,
    /// S = Σ p_k (S_k + (m_k − m)(m_k − m)ᵀ). The neighbours are those of the likeliest class.
    pub fn mixture_posterior(
        &self,
        pos: Option<[f64; 2]>,
        classes: &[(usize, f64)],
        skip: Option<usize>,
    ) -> Posterior {
        self.mixture_posterior_at(pos, classes, skip, None)
    }

    /// [`Self::mixture_posterior`] of a pipe whose soil density is `rho` (kg/m³): in a class
    /// with a given mean its posterior is moved from the class's density to its own
    /// ([`ClassMean::shift`]); without `rho` it stays at the class's density, where the field's
    /// members of that class are kept. It takes the estimated θ as known; the errors stated from
    /// it are widened by [`Self::widening`] (P92).
    pub fn mixture_posterior_at(
        &self,
        pos: Option<[f64; 2]>,
        classes: &[(usize, f64)],
        skip: Option<usize>,
        rho: Option<f64>,
    ) -> Posterior {
        let shared = self.kriging(pos, skip);
        let mut parts: Vec<(f64, Posterior)> = classes
            .iter()
            .map(|&(k, p)| (p, self.posterior_with(&shared, k, rho)))
            .collect();
        let total: f64 = parts.iter().map(|x| x.0).sum();
        let Some(best) = parts
            .iter()
            .enumerate()
            .max_by(|a, b| a.1 .0.total_cmp(&b.1 .0).then(b.0.cmp(&a.0)))
            .map(|x| x.0)
        else {
            return self.posterior_with(&shared, 0, rho);
        };
        if parts.len() == 1 || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return parts.into_iter().nth(best).map(|x| x.1).expect("one part");
        }
        let mut mean = [0.0; 2];
        for (p, q) in &parts {
            for (m, v) in mean.iter_mut().zip(q.mean) {
                *m += p / total * v;
            }
        }
        let mut cov = Sym2::default();
        for (p, q) in &parts {
            let d = [q.mean[0] - mean[0], q.mean[1] - mean[1]];
            let spread = Sym2::new(d[0] * d[0], d[0] * d[1], d[1] * d[1]);
            cov = cov.add(&q.cov.add(&spread).scale(p / total));
        }
        Posterior {
            mean,
            cov,
            neighbours: parts.swap_remove(best).1.neighbours,
        }
    }

    /// The members nearest to `pos` (at most [`NEIGHBOURS`]), leaving out member `skip`.
    pub fn neighbours_of(&self, pos: [f64; 2], skip: Option<usize>) -> Vec<(usize, f64)> {
        self.tree
            .nearest_neighbor_iter(&pos)
            .map(|g| g.data as usize)
            .filter(|&j| Some(j) != skip)
            .take(NEIGHBOURS)
            .map(|j| (j, self.obs[j].pos.map_or(f64::INFINITY, |p| dist(p, pos))))
            .collect()
    }

    /// The posterior of the u of a pipe at `pos` in class `class` (P80, universal kriging on
    /// its nearest members, the class means' error included), leaving out member `skip` (its
    /// leave-one-out prediction, P82). Without a position: its class mean, B and T added.
    pub fn posterior(&self, pos: Option<[f64; 2]>, class: usize, skip: Option<usize>) -> Posterior {
        self.posterior_with(&self.kriging(pos, skip), class, None)
    }

    /// What the posteriors at `pos` share across the classes a pipe may be in: its neighbours
    /// and the conditional of a target of unit amplitude (√b = 1, no own variance) on them.
    /// A class k scales the target's cross-covariance with the neighbours by √b_k and leaves
    /// their covariance C as it is, so its weights are √b_k A₁ and its variance
    /// b_k B + t_k T − b_k c₁ C⁻¹ c₁ᵀ (P80): one factorisation of C serves every class.
    fn kriging(&self, pos: Option<[f64; 2]>, skip: Option<usize>) -> Kriging {
        let neighbours = pos.map_or_else(Vec::new, |p| self.neighbours_of(p, skip));
        let idx: Vec<usize> = neighbours.iter().map(|n| n.0).collect();
        let unit = conditional(&self.terms(), pos, 1.0, Sym2::default(), &idx);
        Kriging {
            neighbours,
            idx,
            unit,
        }
    }

    /// The posterior in class `class` from the shared part of [`Self::kriging`], of a pipe of
    /// soil density `rho` (see [`Self::mixture_posterior_at`]).
    fn posterior_with(&self, k: &Kriging, class: usize, rho: Option<f64>) -> Posterior {
        let target_var = self.prior_var(class);
        let root_b = self.scales.of_class(class)[0].sqrt();
        let neighbours = k.neighbours.clone();
        let idx = &k.idx;
        let cond = match &k.unit {
            Some(u) => Conditional {
                a: &u.a * root_b,
                v: target_var.add(&u.v.scale(root_b * root_b)),
            },
            None => Conditional {
                a: DMatrix::zeros(2, 0),
                v: target_var,
            },
        };
        let used: &[usize] = if cond.a.ncols() == 0 { &[] } else { idx };
        let (mu, _) = self.class(class);
        let mut mean = mu;
        for (p, &j) in used.iter().enumerate() {
            let (mj, _) = self.class(self.obs[j].class);
            let d = [self.obs[j].u[0] - mj[0], self.obs[j].u[1] - mj[1]];
            for (a, m) in mean.iter_mut().enumerate() {
                *m += cond.a[(a, 2 * p)] * d[0] + cond.a[(a, 2 * p + 1)] * d[1];
            }
        }
        // Z Cov(μ) Zᵀ over the touched classes (universal kriging's term for the means).
        let z = design(
            class,
            |r, c| cond.a[(r, c)],
            used.iter().copied(),
            &self.obs,
        );
        let mut extra = [[0.0; 2]; 2];
        for (k, bk) in &z {
            for (l, bl) in &z {
                for r in 0..2 {
                    for c in 0..2 {
                        let mut s = 0.0;
                        for a in 0..2 {
                            for b in 0..2 {
                                s += bk[2 * r + a]
                                    * self.class_cov[(2 * k + a, 2 * l + b)]
                                    * bl[2 * c + b];
                            }
                        }
                        extra[r][c] += s;
                    }
                }
            }
        }
        let cov = cond.v.add(&Sym2::new(
            extra[0][0],
            0.5 * (extra[0][1] + extra[1][0]),
            extra[1][1],
        ));
        if let (Some(g), Some(rho)) = (self.scales.given_mean(class), rho) {
            let d = g.shift(rho);
            mean = [mean[0] + d, mean[1] + d];
        }
        Posterior {
            mean,
            cov,
            neighbours,
        }
    }
}
