//! The soil of a synthetic network as geology makes it (model §7.12, P78): contiguous map
//! units, each with its own soil from soft to stiff, and inside them a soil that varies smoothly,
//! a Gaussian field of u = (ln c_P, ln c_S) with exponential covariance, plus a small scatter
//! per pipe (trench, backfill).
//!
//! * Units: a Voronoi partition of the map around a few centres (every cell is convex, so every
//!   unit is contiguous). Unit j of N takes its class at t = j/(N − 1) of [`SOILS`] ordered
//!   soft → stiff (soft clay and gravel at the ends), so a network holds soft and stiff ground;
//!   its mean soil is drawn inside the class's ranges.
//! * Field: w(x) = L (w₁(x), w₂(x)) with B = L Lᵀ, w₁, w₂ independent standard fields of
//!   correlation ρ(h) = e^(−h/ℓ), drawn by random Fourier features (Rahimi & Recht 2007): the
//!   exponential covariance in the plane has the spectral density ∝ (1/ℓ² + |ω|²)^(−3/2), a
//!   bivariate Student t with one degree of freedom, so ω = z / (ℓ |g|) with z ~ N(0, I₂),
//!   g ~ N(0, 1). The covariance over realisations is exactly ρ; each realisation costs O(M)
//!   per point and no memory that grows with the network.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{SoilClass, SOILS};
use crate::stats::normal;

/// Random Fourier features per standard field: the realised field's marginal is a sum of this
/// many cosines, Gaussian to well within what a network of a few hundred pipes can resolve.
pub const FEATURES: usize = 1000;

/// One-sigma spread of ln c_S about its unit's mean, over the unit (B₂₂ = 0.20²): soils of one
/// map unit differ by about a factor 1.2 in c_S (1.5 in shear modulus) at one sigma. With it,
/// knowing a unit's mean soil leaves plastic leak-band speeds about 1.1 % (median) and 6 %
/// (p90) off, near model §7.12's 1.6 % / 5.8 %.
pub const UNIT_SPREAD_LN_CS: f64 = 0.20;
/// One-sigma spread of ln c_P about its unit's mean (B₁₁ = 0.15²): the compressional speed
/// varies less, as the bulk stiffness of a wet soil does.
pub const UNIT_SPREAD_LN_CP: f64 = 0.15;
/// Correlation of ln c_P and ln c_S in the field (B₁₂ / √(B₁₁ B₂₂)): a stiffer soil is stiffer
/// in both, and ν_m stays within a few hundredths of its unit's.
pub const UNIT_SPREAD_CORRELATION: f64 = 0.9;
/// Per-pipe scatter of (ln c_P, ln c_S), one sigma each, correlated as the field (T of P78:
/// the trench and its backfill).
pub const PIPE_SCATTER_LN: f64 = 0.03;
/// Smallest and largest ν_m a field soil is given: c_P / c_S is kept in the range these imply.
pub const FIELD_NU_RANGE: (f64, f64) = (0.05, 0.48);

/// The soil of one map unit: its class and the mean of u = (ln c_P, ln c_S).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitSoil {
    /// Soil class (its name is the unit's `soil_type` label).
    pub class: SoilClass,
    /// Mean (ln c_P, ln c_S), c in m/s.
    pub mean: [f64; 2],
}

/// One random Fourier feature: cos(ω·x + φ).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Feature {
    wx: f64,
    wy: f64,
    phase: f64,
}

/// The geology of a synthetic network: its units and the correlated soil inside them.
#[derive(Debug, Clone, PartialEq)]
pub struct Geology {
    /// Voronoi centres of the units, projected metres.
    pub centres: Vec<(f64, f64)>,
    /// Soil of each unit.
    pub units: Vec<UnitSoil>,
    /// Correlation length ℓ, m.
    pub correlation_length_m: f64,
    /// Lower-triangular L with L Lᵀ = B.
    chol: [[f64; 2]; 2],
    features: [Vec<Feature>; 2],
}

/// (c_P, c_S) in m/s of a soil (P63–P64, real moduli).
pub fn wave_speeds(youngs_modulus: f64, poisson: f64, density: f64) -> (f64, f64) {
    let m = youngs_modulus * (1.0 - poisson) / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
    let g = youngs_modulus / (2.0 * (1.0 + poisson));
    ((m / density).sqrt(), (g / density).sqrt())
}

/// (E_m Pa, ν_m) of a soil of density ρ with speeds (c_P, c_S) (P63–P64 inverted):
/// ν = (M − 2G) / (2(M − G)), E = 2G(1 + ν), with M = ρ c_P², G = ρ c_S².
pub fn moduli(p_speed: f64, s_speed: f64, density: f64) -> (f64, f64) {
    let m = density * p_speed * p_speed;
    let g = density * s_speed * s_speed;
    let nu = (m - 2.0 * g) / (2.0 * (m - g));
    (2.0 * g * (1.0 + nu), nu)
}

/// ln(c_P / c_S) of a soil of Poisson's ratio ν: ½ ln(2(1 − ν)/(1 − 2ν)).
fn ln_speed_ratio(nu: f64) -> f64 {
    0.5 * (2.0 * (1.0 - nu) / (1.0 - 2.0 * nu)).ln()
}

impl Geology {
    /// Draw `units` units with centres among `sites` (distinct sites, so every unit holds at
    /// least the pipe at its centre when the sites are the pipes' midpoints) and the field of
    /// correlation length `correlation_length_m`, all from `seed`.
    pub fn draw(seed: u64, units: usize, sites: &[(f64, f64)], correlation_length_m: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let units = units.clamp(1, sites.len().max(1));
        let centres: Vec<(f64, f64)> = choose(&mut rng, sites.len(), units)
            .into_iter()
            .map(|i| sites[i])
            .collect();
        let soils = (0..units)
            .map(|j| {
                // Unit j of N sits at t = j/(N − 1) of the classes ordered soft → stiff (the
                // softest and the stiffest at the ends, a neighbour drawn between them).
                let top = (SOILS.len() - 1) as f64;
                let t = if units > 1 {
                    j as f64 / (units - 1) as f64
                } else {
                    rng.gen::<f64>()
                };
                let class =
                    SOILS[((t * top + rng.gen::<f64>()).floor() as usize).min(SOILS.len() - 1)];
                let e = (class.1 .0.ln() + rng.gen::<f64>() * (class.1 .1 / class.1 .0).ln()).exp();
                let nu = rng.gen_range(class.2 .0..class.2 .1);
                let rho = 0.5 * (class.3 .0 + class.3 .1);
                let (cp, cs) = wave_speeds(e, nu, rho);
                UnitSoil {
                    class,
                    mean: [cp.ln(), cs.ln()],
                }
            })
            .collect();
        let (sp, ss, r) = (
            UNIT_SPREAD_LN_CP,
            UNIT_SPREAD_LN_CS,
            UNIT_SPREAD_CORRELATION,
        );
        let chol = [[sp, 0.0], [r * ss, ss * (1.0 - r * r).sqrt()]];
        let mut feature = || {
            let g = normal(&mut rng).abs().max(1e-12);
            Feature {
                wx: normal(&mut rng) / (correlation_length_m * g),
                wy: normal(&mut rng) / (correlation_length_m * g),
                phase: rng.gen::<f64>() * std::f64::consts::TAU,
            }
        };
        let f1: Vec<Feature> = (0..FEATURES).map(|_| feature()).collect();
        let f2: Vec<Feature> = (0..FEATURES).map(|_| feature()).collect();
        Self {
            centres,
            units: soils,
            correlation_length_m,
            chol,
            features: [f1, f2],
        }
    }

    /// The unit at a point: the nearest centre (ties to the lower index).
    pub fn unit_at(&self, p: (f64, f64)) -> usize {
        let d2 = |c: &(f64, f64)| (c.0 - p.0).powi(2) + (c.1 - p.1).powi(2);
        self.centres
            .iter()
            .enumerate()
            .min_by(|a, b| d2(a.1).total_cmp(&d2(b.1)))
            .map_or(0, |(i, _)| i)
    }

    /// The two independent standard fields (w₁, w₂) at a point: zero mean, unit variance,
    /// correlation e^(−h/ℓ) over realisations.
    pub fn standard_field(&self, p: (f64, f64)) -> [f64; 2] {
        let scale = (2.0 / FEATURES as f64).sqrt();
        self.features.each_ref().map(|fs| {
            scale
                * fs.iter()
                    .map(|f| (f.wx * p.0 + f.wy * p.1 + f.phase).cos())
                    .sum::<f64>()
        })
    }

    /// The smooth soil u(x) = μ_k(x) + L w(x) at a point (P78 without the per-pipe scatter).
    pub fn field_at(&self, p: (f64, f64)) -> [f64; 2] {
        let mean = self.units[self.unit_at(p)].mean;
        let w = self.standard_field(p);
        let l = &self.chol;
        [
            mean[0] + l[0][0] * w[0],
            mean[1] + l[1][0] * w[0] + l[1][1] * w[1],
        ]
    }

    /// A pipe's soil at `p`: its unit, and (E_m Pa, ν_m) for its density ρ from the field plus
    /// the per-pipe scatter drawn from `rng`, with c_P / c_S kept inside [`FIELD_NU_RANGE`].
    pub fn pipe_soil<R: Rng + ?Sized>(
        &self,
        p: (f64, f64),
        density: f64,
        rng: &mut R,
    ) -> (usize, f64, f64) {
        let u = self.field_at(p);
        // The pipe's scatter has the field's correlation of the two speeds.
        let (z1, z2) = (normal(rng), normal(rng));
        let r = UNIT_SPREAD_CORRELATION;
        let ln_cp = u[0] + PIPE_SCATTER_LN * z1;
        let ln_cs = u[1] + PIPE_SCATTER_LN * (r * z1 + (1.0 - r * r).sqrt() * z2);
        let ln_cp = ln_cp.clamp(
            ln_cs + ln_speed_ratio(FIELD_NU_RANGE.0),
            ln_cs + ln_speed_ratio(FIELD_NU_RANGE.1),
        );
        let (e, nu) = moduli(ln_cp.exp(), ln_cs.exp(), density);
        (self.unit_at(p), e, nu)
    }
}

/// `k` distinct indices of `0..n` in random order (a partial Fisher–Yates shuffle); all of them
/// when `k ≥ n`.
pub fn choose<R: Rng + ?Sized>(rng: &mut R, n: usize, k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    let k = k.min(n);
    for i in 0..k {
        let j = rng.gen_range(i..n);
        idx.swap(i, j);
    }
    idx.truncate(k);
    idx
}

/// The number of `n` items a fraction selects: `round(fraction · n)`.
pub fn count_of(fraction: f64, n: usize) -> usize {
    ((fraction * n as f64).round() as usize).min(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moduli_invert_wave_speeds() {
        for (e, nu, rho) in [
            (5e7, 0.33, 1900.0),
            (8e6, 0.45, 1700.0),
            (3e8, 0.22, 2100.0),
        ] {
            let (cp, cs) = wave_speeds(e, nu, rho);
            let (e2, nu2) = moduli(cp, cs, rho);
            assert!((e2 / e - 1.0).abs() < 1e-12 && (nu2 - nu).abs() < 1e-12);
            assert!((ln_speed_ratio(nu) - (cp / cs).ln()).abs() < 1e-12);
        }
        // The reference loam of model §3.4: 205.5 and 98.7 m/s.
        let (cp, cs) = wave_speeds(5e7, 0.35, 1900.0);
        assert!((cp - 205.5).abs() < 0.1 && (cs - 98.7).abs() < 0.1);
    }

    #[test]
    fn choose_gives_distinct_indices() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut v = choose(&mut rng, 50, 20);
        assert_eq!(v.len(), 20);
        v.sort_unstable();
        v.dedup();
        assert_eq!(v.len(), 20);
        assert!(v.iter().all(|&i| i < 50));
        assert_eq!(choose(&mut rng, 5, 9).len(), 5);
        assert_eq!(count_of(0.15, 600), 90);
        assert_eq!(count_of(0.1, 105), 11);
    }

    /// Over many realisations, the standard field has unit variance and the correlation
    /// e^(−h/ℓ) at lags 0.25ℓ … 3ℓ, and the pipe scatter and B give the stated spreads.
    #[test]
    fn field_has_the_exponential_correlation() {
        let ell = 350.0;
        let lags = [0.25, 0.5, 1.0, 2.0, 3.0];
        let realisations = 400;
        let mut sum_sq = 0.0;
        let mut prods = [0.0; 5];
        let mut count = 0.0;
        for r in 0..realisations {
            let g = Geology::draw(9000 + r, 1, &[(0.0, 0.0)], ell);
            // A few independent base points per realisation (several ℓ apart).
            for b in 0..4 {
                let p0 = (4000.0 * b as f64, -2500.0 * b as f64);
                let w0 = g.standard_field(p0);
                for (c, &w) in w0.iter().enumerate() {
                    sum_sq += w * w;
                    count += 1.0;
                    for (k, &lag) in lags.iter().enumerate() {
                        let angle = 0.7 * (b + c) as f64;
                        let p = (
                            p0.0 + lag * ell * angle.cos(),
                            p0.1 + lag * ell * angle.sin(),
                        );
                        prods[k] += w * g.standard_field(p)[c];
                    }
                }
            }
        }
        let var = sum_sq / count;
        assert!((var - 1.0).abs() < 0.1, "variance {var}");
        for (k, &lag) in lags.iter().enumerate() {
            let rho = prods[k] / count / var;
            let expect = (-lag).exp();
            assert!(
                (rho - expect).abs() < 0.08,
                "lag {lag} ℓ: correlation {rho:.3}, expected {expect:.3}"
            );
        }
    }

    #[test]
    fn units_are_the_nearest_centre_and_span_soft_to_stiff() {
        let sites: Vec<(f64, f64)> = (0..100)
            .map(|i| ((i % 10) as f64 * 100.0, (i / 10) as f64 * 100.0))
            .collect();
        let g = Geology::draw(5, 3, &sites, 350.0);
        assert_eq!(g.units.len(), 3);
        // Unit j's class sits at j/(N − 1) of the classes ordered soft → stiff.
        let names: Vec<&str> = g.units.iter().map(|u| u.class.0).collect();
        assert_eq!(names[0], "soft_clay");
        assert!(["loam", "sand"].contains(&names[1]));
        assert_eq!(names[2], "gravel");
        for (j, &c) in g.centres.iter().enumerate() {
            assert_eq!(g.unit_at(c), j);
        }
    }
}
