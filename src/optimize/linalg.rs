//! Small dense linear algebra for problems with a handful of parameters (≤ ~10), without
//! external crates: normal equations, Cholesky solves with an eigen-decomposition
//! fallback, a cyclic Jacobi symmetric eigensolver, pseudo-inverses and parameter
//! covariances from a Jacobian.
//!
//! All matrices are dense `&[f64]` slices in row-major order; an `m × n` matrix `a` has
//! element `(i, j)` at `a[i * n + j]`.

use super::Bounds;

/// Eigenvalues of `JᵀJ` (or of a column-equilibrated version of it) at or below
/// `EIGEN_RCOND · λ_max` are treated as zero by the pseudo-inverse, which then reports the
/// matrix as rank deficient. `1e-12` on `JᵀJ` corresponds to a singular-value ratio of
/// `1e-6` of `J`; smaller eigenvalues of a matrix formed as `JᵀJ` in double precision carry
/// few correct digits.
pub const EIGEN_RCOND: f64 = 1e-12;

/// Maximum number of Jacobi sweeps; cyclic Jacobi converges quadratically, so a handful of
/// sweeps suffices for the sizes used here and this limit is only a safeguard.
pub const JACOBI_MAX_SWEEPS: usize = 100;

/// `JᵀJ` (`n × n`, row-major) of an `m × n` row-major matrix `j`.
pub fn jtj(j: &[f64], m: usize, n: usize) -> Vec<f64> {
    assert_eq!(j.len(), m * n, "jtj: matrix has wrong length");
    let mut a = vec![0.0; n * n];
    for row in j.chunks_exact(n) {
        for p in 0..n {
            let rp = row[p];
            if rp == 0.0 {
                continue;
            }
            for q in p..n {
                a[p * n + q] += rp * row[q];
            }
        }
    }
    for p in 0..n {
        for q in 0..p {
            a[p * n + q] = a[q * n + p];
        }
    }
    a
}

/// `Jᵀr` (length `n`) of an `m × n` row-major matrix `j` and a vector `r` of length `m`.
pub fn jt_vec(j: &[f64], m: usize, n: usize, r: &[f64]) -> Vec<f64> {
    assert_eq!(j.len(), m * n, "jt_vec: matrix has wrong length");
    assert_eq!(r.len(), m, "jt_vec: vector has wrong length");
    let mut g = vec![0.0; n];
    for (row, &ri) in j.chunks_exact(n).zip(r) {
        for (gq, &jq) in g.iter_mut().zip(row) {
            *gq += jq * ri;
        }
    }
    g
}

/// Cholesky factor `L` (lower triangular, row-major `n × n`, `A = L Lᵀ`) of a symmetric
/// matrix, or `None` if `A` is not numerically positive definite (a pivot `≤ 0` or
/// non-finite).
pub fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    assert_eq!(a.len(), n * n, "cholesky: matrix has wrong length");
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// Solves `L Lᵀ x = b` given the Cholesky factor from [`cholesky`].
pub fn cholesky_solve(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    assert_eq!(b.len(), n, "cholesky_solve: vector has wrong length");
    let mut y = b.to_vec();
    for i in 0..n {
        let mut s = y[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = y[i];
        for k in i + 1..n {
            s -= l[k * n + i] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    y
}

/// Solves `A x = b` for a symmetric positive (semi)definite `A` (`n × n`, row-major).
///
/// Uses Cholesky; if that fails (singular or indefinite up to rounding), falls back to the
/// minimum-norm least-squares solution through the eigen-decomposition pseudo-inverse with
/// cut-off [`EIGEN_RCOND`].
pub fn solve_spd(a: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    match cholesky(a, n) {
        Some(l) => cholesky_solve(&l, n, b),
        None => {
            let (pinv, _rank) = pseudo_inverse_symmetric(a, n, EIGEN_RCOND);
            mat_vec(&pinv, n, n, b)
        }
    }
}

/// `A x` for an `m × n` row-major `A`.
pub fn mat_vec(a: &[f64], m: usize, n: usize, x: &[f64]) -> Vec<f64> {
    assert_eq!(a.len(), m * n, "mat_vec: matrix has wrong length");
    assert_eq!(x.len(), n, "mat_vec: vector has wrong length");
    a.chunks_exact(n)
        .map(|row| row.iter().zip(x).map(|(a, b)| a * b).sum())
        .collect()
}

/// Eigen-decomposition `A = V diag(λ) Vᵀ` of a symmetric matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct SymmetricEigen {
    /// Eigenvalues in ascending order.
    pub values: Vec<f64>,
    /// Orthonormal eigenvectors, row-major `n × n`: column `k` (elements `vectors[i*n + k]`)
    /// belongs to `values[k]`.
    pub vectors: Vec<f64>,
}

/// Symmetric eigen-decomposition by the cyclic Jacobi method (Golub & Van Loan, §8.5).
///
/// Only the upper triangle's symmetric part matters; the input is symmetrised as
/// `(A + Aᵀ)/2`. Accurate to a few ulps of `‖A‖` for the small matrices used here.
pub fn symmetric_eigen(a: &[f64], n: usize) -> SymmetricEigen {
    assert_eq!(a.len(), n * n, "symmetric_eigen: matrix has wrong length");
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            m[i * n + j] = 0.5 * (a[i * n + j] + a[j * n + i]);
        }
    }
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let norm: f64 = m.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 && norm.is_finite() {
        for _sweep in 0..JACOBI_MAX_SWEEPS {
            let off: f64 = (0..n)
                .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
                .map(|(i, j)| m[i * n + j] * m[i * n + j])
                .sum::<f64>()
                .sqrt();
            if off <= f64::EPSILON * 1e-3 * norm {
                break;
            }
            for p in 0..n {
                for q in p + 1..n {
                    let apq = m[p * n + q];
                    if apq == 0.0 {
                        continue;
                    }
                    let theta = (m[q * n + q] - m[p * n + p]) / (2.0 * apq);
                    // Smaller root of t² + 2θt − 1 = 0, t = tan(rotation angle).
                    let t = if theta.abs() > 1e150 {
                        0.5 / theta
                    } else {
                        theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                    };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    let s = t * c;
                    for k in 0..n {
                        let (mkp, mkq) = (m[k * n + p], m[k * n + q]);
                        m[k * n + p] = c * mkp - s * mkq;
                        m[k * n + q] = s * mkp + c * mkq;
                    }
                    for k in 0..n {
                        let (mpk, mqk) = (m[p * n + k], m[q * n + k]);
                        m[p * n + k] = c * mpk - s * mqk;
                        m[q * n + k] = s * mpk + c * mqk;
                    }
                    m[p * n + q] = 0.0;
                    m[q * n + p] = 0.0;
                    for k in 0..n {
                        let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                        v[k * n + p] = c * vkp - s * vkq;
                        v[k * n + q] = s * vkp + c * vkq;
                    }
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| m[i * n + i].total_cmp(&m[j * n + j]));
    let values = order.iter().map(|&k| m[k * n + k]).collect();
    let mut vectors = vec![0.0; n * n];
    for (new_k, &k) in order.iter().enumerate() {
        for i in 0..n {
            vectors[i * n + new_k] = v[i * n + k];
        }
    }
    SymmetricEigen { values, vectors }
}

/// Moore–Penrose pseudo-inverse of a symmetric matrix: eigenvalues `λ` with
/// `|λ| ≤ rcond · max|λ|` are treated as zero. Returns the inverse and the numerical rank.
pub fn pseudo_inverse_symmetric(a: &[f64], n: usize, rcond: f64) -> (Vec<f64>, usize) {
    let eig = symmetric_eigen(a, n);
    let lmax = eig.values.iter().fold(0.0f64, |acc, l| acc.max(l.abs()));
    let cut = rcond * lmax;
    let mut inv = vec![0.0; n * n];
    let mut rank = 0;
    for (k, &l) in eig.values.iter().enumerate() {
        if l.is_nan() || l.abs() <= cut || l == 0.0 {
            continue;
        }
        rank += 1;
        for i in 0..n {
            let vik = eig.vectors[i * n + k] / l;
            for j in 0..n {
                inv[i * n + j] += vik * eig.vectors[j * n + k];
            }
        }
    }
    (inv, rank)
}

/// 2-norm condition number of an `m × n` matrix `J`, `σ_max/σ_min = sqrt(λ_max/λ_min)` of
/// `JᵀJ`; `+∞` when `JᵀJ` has a non-positive eigenvalue. Reliable up to about `1e7`
/// (forming `JᵀJ` squares the conditioning).
pub fn condition_number(j: &[f64], m: usize, n: usize) -> f64 {
    let eig = symmetric_eigen(&jtj(j, m, n), n);
    cond_from_eigenvalues(&eig.values)
}

fn cond_from_eigenvalues(values: &[f64]) -> f64 {
    let (lmin, lmax) = (values[0], values[values.len() - 1]);
    if lmin > 0.0 {
        (lmax / lmin).sqrt()
    } else {
        f64::INFINITY
    }
}

/// Parameter covariance of a least-squares fit and derived quantities.
#[derive(Debug, Clone, PartialEq)]
pub struct Covariance {
    /// `scale · (JᵀJ)⁺`, row-major `n × n`, in squared parameter units.
    pub cov: Vec<f64>,
    /// Standard errors `sqrt(cov[i][i])`, in parameter units.
    pub std_errors: Vec<f64>,
    /// Correlation matrix `cov[i][j] / (se_i se_j)`, row-major `n × n`, unit diagonal
    /// (off-diagonal entries are 0 where a standard error is 0).
    pub correlation: Vec<f64>,
    /// Condition number of `J` itself, `sqrt(λ_max/λ_min)` of `JᵀJ` (depends on the
    /// parameters' units; `+∞` if singular).
    pub condition_number: f64,
    /// Condition number of `J` after scaling its columns to unit norm (unit-free; the
    /// quantity that decides identifiability).
    pub scaled_condition_number: f64,
    /// True when some direction of the column-scaled `JᵀJ` has an eigenvalue at or below
    /// [`EIGEN_RCOND`] times the largest (or a column of `J` is zero): those directions are
    /// dropped by the pseudo-inverse, so the reported variances are lower bounds there.
    pub rank_deficient: bool,
}

/// Covariance of the parameters of a least-squares fit from its Jacobian.
///
/// `j` is the `m × n` row-major Jacobian of the residuals at the optimum and `scale` the
/// residual variance, usually `σ̂² = cost / (m − n)` with `cost` the sum of squares (pass
/// `1.0` if the residuals are already weighted by their standard deviations).
///
/// To make the rank decision independent of the parameters' units, `JᵀJ` is first scaled
/// to unit diagonal (`D⁻¹ JᵀJ D⁻¹`, `D = sqrt(diag JᵀJ)`), pseudo-inverted with cut-off
/// [`EIGEN_RCOND`] and scaled back, so `cov = scale · D⁻¹ (D⁻¹JᵀJD⁻¹)⁺ D⁻¹`, which equals
/// `scale · (JᵀJ)⁻¹` whenever `JᵀJ` is well conditioned. Parameters whose Jacobian column is
/// zero get zero variance and set `rank_deficient`.
pub fn covariance_from_jacobian(j: &[f64], m: usize, n: usize, scale: f64) -> Covariance {
    assert_eq!(
        j.len(),
        m * n,
        "covariance_from_jacobian: matrix has wrong length"
    );
    let a = jtj(j, m, n);
    let raw_eig = symmetric_eigen(&a, n);
    let condition_number = cond_from_eigenvalues(&raw_eig.values);

    let d: Vec<f64> = (0..n).map(|i| a[i * n + i].max(0.0).sqrt()).collect();
    let zero_column = d.iter().any(|&di| di == 0.0 || !di.is_finite());
    let mut scaled = vec![0.0; n * n];
    for p in 0..n {
        for q in 0..n {
            if d[p] > 0.0 && d[q] > 0.0 {
                scaled[p * n + q] = a[p * n + q] / (d[p] * d[q]);
            }
        }
    }
    let scaled_eig = symmetric_eigen(&scaled, n);
    let scaled_condition_number = cond_from_eigenvalues(&scaled_eig.values);
    let (pinv, rank) = pseudo_inverse_symmetric(&scaled, n, EIGEN_RCOND);
    let rank_deficient = zero_column || rank < n;

    let mut cov = vec![0.0; n * n];
    for p in 0..n {
        for q in 0..n {
            if d[p] > 0.0 && d[q] > 0.0 {
                cov[p * n + q] = scale * pinv[p * n + q] / (d[p] * d[q]);
            }
        }
    }
    let std_errors: Vec<f64> = (0..n).map(|i| cov[i * n + i].max(0.0).sqrt()).collect();
    let mut correlation = vec![0.0; n * n];
    for p in 0..n {
        for q in 0..n {
            correlation[p * n + q] = if p == q {
                1.0
            } else if std_errors[p] > 0.0 && std_errors[q] > 0.0 {
                cov[p * n + q] / (std_errors[p] * std_errors[q])
            } else {
                0.0
            };
        }
    }
    Covariance {
        cov,
        std_errors,
        correlation,
        condition_number,
        scaled_condition_number,
        rank_deficient,
    }
}

/// Probe distance along each principal axis of the covariance, in standard deviations.
pub const CURVATURE_PROBE_SIGMAS: f64 = 2.0;

/// Check the linearised covariance against the misfit itself, and widen it where the valley is
/// flatter than the quadratic model says.
///
/// A covariance `c = scale·(JᵀJ)⁻¹` assumes the cost (sum of squares) rises by `scale·t²/λ` a
/// distance t along a principal axis of variance λ. In a curved valley the rise is often much
/// smaller and the linearised errors too small. Here `cost_at` is evaluated
/// [`CURVATURE_PROBE_SIGMAS`] standard deviations out on both sides of each axis (or as far as
/// the bounds allow, at least a quarter of that); where the smaller rise is r times the
/// predicted one with r < 1, that axis's variance is divided by r. Errors are never narrowed.
/// Costs 2n evaluations; `cost0` is the cost at `x`; `None` from `cost_at` skips that side.
pub fn widen_along_flat_directions(
    x: &[f64],
    cost0: f64,
    scale: f64,
    bounds: &Bounds,
    c: &mut Covariance,
    mut cost_at: impl FnMut(&[f64]) -> Option<f64>,
) {
    let n = x.len();
    let eig = symmetric_eigen(&c.cov, n);
    let mut cov = vec![0.0; n * n];
    for k in 0..n {
        let lam = eig.values[k];
        let v: Vec<f64> = (0..n).map(|i| eig.vectors[i * n + k]).collect();
        let mut lam_new = lam;
        if lam.is_finite() && lam > 0.0 {
            let s = CURVATURE_PROBE_SIGMAS * lam.sqrt();
            let mut ratio = f64::INFINITY;
            for sign in [1.0, -1.0] {
                // Longest step t ≤ s along ±v that stays in the box.
                let mut t = s;
                for i in 0..n {
                    let d = sign * v[i];
                    if d > 0.0 {
                        t = t.min((bounds.upper()[i] - x[i]) / d);
                    } else if d < 0.0 {
                        t = t.min((bounds.lower()[i] - x[i]) / d);
                    }
                }
                if t < 0.25 * s {
                    continue;
                }
                let p: Vec<f64> = (0..n).map(|i| x[i] + sign * t * v[i]).collect();
                let Some(cost) = cost_at(&p) else {
                    continue;
                };
                let predicted = scale * t * t / lam;
                let rise = cost - cost0;
                ratio = ratio.min(rise / predicted);
            }
            if ratio.is_finite() && ratio < 1.0 {
                lam_new = lam / ratio.max(1e-6);
            }
        }
        for i in 0..n {
            for j in 0..n {
                cov[i * n + j] += lam_new * v[i] * v[j];
            }
        }
    }
    for i in 0..n {
        c.std_errors[i] = cov[i * n + i].max(0.0).sqrt();
    }
    for i in 0..n {
        for j in 0..n {
            let d = c.std_errors[i] * c.std_errors[j];
            c.correlation[i * n + j] = if d > 0.0 { cov[i * n + j] / d } else { 0.0 };
        }
    }
    c.cov = cov;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, rtol: f64) -> bool {
        (a - b).abs() <= rtol * b.abs().max(1e-300)
    }

    fn hilbert(n: usize) -> Vec<f64> {
        (0..n * n)
            .map(|k| 1.0 / ((k / n + k % n + 1) as f64))
            .collect()
    }

    #[test]
    fn eigenvalues_of_tridiagonal_3x3() {
        // [[2,-1,0],[-1,2,-1],[0,-1,2]] has eigenvalues 2-√2, 2, 2+√2 with eigenvectors
        // (1, ±√2, 1)/2 and (1, 0, -1)/√2.
        let a = [2.0, -1.0, 0.0, -1.0, 2.0, -1.0, 0.0, -1.0, 2.0];
        let e = symmetric_eigen(&a, 3);
        let s2 = 2f64.sqrt();
        let expected = [2.0 - s2, 2.0, 2.0 + s2];
        for (l, x) in e.values.iter().zip(expected) {
            assert!((l - x).abs() < 1e-14, "{l} vs {x}");
        }
        // Eigenvector of the smallest eigenvalue is ±(1/2, √2/2, 1/2).
        let v0 = [e.vectors[0], e.vectors[3], e.vectors[6]];
        let sign = v0[0].signum();
        for (v, x) in v0.iter().zip([0.5, s2 / 2.0, 0.5]) {
            assert!((sign * v - x).abs() < 1e-14);
        }
        // A V = V Λ and VᵀV = I.
        for k in 0..3 {
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| a[i * 3 + j] * e.vectors[j * 3 + k]).sum();
                assert!((av - e.values[k] * e.vectors[i * 3 + k]).abs() < 1e-14);
                let vv: f64 = (0..3)
                    .map(|j| e.vectors[j * 3 + i] * e.vectors[j * 3 + k])
                    .sum();
                assert!((vv - if i == k { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn eigen_of_diagonal_and_empty_input() {
        let e = symmetric_eigen(&[3.0, 0.0, 0.0, -1.0], 2);
        assert_eq!(e.values, vec![-1.0, 3.0]);
        let z = symmetric_eigen(&[0.0; 4], 2);
        assert_eq!(z.values, vec![0.0, 0.0]);
    }

    #[test]
    fn hilbert_condition_numbers() {
        // 2-norm condition numbers of the Hilbert matrices H3 and H4 (e.g. Gregory & Karney,
        // "A collection of matrices for testing computational algorithms", 1969).
        assert!(close(
            condition_number(&hilbert(3), 3, 3),
            524.056_777_586_0,
            1e-9
        ));
        assert!(close(
            condition_number(&hilbert(4), 4, 4),
            15_513.738_738_93,
            1e-7
        ));
        // Eigenvalues of H3.
        let e = symmetric_eigen(&hilbert(3), 3);
        for (l, x) in e.values.iter().zip([
            0.002_687_340_355_773_5,
            0.122_327_065_853_961,
            1.408_318_927_123_97,
        ]) {
            assert!(close(*l, x, 1e-11), "{l} vs {x}");
        }
    }

    #[test]
    fn cholesky_solves_spd_system() {
        // A = [[4,2],[2,3]], b = [2, 1] -> x = [0.5, 0].
        let a = [4.0, 2.0, 2.0, 3.0];
        let l = cholesky(&a, 2).unwrap();
        assert_eq!(l, vec![2.0, 0.0, 1.0, 2f64.sqrt()]);
        let x = cholesky_solve(&l, 2, &[2.0, 1.0]);
        assert!((x[0] - 0.5).abs() < 1e-15 && x[1].abs() < 1e-15);
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    #[test]
    fn solve_spd_falls_back_to_minimum_norm_solution() {
        // Singular A = [[1,1],[1,1]], b = [2,2]: minimum-norm solution is [1,1].
        let x = solve_spd(&[1.0, 1.0, 1.0, 1.0], 2, &[2.0, 2.0]);
        assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12);
        let (_, rank) = pseudo_inverse_symmetric(&[1.0, 1.0, 1.0, 1.0], 2, EIGEN_RCOND);
        assert_eq!(rank, 1);
    }

    #[test]
    fn normal_equations_helpers() {
        // J = [[1,2],[3,4],[5,6]]: JᵀJ = [[35,44],[44,56]], Jᵀ[1,1,1] = [9,12].
        let j = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(jtj(&j, 3, 2), vec![35.0, 44.0, 44.0, 56.0]);
        assert_eq!(jt_vec(&j, 3, 2, &[1.0, 1.0, 1.0]), vec![9.0, 12.0]);
        assert_eq!(mat_vec(&j, 3, 2, &[1.0, -1.0]), vec![-1.0, -1.0, -1.0]);
    }

    #[test]
    fn covariance_of_straight_line_fit() {
        // y = a + b t at t = 0, 1, 2: J = [[1,0],[1,1],[1,2]], JᵀJ = [[3,3],[3,5]],
        // (JᵀJ)⁻¹ = [[5,-3],[-3,3]]/6. With scale 2: cov = [[5/3,-1],[-1,1]].
        let j = [1.0, 0.0, 1.0, 1.0, 1.0, 2.0];
        let c = covariance_from_jacobian(&j, 3, 2, 2.0);
        let expected = [5.0 / 3.0, -1.0, -1.0, 1.0];
        for (x, e) in c.cov.iter().zip(expected) {
            assert!((x - e).abs() < 1e-13, "{x} vs {e}");
        }
        assert!((c.std_errors[0] - (5.0f64 / 3.0).sqrt()).abs() < 1e-13);
        assert!((c.std_errors[1] - 1.0).abs() < 1e-13);
        let rho = -1.0 / (5.0f64 / 3.0).sqrt();
        assert!((c.correlation[1] - rho).abs() < 1e-13);
        assert!((c.correlation[2] - rho).abs() < 1e-13);
        assert_eq!(c.correlation[0], 1.0);
        // Eigenvalues of [[3,3],[3,5]] are 4 ± √10.
        let cond = ((4.0 + 10f64.sqrt()) / (4.0 - 10f64.sqrt())).sqrt();
        assert!(close(c.condition_number, cond, 1e-12));
        assert!(!c.rank_deficient);
    }

    #[test]
    fn covariance_is_unit_invariant_and_flags_rank_deficiency() {
        // Rescaling parameter 2 by 1e6 rescales its column by 1e-6: the scaled covariance
        // must follow exactly and the rank decision must not change.
        let j = [1.0, 0.0, 1.0, 1.0, 1.0, 2.0];
        let js = [1.0, 0.0, 1.0, 1e-6, 1.0, 2e-6];
        let c = covariance_from_jacobian(&j, 3, 2, 1.0);
        let cs = covariance_from_jacobian(&js, 3, 2, 1.0);
        assert!(close(cs.std_errors[1], c.std_errors[1] * 1e6, 1e-10));
        assert!(!cs.rank_deficient);
        assert!(cs.condition_number > 1e5);
        assert!(close(
            cs.scaled_condition_number,
            c.scaled_condition_number,
            1e-10
        ));
        // Two identical columns: rank 1.
        let jd = [1.0, 1.0, 2.0, 2.0, 3.0, 3.0];
        let cd = covariance_from_jacobian(&jd, 3, 2, 1.0);
        assert!(cd.rank_deficient);
        assert!(cd.condition_number.is_infinite() || cd.condition_number > 1e7);
        // A zero column.
        let jz = [1.0, 0.0, 2.0, 0.0];
        assert!(covariance_from_jacobian(&jz, 2, 2, 1.0).rank_deficient);
    }

    /// A valley flatter than its quadratic model along x (cost 9 sin²x, linearised 9x²) is
    /// widened by exactly the measured ratio; a straight direction (cost y²) and a valley
    /// steeper than quadratic (cost 9x² + 50x⁴) are left alone.
    #[test]
    fn widening_follows_the_measured_rise() {
        let b = Bounds::new(vec![-10.0, -10.0], vec![10.0, 10.0]).unwrap();
        // J at 0 = diag(3, 1): cov = diag(1/9, 1).
        let j = [3.0, 0.0, 0.0, 1.0];
        let mut c = covariance_from_jacobian(&j, 2, 2, 1.0);
        widen_along_flat_directions(&[0.0, 0.0], 0.0, 1.0, &b, &mut c, |p| {
            Some(9.0 * p[0].sin().powi(2) + p[1] * p[1])
        });
        let t: f64 = 2.0 / 3.0; // 2σ along x
        let ratio = 9.0 * t.sin().powi(2) / 4.0;
        assert!(
            (c.std_errors[0] - (1.0 / 3.0) / ratio.sqrt()).abs() < 1e-12,
            "{:?}",
            c.std_errors
        );
        assert!((c.std_errors[1] - 1.0).abs() < 1e-12);
        assert!(c.correlation[1].abs() < 1e-12);
        let mut c = covariance_from_jacobian(&j, 2, 2, 1.0);
        widen_along_flat_directions(&[0.0, 0.0], 0.0, 1.0, &b, &mut c, |p| {
            Some(9.0 * p[0] * p[0] + 50.0 * p[0].powi(4) + p[1] * p[1])
        });
        assert!(
            (c.std_errors[0] - 1.0 / 3.0).abs() < 1e-12,
            "never narrowed"
        );
    }
}
