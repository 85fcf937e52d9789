//! The joint posterior of several pipes' soils (model §7.12, P80), for quantities that depend on
//! more than one predicted pipe at once, such as a leak's position on a path of several segments
//! (P86).
//!
//! [`super::model::Field::posterior`] gives each pipe's posterior on its own. Two predicted pipes
//! near each other are predicted from the same measured neighbours and lie in the same soil, so
//! their errors are correlated: the kriging conditional of all the targets together,
//!
//! S_TT = C_TT − A C_NT + Z Cov(μ) Zᵀ,   A = C_TN C_NN⁻¹,   Z = X_T − A X_N,
//!
//! on the union N of their nearest members, with C = B e^(−d/ℓ) between distinct points, B + T
//! on a target's own block and B + T + I⁻¹ on a member's (P78, P79), X the class indicators and
//! Cov(μ) the class means' posterior (universal kriging). For one target it is the field's own
//! single-pipe posterior.
//!
//! [`JointField::from_db`] rebuilds the field from the stored fit information and the
//! hyper-parameters of the latest field update, so nothing is re-estimated.

use std::collections::HashMap;

use nalgebra::DMatrix;
use rusqlite::Connection;

use super::model::{dist, Field, Hyper, Sym2};
use super::Site;
use crate::db::field as store;
use crate::db::DbError;

/// A pipe whose soil the joint posterior is taken of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Its midpoint, m (None: no geometry; it is then correlated with nothing).
    pub pos: Option<[f64; 2]>,
    /// Its soil class.
    pub class: usize,
    /// Its soil density, kg/m³: in a class whose mean is given at another density (a declared
    /// zone's), its mean moves to this one (P63–P64); None: the class's density.
    pub soil_density: Option<f64>,
}

/// The joint posterior of the targets' u = (ln c_P, ln c_S).
#[derive(Debug, Clone, PartialEq)]
pub struct JointPosterior {
    /// Mean per target.
    pub mean: Vec<[f64; 2]>,
    /// Covariance (2m × 2m, target i's coordinates at rows 2i, 2i + 1).
    pub cov: DMatrix<f64>,
}

impl JointPosterior {
    /// The 2 × 2 block between targets `i` and `j` (Cov(u_i, u_j)).
    pub fn block(&self, i: usize, j: usize) -> [[f64; 2]; 2] {
        let c = &self.cov;
        [
            [c[(2 * i, 2 * j)], c[(2 * i, 2 * j + 1)]],
            [c[(2 * i + 1, 2 * j)], c[(2 * i + 1, 2 * j + 1)]],
        ]
    }

    /// gᵢᵀ Cov(u_i, u_j) g_j: the covariance of two linear functions of the soils (a speed
    /// through its gradient ∂c/∂u).
    pub fn cov_of(&self, i: usize, gi: [f64; 2], j: usize, gj: [f64; 2]) -> f64 {
        let b = self.block(i, j);
        (0..2)
            .map(|a| (0..2).map(|c| gi[a] * b[a][c] * gj[c]).sum::<f64>())
            .sum()
    }
}

/// The field with its sites, for joint posteriors.
#[derive(Debug)]
pub struct JointField {
    /// The field (stored hyper-parameters, class means re-estimated from the same fits).
    pub field: Field,
    /// Every segment as the field sees it.
    pub sites: Vec<Site>,
    by_id: HashMap<String, usize>,
}

/// The hyper-parameters of a stored field update, when it has them all.
pub fn stored_hyper(run: &store::FieldRunRow) -> Option<Hyper> {
    match (run.correlation_length_m, run.field_cov, run.scatter_var) {
        (Some(ell), [Some(bp), Some(bps), Some(bs)], [Some(tp), Some(ts)]) => Some(Hyper {
            b: Sym2::new(bp, bps, bs),
            ell,
            t: Sym2::new(tp, 0.0, ts),
        }),
        _ => None,
    }
}

impl JointField {
    /// The field of the latest update, rebuilt from the stored fits with its stored
    /// hyper-parameters; `None` when there is no update or no measured segment.
    pub fn from_db(conn: &Connection) -> Result<Option<JointField>, DbError> {
        Ok(
            super::stored_field(conn, &None)?
                .map(|(_, field, sites)| JointField::new(field, sites)),
        )
    }

    /// From a field and its sites.
    pub fn new(field: Field, sites: Vec<Site>) -> JointField {
        let by_id = sites
            .iter()
            .enumerate()
            .map(|(i, s)| (s.segment_id.clone(), i))
            .collect();
        JointField {
            field,
            sites,
            by_id,
        }
    }

    /// A segment as a target, if the field knows it.
    pub fn target(&self, segment_id: &str) -> Option<Target> {
        let s = &self.sites[*self.by_id.get(segment_id)?];
        Some(Target {
            pos: s.pos,
            class: s.class.unwrap_or(0),
            soil_density: s.soil_density,
        })
    }

    /// The joint posterior of `targets` (none of them a member: their own fits would be left
    /// in).
    pub fn posterior(&self, targets: &[Target]) -> JointPosterior {
        joint_posterior(&self.field, targets)
    }
}

/// Covariance of the field between two points, either possibly without a position.
fn kernel(h: &Hyper, a: Option<[f64; 2]>, b: Option<[f64; 2]>) -> Sym2 {
    match (a, b) {
        (Some(a), Some(b)) => h.kernel(dist(a, b)),
        _ => Sym2::default(),
    }
}

fn put(m: &mut DMatrix<f64>, r: usize, c: usize, s: Sym2) {
    for a in 0..2 {
        for b in 0..2 {
            m[(2 * r + a, 2 * c + b)] = s.at(a, b);
        }
    }
}

/// The joint kriging posterior of `targets` given the field's members (module docs).
pub fn joint_posterior(field: &Field, targets: &[Target]) -> JointPosterior {
    let h = &field.hyper;
    let m = targets.len();
    // The union of the targets' nearest members, in the order each target lists them.
    let mut nbrs: Vec<usize> = Vec::new();
    for t in targets {
        if let Some(p) = t.pos {
            for (j, _) in field.neighbours_of(p, None) {
                if !nbrs.contains(&j) {
                    nbrs.push(j);
                }
            }
        }
    }
    let k = nbrs.len();
    let own = h.b.add(&h.t);
    let mut ctt = DMatrix::<f64>::zeros(2 * m, 2 * m);
    for a in 0..m {
        for b in 0..m {
            let s = if a == b {
                own
            } else {
                kernel(h, targets[a].pos, targets[b].pos)
            };
            put(&mut ctt, a, b, s);
        }
    }
    let mut cnn = DMatrix::<f64>::zeros(2 * k, 2 * k);
    let mut cnt = DMatrix::<f64>::zeros(2 * k, 2 * m);
    for (p, &i) in nbrs.iter().enumerate() {
        let oi = &field.obs[i];
        for (q, &j) in nbrs.iter().enumerate() {
            let s = if p == q {
                h.b.add(&h.t).add(&oi.noise())
            } else {
                kernel(h, oi.pos, field.obs[j].pos)
            };
            put(&mut cnn, p, q, s);
        }
        for (a, t) in targets.iter().enumerate() {
            put(&mut cnt, p, a, kernel(h, oi.pos, t.pos));
        }
    }
    // A = C_TN C_NN⁻¹ (2m × 2k); without a usable factor, no conditioning (the field's own
    // posterior falls back the same way).
    let (a_mat, v) = match (k > 0).then(|| cnn.clone().cholesky()).flatten() {
        Some(ch) => {
            let x = ch.solve(&cnt); // C_NN⁻¹ C_NT
            let reduce = cnt.transpose() * &x;
            (x.transpose(), &ctt - reduce)
        }
        None => (DMatrix::zeros(2 * m, 0), ctt),
    };
    let used: &[usize] = if a_mat.ncols() == 0 { &[] } else { &nbrs };
    // Means: the class mean plus the kriged anomalies of the members.
    let mean: Vec<[f64; 2]> = (0..m)
        .map(|t| {
            let (mu, _) = field.class(targets[t].class);
            let mut out = mu;
            for (p, &j) in used.iter().enumerate() {
                let (mj, _) = field.class(field.obs[j].class);
                let d = [field.obs[j].u[0] - mj[0], field.obs[j].u[1] - mj[1]];
                for (r, o) in out.iter_mut().enumerate() {
                    *o += a_mat[(2 * t + r, 2 * p)] * d[0] + a_mat[(2 * t + r, 2 * p + 1)] * d[1];
                }
            }
            if let (Some(g), Some(rho)) = (
                field.scales.given_mean(targets[t].class),
                targets[t].soil_density,
            ) {
                let d = g.shift(rho);
                out = [out[0] + d, out[1] + d];
            }
            out
        })
        .collect();
    // Z = X_T − A X_N over the classes (2m × 2K), then Z Cov(μ) Zᵀ.
    let nk = field.n_classes();
    let mut z = DMatrix::<f64>::zeros(2 * m, 2 * nk);
    for (t, tg) in targets.iter().enumerate() {
        z[(2 * t, 2 * tg.class)] += 1.0;
        z[(2 * t + 1, 2 * tg.class + 1)] += 1.0;
    }
    for (p, &j) in used.iter().enumerate() {
        let c = field.obs[j].class;
        for r in 0..2 * m {
            for b in 0..2 {
                z[(r, 2 * c + b)] -= a_mat[(r, 2 * p + b)];
            }
        }
    }
    let mut cov = v + &z * &field.class_cov * z.transpose();
    // The predictive covariance, widened per axis as each pipe's own (P92).
    for r in 0..2 * m {
        for c in 0..2 * m {
            cov[(r, c)] *= field.widening[r % 2] * field.widening[c % 2];
        }
    }
    // Symmetric to rounding.
    let sym = 0.5 * (&cov + cov.transpose());
    cov = sym;
    JointPosterior { mean, cov }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::model::{Observation, Posterior, CLASS_PRIOR_SD, TYPICAL_LN_SPEEDS};
    use nalgebra::DVector;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn normal(rng: &mut impl Rng) -> f64 {
        crate::stats::normal(rng)
    }

    fn hyper() -> Hyper {
        Hyper {
            b: Sym2::new(0.0225, 0.027, 0.04),
            ell: 300.0,
            t: Sym2::new(0.0009, 0.0, 0.0009),
        }
    }

    /// The information of a fit that sees both speeds, a few per cent each.
    const INFO: Sym2 = Sym2::new(900.0, -200.0, 400.0);

    fn member_positions() -> Vec<[f64; 2]> {
        vec![
            [0.0, 0.0],
            [400.0, 50.0],
            [800.0, -30.0],
            [120.0, 500.0],
            [650.0, 420.0],
            [1000.0, 600.0],
            [300.0, 900.0],
            [900.0, 1000.0],
        ]
    }

    fn classes_of(pos: &[[f64; 2]]) -> Vec<usize> {
        pos.iter().map(|p| usize::from(p[0] > 500.0)).collect()
    }

    /// Members observed at `u`, in two classes split at x = 500 m.
    fn members(u: &[[f64; 2]]) -> Vec<Observation> {
        let pos = member_positions();
        let cls = classes_of(&pos);
        pos.iter()
            .zip(u)
            .enumerate()
            .map(|(i, (p, u))| Observation {
                pos: Some(*p),
                class: cls[i],
                u: *u,
                info: INFO,
                key: crate::db::hash::fnv1a64(format!("m{i}").as_bytes()),
                suspect: false,
            })
            .collect()
    }

    fn field_of(obs: Vec<Observation>) -> Field {
        Field::with_hyper(
            obs,
            2,
            (50.0, 2000.0),
            hyper(),
            super::super::model::HyperSource::MarginalLikelihood,
        )
    }

    /// One target: exactly the field's single-pipe posterior, its covariance widened as the
    /// predictions' (P92).
    #[test]
    fn one_target_is_the_single_pipe_posterior() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let u: Vec<[f64; 2]> = (0..8)
            .map(|_| [5.4 + 0.2 * normal(&mut rng), 4.7 + 0.2 * normal(&mut rng)])
            .collect();
        let field = field_of(members(&u));
        for (pos, class) in [
            (Some([350.0, 300.0]), 0),
            (Some([700.0, 800.0]), 1),
            (Some([5000.0, 5000.0]), 1),
            (None, 0),
        ] {
            let plain = field.posterior(pos, class, None);
            let single = Posterior {
                cov: plain.cov.scale_axes(field.widening),
                ..plain
            };
            let joint = joint_posterior(
                &field,
                &[Target {
                    pos,
                    class,
                    soil_density: None,
                }],
            );
            for a in 0..2 {
                assert!(
                    (joint.mean[0][a] - single.mean[a]).abs() < 1e-9,
                    "{pos:?}: {:?} vs {:?}",
                    joint.mean[0],
                    single.mean
                );
                for b in 0..2 {
                    assert!(
                        (joint.cov[(a, b)] - single.cov.at(a, b)).abs() < 1e-9,
                        "{pos:?} ({a},{b}): {} vs {}",
                        joint.cov[(a, b)],
                        single.cov.at(a, b)
                    );
                }
            }
        }
    }

    /// Draw the members' fitted u and two targets' true u from the field model itself (class
    /// means from their prior, the field by Cholesky of its full covariance, each pipe's
    /// scatter T, each fit's noise I⁻¹), predict the targets, and compare the errors' sample
    /// covariance with the joint posterior's. With at most as many members as the field's
    /// conditioning sets, the posterior is the exact Gaussian conditional, so it holds for
    /// every entry within its Monte-Carlo error.
    #[test]
    fn joint_covariance_matches_soils_drawn_from_the_field_model() {
        let h = hyper();
        let mpos = member_positions();
        let mcls = classes_of(&mpos);
        let targets = [
            Target {
                pos: Some([450.0, 250.0]),
                class: 0,
                soil_density: None,
            },
            Target {
                pos: Some([560.0, 300.0]),
                class: 1,
                soil_density: None,
            },
        ];
        let pts: Vec<[f64; 2]> = mpos
            .iter()
            .copied()
            .chain(targets.iter().map(|t| t.pos.unwrap()))
            .collect();
        let cls: Vec<usize> = mcls
            .iter()
            .copied()
            .chain(targets.iter().map(|t| t.class))
            .collect();
        let n = pts.len();
        let mut k = DMatrix::<f64>::zeros(2 * n, 2 * n);
        for i in 0..n {
            for j in 0..n {
                let mut s = h.kernel(dist(pts[i], pts[j]));
                if i == j {
                    s = s.add(&h.t);
                }
                put(&mut k, i, j, s);
            }
        }
        let l = k.cholesky().unwrap().l();
        let noise = Observation {
            pos: None,
            class: 0,
            u: [0.0; 2],
            info: INFO,
            key: 0,
            suspect: false,
        }
        .noise()
        .cholesky()
        .unwrap();
        // The formula does not depend on the data: take it once. The draws use θ itself, so
        // they follow the plug-in covariance: the predictive's widening for θ estimated (P92,
        // greater than 1 on eight members) is divided out.
        let fixed = field_of(members(&[[5.4, 4.7]; 8]));
        assert!(
            fixed.widening.iter().all(|q| *q > 1.01),
            "{:?}",
            fixed.widening
        );
        let mut formula = joint_posterior(&fixed, &targets);
        for r in 0..4 {
            for c in 0..4 {
                formula.cov[(r, c)] /= fixed.widening[r % 2] * fixed.widening[c % 2];
            }
        }
        let draws = 4000;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut errs: Vec<[f64; 4]> = Vec::with_capacity(draws);
        for _ in 0..draws {
            let mu: Vec<[f64; 2]> = (0..2)
                .map(|_| {
                    [
                        TYPICAL_LN_SPEEDS[0] + CLASS_PRIOR_SD * normal(&mut rng),
                        TYPICAL_LN_SPEEDS[1] + CLASS_PRIOR_SD * normal(&mut rng),
                    ]
                })
                .collect();
            let w = &l * DVector::from_fn(2 * n, |_, _| normal(&mut rng));
            let truth: Vec<[f64; 2]> = (0..n)
                .map(|i| [mu[cls[i]][0] + w[2 * i], mu[cls[i]][1] + w[2 * i + 1]])
                .collect();
            let observed: Vec<[f64; 2]> = truth[..mpos.len()]
                .iter()
                .map(|u| {
                    let (a, b) = (normal(&mut rng), normal(&mut rng));
                    [u[0] + noise[0] * a, u[1] + noise[1] * a + noise[2] * b]
                })
                .collect();
            let post = joint_posterior(&field_of(members(&observed)), &targets);
            let t = &truth[mpos.len()..];
            errs.push([
                t[0][0] - post.mean[0][0],
                t[0][1] - post.mean[0][1],
                t[1][0] - post.mean[1][0],
                t[1][1] - post.mean[1][1],
            ]);
        }
        let nd = draws as f64;
        let mean: Vec<f64> = (0..4)
            .map(|a| errs.iter().map(|e| e[a]).sum::<f64>() / nd)
            .collect();
        let cov = |a: usize, b: usize| {
            errs.iter()
                .map(|e| (e[a] - mean[a]) * (e[b] - mean[b]))
                .sum::<f64>()
                / (nd - 1.0)
        };
        for a in 0..4 {
            for b in a..4 {
                let f = formula.cov[(a, b)];
                // Standard error of a sample covariance of Gaussians: √((σ_a² σ_b² + σ_ab²)/N).
                let se = ((formula.cov[(a, a)] * formula.cov[(b, b)] + f * f) / nd).sqrt();
                let got = cov(a, b);
                assert!(
                    (got - f).abs() < 4.0 * se,
                    "({a},{b}): sample {got:.5} vs formula {f:.5} ± {se:.5}"
                );
            }
        }
        // The cross terms are far from zero: two pipes 115 m apart share their soil.
        let corr = formula.cov[(1, 3)] / (formula.cov[(1, 1)] * formula.cov[(3, 3)]).sqrt();
        assert!(corr > 0.3, "{corr}");
    }

    /// Two close predicted neighbours: the variance of their sum is well above the sum of their
    /// variances (the independent answer); far apart, they share much less.
    #[test]
    fn close_neighbours_add_their_errors() {
        let field = field_of(members(&[[5.4, 4.7]; 8]));
        let ratio = |a: [f64; 2], b: [f64; 2]| {
            let p = joint_posterior(
                &field,
                &[
                    Target {
                        pos: Some(a),
                        class: 0,
                        soil_density: None,
                    },
                    Target {
                        pos: Some(b),
                        class: 0,
                        soil_density: None,
                    },
                ],
            );
            let g = [0.3, 0.7];
            let (v0, v1, c) = (
                p.cov_of(0, g, 0, g),
                p.cov_of(1, g, 1, g),
                p.cov_of(0, g, 1, g),
            );
            (v0 + v1 + 2.0 * c) / (v0 + v1)
        };
        // 60 m apart, 700 m and more from the nearest measured pipe.
        let near = ratio([1500.0, 1500.0], [1560.0, 1500.0]);
        assert!(near > 1.3, "{near}");
        // 5 km apart: only their class mean's error is shared.
        let far = ratio([1500.0, 1500.0], [-3000.0, 4000.0]);
        assert!(far < near - 0.3, "{far} {near}");
    }
}
