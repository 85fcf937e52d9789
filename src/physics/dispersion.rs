//! The dispersion relation of the fluid-dominated s = 1 wave, model §4 (eqs. P8–P39).
//!
//! [`Evaluator`] holds every quantity that depends only on the system and ω (P8–P14), so that
//! the residual F(k1) of eq. P32, evaluated 5–10 times per root, recomputes only what depends on
//! k1: the radial wavenumbers, two Hankel ratios and (in `full`) one Bessel ratio.

use num_complex::Complex64;

use super::inputs::{ContactMode, Model, System};
use crate::special::{hankel_ratio, principal_sqrt, psi, psi_d, sqrt_plus, SpecialError};

const I: Complex64 = Complex64::new(0.0, 1.0);

/// Bonded soil dynamic stiffness at r = a (Pa/m), eqs. P18–P21, and the slip stiffness P23.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoilStiffness {
    /// K11: axial stress per axial displacement, eq. P18.
    pub k11: Complex64,
    /// K12: axial stress per radial displacement, eq. P19.
    pub k12: Complex64,
    /// K21 = −K12 exactly (reciprocity), eq. P20.
    pub k21: Complex64,
    /// K22: radial stress per radial displacement, eq. P21.
    pub k22: Complex64,
}

impl SoilStiffness {
    /// No soil: K = 0 (eq. P22).
    pub const ZERO: SoilStiffness = SoilStiffness {
        k11: Complex64::new(0.0, 0.0),
        k12: Complex64::new(0.0, 0.0),
        k21: Complex64::new(0.0, 0.0),
        k22: Complex64::new(0.0, 0.0),
    };

    /// Radial stiffness of a lubricated interface, K_slip = K22 − K21·K12/K11, eq. P23.
    /// Zero when the soil is absent (eq. P22).
    pub fn slip(&self) -> Complex64 {
        if self.k11 == Complex64::new(0.0, 0.0) {
            return Complex64::new(0.0, 0.0);
        }
        self.k22 - self.k21 * self.k12 / self.k11
    }
}

/// The soil stiffness and its derivative with respect to k1 (for Newton's method).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoilStiffnessD {
    /// The stiffness at k1.
    pub k: SoilStiffness,
    /// d/dk1 of each entry.
    pub dk: SoilStiffness,
}

/// The soil's complex Lamé moduli and wavenumbers at one frequency, eqs. P13–P14.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoilWaves {
    /// Complex shear modulus μ̂_m, Pa.
    pub mu: Complex64,
    /// k_P² = ρ_m ω²/(λ̂_m + 2μ̂_m), rad²/m².
    pub kp2: Complex64,
    /// k_S² = ρ_m ω²/μ̂_m, rad²/m².
    pub ks2: Complex64,
}

impl SoilWaves {
    /// Eqs. P13–P14 for a present soil (E_m > 0).
    pub fn new(
        youngs_modulus: f64,
        poisson: f64,
        density: f64,
        loss_factor: f64,
        omega: f64,
    ) -> Self {
        let damp = Complex64::new(1.0, loss_factor);
        let nu = poisson;
        let lambda = damp * (youngs_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)));
        let mu = damp * (youngs_modulus / (2.0 * (1.0 + nu)));
        let rw2 = density * omega * omega;
        Self {
            mu,
            kp2: rw2 / (lambda + 2.0 * mu),
            ks2: rw2 / mu,
        }
    }

    /// Bonded soil stiffness at r = a for axial wavenumber k1, eqs. P15–P21.
    ///
    /// Forms D (P17) once; K21 is set to −K12 exactly (model §5.7).
    pub fn stiffness(&self, k1: Complex64, a: f64) -> Result<SoilStiffness, SpecialError> {
        let k1sq = k1 * k1;
        let qp = sqrt_plus(self.kp2 - k1sq); // P15
        let qs = sqrt_plus(self.ks2 - k1sq);
        let p = hankel_ratio(qp * a)?; // P16
        let q = hankel_ratio(qs * a)?;
        let d = p * k1sq + q * qp * qs; // P17
        let mu = self.mu;
        let k11 = mu * qp * self.ks2 / d; // P18
        let k12 = -I * mu * k1 * (2.0 - self.ks2 * p / d); // P19
        let k22 = -(mu / a) * (2.0 + a * qs * self.ks2 * p * q / d); // P21
        Ok(SoilStiffness {
            k11,
            k12,
            k21: -k12, // P20
            k22,
        })
    }
}

impl SoilWaves {
    /// Eqs. P15–P21 and their derivative with respect to k1, by the chain rule:
    /// dq/dk1 = −k1/q, dP/dk1 = P′(q a)·a·dq/dk1 with P′ = 1 + P² + P/z.
    pub fn stiffness_d(&self, k1: Complex64, a: f64) -> Result<SoilStiffnessD, SpecialError> {
        let k1sq = k1 * k1;
        let qp = sqrt_plus(self.kp2 - k1sq);
        let qs = sqrt_plus(self.ks2 - k1sq);
        // One reciprocal each for q_P, q_S and D: complex divisions are the costly operation here.
        let (inv_qp, inv_qs) = (qp.inv(), qs.inv());
        let (dqp, dqs) = (-k1 * inv_qp, -k1 * inv_qs);
        // P′(z) = 1 + P² + P/z (as `hankel_ratio_d`), with 1/z = 1/(q a) from the reciprocals.
        let (p, q) = (hankel_ratio(qp * a)?, hankel_ratio(qs * a)?);
        let inv_a = 1.0 / a;
        let p1 = 1.0 + p * p + p * inv_qp * inv_a;
        let q1 = 1.0 + q * q + q * inv_qs * inv_a;
        let (dp, dq) = (p1 * a * dqp, q1 * a * dqs);
        let d = p * k1sq + q * qp * qs;
        let dd = dp * k1sq + p * 2.0 * k1 + dq * qp * qs + q * (dqp * qs + qp * dqs);
        let inv_d = d.inv();
        let dd_d = dd * inv_d;
        let (mu, ks2) = (self.mu, self.ks2);
        let k11 = mu * qp * ks2 * inv_d;
        let dk11 = mu * ks2 * (dqp - qp * dd_d) * inv_d;
        let t = 2.0 - ks2 * p * inv_d;
        let dt = -ks2 * (dp - p * dd_d) * inv_d;
        let k12 = -I * mu * k1 * t;
        let dk12 = -I * mu * (t + k1 * dt);
        let u = qs * p * q * inv_d;
        let du = (dqs * p * q + qs * dp * q + qs * p * dq) * inv_d - u * dd_d;
        let k22 = -(mu / a) * (2.0 + a * ks2 * u);
        let dk22 = -mu * ks2 * du;
        Ok(SoilStiffnessD {
            k: SoilStiffness {
                k11,
                k12,
                k21: -k12,
                k22,
            },
            dk: SoilStiffness {
                k11: dk11,
                k12: dk12,
                k21: -dk12,
                k22: dk22,
            },
        })
    }
}

/// Quantities of eqs. P8–P14 at one angular frequency, and the residual F(k1) of eq. P32.
#[derive(Debug, Clone, Copy)]
pub struct Evaluator {
    /// Angular frequency ω, rad/s.
    pub omega: f64,
    /// k_f² = ω²ρ_f/B_f, eq. P8.
    pub kf2: f64,
    /// β = 2(a/h)(1 − ν_p²)B_f/Ê_p, eq. P10.
    pub beta: Complex64,
    /// Ω² = ω²a²ρ_p(1 − ν_p²)/Ê_p, eq. P11.
    pub omega2: Complex64,
    /// κ = a²(1 − ν_p²)/(Ê_p h), eq. P12.
    pub kappa: Complex64,
    /// Mean radius a, m.
    pub a: f64,
    /// Pipe Poisson's ratio ν_p.
    pub nu_p: f64,
    /// Soil waves, `None` in vacuo (eq. P22).
    pub soil: Option<SoilWaves>,
    /// Contact coefficient ξ.
    pub contact: f64,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
}

impl Evaluator {
    /// Precompute eqs. P8–P14 for `system` at angular frequency `omega` (rad/s).
    pub fn new(system: &System, omega: f64) -> Self {
        let (fl, p, s) = (&system.fluid, &system.pipe, &system.soil);
        let e_hat = p.complex_modulus(omega); // P9 (P70 for a viscoelastic wall)
        let one_nu2 = 1.0 - p.poisson * p.poisson;
        let (a, h) = (p.mean_radius, p.wall_thickness);
        let soil = if s.is_absent() {
            None
        } else {
            Some(SoilWaves::new(
                s.youngs_modulus,
                s.poisson,
                s.density,
                s.loss_factor,
                omega,
            ))
        };
        Self {
            omega,
            kf2: omega * omega * fl.density / fl.bulk_modulus, // P8
            beta: 2.0 * (a / h) * one_nu2 * fl.bulk_modulus / e_hat, // P10
            omega2: omega * omega * a * a * p.density * one_nu2 / e_hat, // P11
            kappa: a * a * one_nu2 / (e_hat * h),              // P12
            a,
            nu_p: p.poisson,
            soil,
            contact: system.contact,
            model: system.model,
            contact_mode: system.contact_mode,
        }
    }

    /// Soil stiffness at k1 (zero in vacuo, eq. P22).
    pub fn stiffness(&self, k1: Complex64) -> Result<SoilStiffness, SpecialError> {
        match &self.soil {
            Some(s) => s.stiffness(k1, self.a),
            None => Ok(SoilStiffness::ZERO),
        }
    }

    /// α of eq. P29/P34 (`reciprocal`), P35 (`printed`) or P37 (`blend`), given the stiffness.
    pub fn alpha_with(&self, k1: Complex64, k: &SoilStiffness) -> Complex64 {
        let ka = k1 * self.a;
        let ka2 = ka * ka;
        let (nu, kappa, xi) = (self.nu_p, self.kappa, self.contact);
        let delta = match self.model {
            Model::Full => 1.0,
            Model::Seed => 0.0,
        };
        let d_ax = delta * self.omega2 - ka2 + xi * kappa * k.k11; // P28
        match self.contact_mode {
            ContactMode::Reciprocal => {
                let c_ax = -I * nu * ka + xi * kappa * k.k12; // P28
                let c_ra = I * nu * ka + kappa * k.k21;
                -kappa * k.k22 + c_ra * c_ax / d_ax // P29
            }
            ContactMode::Printed => {
                let s = kappa * k.k21; // P35
                -kappa * k.k22 + ka2 * (nu + I * s / ka) * (nu - I * xi * s / ka) / d_ax
            }
            ContactMode::Blend => {
                let c_ax = -I * nu * ka + xi * kappa * k.k12; // P37
                let c_ra = I * nu * ka + xi * kappa * k.k21;
                let k_eff = xi * k.k22 + (1.0 - xi) * k.slip(); // P36
                -kappa * k_eff + c_ra * c_ax / d_ax
            }
        }
    }

    /// α at k1 (eqs. P28–P37).
    pub fn alpha(&self, k1: Complex64) -> Result<Complex64, SpecialError> {
        Ok(self.alpha_with(k1, &self.stiffness(k1)?))
    }

    /// The fluid-loading factor ψ: eq. P24 in `full`, 1 in `seed` (P33).
    pub fn psi(&self, k1: Complex64) -> Result<Complex64, SpecialError> {
        match self.model {
            Model::Full => psi((self.kf2 - k1 * k1) * (self.a * self.a)),
            Model::Seed => Ok(Complex64::new(1.0, 0.0)),
        }
    }

    /// The residual F(k1) = k1²/k_f² − 1 − βψ/(1 − Ω² + α(k1)), eq. P32. Dimensionless, O(1).
    pub fn residual(&self, k1: Complex64) -> Result<Complex64, SpecialError> {
        let alpha = self.alpha(k1)?;
        let psi = self.psi(k1)?;
        Ok(k1 * k1 / self.kf2 - 1.0 - self.beta * psi / (1.0 - self.omega2 + alpha))
    }

    /// F(k1) of eq. P32 and dF/dk1, for Newton's method. The derivative follows every step of
    /// eqs. P15–P37 by the chain rule; `tests/physics_limits.rs` checks it against central
    /// differences for every model and contact reading.
    pub fn residual_d(&self, k1: Complex64) -> Result<(Complex64, Complex64), SpecialError> {
        let (a, nu, kappa, xi) = (self.a, self.nu_p, self.kappa, self.contact);
        let zero = Complex64::new(0.0, 0.0);
        let (k, dk) = match &self.soil {
            Some(s) => {
                let d = s.stiffness_d(k1, a)?;
                (d.k, d.dk)
            }
            None => (SoilStiffness::ZERO, SoilStiffness::ZERO),
        };
        let ka = k1 * a;
        let delta = match self.model {
            Model::Full => 1.0,
            Model::Seed => 0.0,
        };
        let d_ax = delta * self.omega2 - ka * ka + xi * kappa * k.k11;
        let dd_ax = -2.0 * ka * a + xi * kappa * dk.k11;
        let (alpha, dalpha) = match self.contact_mode {
            ContactMode::Reciprocal | ContactMode::Blend => {
                let blend = self.contact_mode == ContactMode::Blend;
                let f21 = if blend { xi } else { 1.0 };
                let c_ax = -I * nu * ka + xi * kappa * k.k12;
                let dc_ax = -I * nu * a + xi * kappa * dk.k12;
                let c_ra = I * nu * ka + f21 * kappa * k.k21;
                let dc_ra = I * nu * a + f21 * kappa * dk.k21;
                let (keff, dkeff) = if blend {
                    // K_slip = K22 + K12²/K11 (K21 = −K12), zero without soil (P22).
                    let (ks, dks) = if k.k11 == zero {
                        (zero, zero)
                    } else {
                        (
                            k.k22 + k.k12 * k.k12 / k.k11,
                            dk.k22
                                + (2.0 * k.k12 * dk.k12 * k.k11 - k.k12 * k.k12 * dk.k11)
                                    / (k.k11 * k.k11),
                        )
                    };
                    (xi * k.k22 + (1.0 - xi) * ks, xi * dk.k22 + (1.0 - xi) * dks)
                } else {
                    (k.k22, dk.k22)
                };
                let n = c_ra * c_ax;
                let dn = dc_ra * c_ax + c_ra * dc_ax;
                let inv_d_ax = d_ax.inv();
                let n_d = n * inv_d_ax;
                (
                    -kappa * keff + n_d,
                    -kappa * dkeff + (dn - n_d * dd_ax) * inv_d_ax,
                )
            }
            ContactMode::Printed => {
                // ka²(ν + iS/ka)(ν − iξS/ka) = (ν ka + iS)(ν ka − iξS), S = κK21 (P35).
                let (sv, dsv) = (kappa * k.k21, kappa * dk.k21);
                let (f1, df1) = (nu * ka + I * sv, nu * a + I * dsv);
                let (f2, df2) = (nu * ka - I * xi * sv, nu * a - I * xi * dsv);
                let n = f1 * f2;
                let dn = df1 * f2 + f1 * df2;
                let inv_d_ax = d_ax.inv();
                let n_d = n * inv_d_ax;
                (
                    -kappa * k.k22 + n_d,
                    -kappa * dk.k22 + (dn - n_d * dd_ax) * inv_d_ax,
                )
            }
        };
        let (psi_v, dpsi) = match self.model {
            Model::Full => {
                let (p, pw) = psi_d((self.kf2 - k1 * k1) * (a * a))?;
                (p, pw * (-2.0 * k1 * a * a))
            }
            Model::Seed => (Complex64::new(1.0, 0.0), zero),
        };
        let inv_den = (1.0 - self.omega2 + alpha).inv();
        let psi_den = psi_v * inv_den;
        let f = k1 * k1 / self.kf2 - 1.0 - self.beta * psi_den;
        let df = 2.0 * k1 / self.kf2 - self.beta * (dpsi - psi_den * dalpha) * inv_den;
        Ok((f, df))
    }

    /// The in-vacuo root, eq. P39: k1² = k_f²[1 + β₀/(1 − Ω₀²)], principal root with Re ≥ 0.
    /// β₀ = β/(1 − ν_p²) and Ω₀² = Ω²/(1 − ν_p²).
    pub fn in_vacuo_root(&self) -> Complex64 {
        let one_nu2 = 1.0 - self.nu_p * self.nu_p;
        let beta0 = self.beta / one_nu2;
        let omega0_2 = self.omega2 / one_nu2;
        let k = principal_sqrt(self.kf2 * (1.0 + beta0 / (1.0 - omega0_2)));
        if k.re < 0.0 {
            -k
        } else {
            k
        }
    }
}

/// Free-standing form of eq. P39 for a system and ω (rad/s).
pub fn in_vacuo_root(system: &System, omega: f64) -> Complex64 {
    Evaluator::new(system, omega).in_vacuo_root()
}

/// Korteweg's speed c_K = c_f/√(1 + 2aB_f/(E_p h)) with the real E_p, eq. P45 \[R21\].
pub fn korteweg_speed(system: &System) -> f64 {
    let (f, p) = (&system.fluid, &system.pipe);
    f.sound_speed()
        / (1.0 + 2.0 * p.mean_radius * f.bulk_modulus / (p.youngs_modulus * p.wall_thickness))
            .sqrt()
}

/// Low-frequency limit of the `full` model without soil, eq. P46: the fixed point of
/// c² = c_f²/(1 + β/(1 − ν_p²/(1 − c²/c_L²))), started from c_K. Real moduli.
pub fn full_model_low_frequency_speed(system: &System) -> f64 {
    let (f, p) = (&system.fluid, &system.pipe);
    let one_nu2 = 1.0 - p.poisson * p.poisson;
    let beta =
        2.0 * (p.mean_radius / p.wall_thickness) * one_nu2 * f.bulk_modulus / p.youngs_modulus;
    let cl2 = p.plate_speed().powi(2);
    let cf2 = f.sound_speed().powi(2);
    let mut c = korteweg_speed(system);
    for _ in 0..200 {
        let next =
            (cf2 / (1.0 + beta / (1.0 - p.poisson * p.poisson / (1.0 - c * c / cl2)))).sqrt();
        if (next - c).abs() <= 1e-15 * c {
            return next;
        }
        c = next;
    }
    c
}
