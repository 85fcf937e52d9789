//! Two campaigns of one pipe fitted together: one state shared by both except the quantities
//! a cause lets the later campaign change (model §7.14, P95). The residuals are those of both
//! campaigns stacked, each in its own measurement standard deviations, so the misfit is the sum
//! of the two campaigns' χ².

use crate::invert::problem::{ParamSpec, Problem, SegmentData, SolvePath};
use crate::invert::{FitSettings, Param};
use crate::optimize::{Bounds, FiniteDifference, LeastSquares, LevenbergMarquardt};
use crate::physics::effects::Effect;
use crate::physics::System;

/// Where a coordinate of the later campaign's problem comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Source {
    /// The shared coordinate with this index (of the earlier campaign's problem).
    Shared(usize),
    /// The later campaign's own coordinate with this index among the own ones.
    Own(usize),
}

/// The joint problem of a cause: the earlier campaign's problem has the fit's parameter space;
/// the later one's has it with the cause's effect added where the fit does not have it. The
/// joint coordinates are the earlier problem's, then the later campaign's own.
pub struct Joint<'a> {
    earlier: Problem<'a>,
    later: Problem<'a>,
    sources: Vec<Source>,
    own: Vec<ParamSpec>,
    /// The value the earlier campaign takes for a quantity the fit does not have (the cause's
    /// effect at its neutral value), by the later problem's coordinate index.
    neutral: Vec<Option<f64>>,
}

/// What a joint fit found: the joint optimum and its χ² (on the reference path).
#[derive(Debug, Clone, PartialEq)]
pub struct JointOptimum {
    /// The joint coordinates.
    pub y: Vec<f64>,
    /// The summed χ² of both campaigns at `y`, on the reference path.
    pub chi2: f64,
    /// The later campaign's own parameters at `y`, in physical units.
    pub own_values: Vec<(Param, f64)>,
    /// The later campaign's coordinates at `y` (its problem's space: the fit's, with the
    /// cause's effect added where the fit lacks it).
    pub later_x: Vec<f64>,
}

impl<'a> Joint<'a> {
    /// The joint problem in which the later campaign has its own value of each of `own`
    /// (parameters of the fit's space, or the parameter of an effect it does not have).
    /// `earlier_system` gives the neutral value of an added effect (the pipe's own loss factor).
    /// `None` when a named parameter is not of this space or has no neutral value.
    pub fn new(
        earlier: &'a SegmentData,
        later: &'a SegmentData,
        settings: &FitSettings,
        own: &[Param],
        earlier_system: &System,
    ) -> Option<Joint<'a>> {
        let base = &settings.effects;
        let mut later_effects = base.clone();
        for p in own {
            if let Param::Effect(e) = p {
                if !later_effects.contains(e) {
                    later_effects.push(*e);
                }
            }
        }
        let pa = Problem::new(
            earlier,
            settings.method,
            settings.model,
            settings.contact_mode,
            base,
        );
        let pb = Problem::new(
            later,
            settings.method,
            settings.model,
            settings.contact_mode,
            &later_effects,
        );
        let mut sources = Vec::with_capacity(pb.specs.len());
        let mut own_specs = Vec::new();
        let mut neutral = Vec::with_capacity(pb.specs.len());
        for s in &pb.specs {
            let shared = pa.specs.iter().position(|a| a.param == s.param);
            if own.contains(&s.param) {
                sources.push(Source::Own(own_specs.len()));
                own_specs.push(*s);
            } else {
                sources.push(Source::Shared(shared?));
            }
            neutral.push(match (shared, s.param) {
                (None, Param::Effect(e)) => Some(s.coordinate(e.neutral_value(earlier_system)?)),
                _ => None,
            });
        }
        if own_specs.len() != own.len() {
            return None;
        }
        Some(Joint {
            earlier: pa,
            later: pb,
            sources,
            own: own_specs,
            neutral,
        })
    }

    /// The joint box: the earlier problem's, then the own coordinates'.
    pub fn bounds(&self) -> Option<Bounds> {
        let specs = self.earlier.specs.iter().chain(&self.own);
        Bounds::new(
            specs.clone().map(|s| s.lower).collect(),
            specs.map(|s| s.upper).collect(),
        )
        .ok()
    }

    /// The later campaign's coordinates at joint point `y`.
    fn later_x(&self, y: &[f64]) -> Vec<f64> {
        let p = self.earlier.specs.len();
        self.sources
            .iter()
            .map(|s| match *s {
                Source::Shared(i) => y[i],
                Source::Own(j) => y[p + j],
            })
            .collect()
    }

    /// The earlier campaign's coordinates at joint point `y` (the shared ones).
    fn earlier_x<'y>(&self, y: &'y [f64]) -> &'y [f64] {
        &y[..self.earlier.specs.len()]
    }

    /// A start: the shared coordinates `shared`, and the later campaign's own from `later`
    /// (coordinates of the fit's space; an added effect starts at its neutral value).
    pub fn start(&self, shared: &[f64], later: &[f64]) -> Vec<f64> {
        let mut y = shared.to_vec();
        for (k, s) in self.later.specs.iter().enumerate() {
            if !matches!(self.sources[k], Source::Own(_)) {
                continue;
            }
            let v = match self.neutral[k] {
                Some(n) => n,
                None => self
                    .earlier
                    .specs
                    .iter()
                    .position(|a| a.param == s.param)
                    .and_then(|i| later.get(i).copied())
                    .unwrap_or(s.lower),
            };
            y.push(v.clamp(s.lower, s.upper));
        }
        y
    }

    /// The summed χ² of both campaigns at `y` on the reference path (the path every fit's
    /// answer is judged on), +∞ where a root is not found.
    pub fn chi2_on_reference(&self, y: &[f64]) -> f64 {
        let a = self.earlier.on_path(SolvePath::Reference);
        let b = self.later.on_path(SolvePath::Reference);
        let xa = self.earlier_x(y);
        let xb = self.later_x(y);
        let va = a.predict(xa).map(|k| a.sum_of_squares(&k));
        let vb = b.predict(&xb).map(|k| b.sum_of_squares(&k));
        match (va, vb) {
            (Some(va), Some(vb)) => va + vb,
            _ => f64::INFINITY,
        }
    }

    /// The starts of the own coordinates that are added effects: besides the neutral value,
    /// points across the effect's range, since near its neutral value an effect can leave the
    /// misfit flat (a trace of air, φ ≤ 1e-6, changes the water's compressibility by < 1 %:
    /// E3), where a polish would not move.
    pub fn spread_starts(&self, y0: &[f64]) -> Vec<Vec<f64>> {
        let p = self.earlier.specs.len();
        let mut out = vec![y0.to_vec()];
        for (j, s) in self.own.iter().enumerate() {
            let Param::Effect(e) = s.param else { continue };
            if self.earlier.effects.contains(&e) {
                continue;
            }
            for f in OWN_START_FRACTIONS {
                let mut y = y0.to_vec();
                y[p + j] = s.lower + f * (s.upper - s.lower);
                out.push(y);
            }
        }
        out
    }

    /// The summed χ² at `y` on the search path (one evaluation of both campaigns).
    fn search_chi2(&self, y: &[f64]) -> f64 {
        let mut r = vec![0.0; self.n_residuals()];
        if self.residuals(y, &mut r) {
            r.iter().map(|v| v * v).sum()
        } else {
            f64::INFINITY
        }
    }

    /// Polish from the best [`POLISHED_STARTS`] of `starts` by their misfit (Levenberg–Marquardt
    /// in the joint box) and keep the lowest χ² on the reference path. `None` when no start
    /// gives a finite misfit.
    pub fn fit(&self, starts: &[Vec<f64>]) -> Option<JointOptimum> {
        let bounds = self.bounds()?;
        let mut ranked: Vec<(f64, Vec<f64>)> = starts
            .iter()
            .map(|y| {
                let mut y = y.clone();
                bounds.clamp(&mut y);
                (self.search_chi2(&y), y)
            })
            .filter(|(c, _)| c.is_finite())
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        ranked.truncate(POLISHED_STARTS);
        let starts: Vec<Vec<f64>> = ranked.into_iter().map(|(_, y)| y).collect();
        let lm = LevenbergMarquardt::new()
            .max_iterations(JOINT_POLISH_ITERATIONS)
            .ok()?
            .finite_difference(FiniteDifference::Forward)
            .fd_rel_step(1e-6)
            .ok()?
            .ftol(JOINT_FTOL)
            .ok()?
            .xtol(JOINT_XTOL)
            .ok()?
            .final_jacobian(false);
        let mut best: Option<JointOptimum> = None;
        // Each start is a candidate too: the answer is never worse than a start on the
        // reference path (a polish on the search path can cross onto another root there).
        let mut candidates: Vec<Vec<f64>> = starts.clone();
        for y0 in &starts {
            if let Ok(r) = lm.minimize(self, y0, Some(&bounds)) {
                if r.cost.is_finite() {
                    candidates.push(r.x);
                }
            }
        }
        for y in candidates {
            let chi2 = self.chi2_on_reference(&y);
            if chi2.is_finite() && best.as_ref().is_none_or(|b| chi2 < b.chi2) {
                let p = self.earlier.specs.len();
                let own_values = self
                    .own
                    .iter()
                    .enumerate()
                    .map(|(j, s)| (s.param, s.value(y[p + j])))
                    .collect();
                let later_x = self.later_x(&y);
                best = Some(JointOptimum {
                    y,
                    chi2,
                    own_values,
                    later_x,
                });
            }
        }
        best
    }

    /// Number of joint coordinates.
    pub fn dim(&self) -> usize {
        self.earlier.specs.len() + self.own.len()
    }

    /// The effect a cause adds to the later campaign, if the fit does not have it already.
    pub fn added_effects(&self) -> Vec<Effect> {
        self.later
            .effects
            .iter()
            .copied()
            .filter(|e| !self.earlier.effects.contains(e))
            .collect()
    }
}

/// Iterations of a joint polish: it starts next to its optimum (both campaigns' own fits).
pub const JOINT_POLISH_ITERATIONS: usize = 60;

/// The joint polish stops when an iteration lowers χ² by less than this fraction: the test
/// and the ranking of causes need χ² to ~0.01 (P94's Λ, AICc ties within 2), and χ² of both
/// campaigns is ~10–300, so 1e-6 leaves it well within that.
pub const JOINT_FTOL: f64 = 1e-6;

/// The joint polish stops when its (scaled) step is below this fraction of the (scaled)
/// coordinates: a millionth of a coordinate moves χ² by far less than JOINT_FTOL does.
pub const JOINT_XTOL: f64 = 1e-6;

/// Where across an added effect's coordinate range the extra starts lie (log10 φ from −7 to
/// −1.7 for air: −5.4, −4.35, −3.3 and −2.2, i.e. φ ≈ 4e-6 – 6e-3).
pub const OWN_START_FRACTIONS: [f64; 4] = [0.3, 0.5, 0.7, 0.9];

/// Starts polished per joint fit: the two of lowest misfit.
pub const POLISHED_STARTS: usize = 2;

impl LeastSquares for Joint<'_> {
    fn n_params(&self) -> usize {
        self.dim()
    }
    fn n_residuals(&self) -> usize {
        self.earlier.n_residuals() + self.later.n_residuals()
    }
    fn residuals(&self, y: &[f64], out: &mut [f64]) -> bool {
        let ma = self.earlier.n_residuals();
        let (ra, rb) = out.split_at_mut(ma);
        let xb = self.later_x(y);
        self.earlier.residuals(self.earlier_x(y), ra) && self.later.residuals(&xb, rb)
    }
}
