//! Checked physical inputs: the fluid, the pipe wall, the soil and the model options.
//!
//! Every type is built by a constructor that returns `Result`, so the numerical kernels can
//! assume valid input. Ranges are those of model §3.1 ("valid range (reject outside)").

use std::fmt;
use std::str::FromStr;

use num_complex::Complex64;

/// A physical input outside its valid range, with the offending value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// A value outside its valid range.
    #[error("{name} = {} is outside the valid range {range}", crate::units::short(*.value))]
    OutOfRange {
        /// Name of the quantity, with its unit.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The valid range, for the message.
        range: &'static str,
    },
    /// A value that is not a finite number.
    #[error("{name} is not a finite number ({})", crate::units::short(*.value))]
    NotFinite {
        /// Name of the quantity.
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A value of an enumerated option that we do not know.
    #[error("unknown {what} '{value}' (expected one of {expected})")]
    Unknown {
        /// What kind of option.
        what: &'static str,
        /// The rejected text.
        value: String,
        /// The accepted values.
        expected: &'static str,
    },
    /// The wall is too thick for the thin-shell model.
    #[error("wall thickness {} m is more than a quarter of the mean radius {} m (h/a = {ratio:.3} > 0.25): the thin-shell model does not apply", crate::units::short(*.h), crate::units::short(*.a))]
    WallTooThick {
        /// Wall thickness, m.
        h: f64,
        /// Mean radius, m.
        a: f64,
        /// h/a.
        ratio: f64,
    },
}

/// The valid range of one input quantity (model §3.1, "reject outside"). Each range is written
/// once, below; the checked constructors, the importer (which names the offending column) and
/// the synthetic networks all read these.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidRange {
    /// The quantity with its unit, for messages.
    pub name: &'static str,
    /// Lowest valid value.
    pub lo: f64,
    /// Highest valid value.
    pub hi: f64,
    /// The range as written in messages.
    pub text: &'static str,
}

impl ValidRange {
    /// `value` if finite and in the range.
    pub fn check(&self, value: f64) -> Result<f64, InputError> {
        check_range(self.name, value, self.lo, self.hi, self.text)
    }

    /// Is `value` finite and in the range?
    pub fn contains(&self, value: f64) -> bool {
        self.check(value).is_ok()
    }
}

/// Fluid density ρ_f, kg/m³ (model §3.1).
pub const FLUID_DENSITY_RANGE: ValidRange = ValidRange {
    name: "fluid density (kg/m3)",
    lo: 500.0,
    hi: 1100.0,
    text: "500 - 1100",
};
/// Fluid bulk modulus B_f, Pa (model §3.1).
pub const FLUID_BULK_MODULUS_RANGE: ValidRange = ValidRange {
    name: "fluid bulk modulus (Pa)",
    lo: 1e6,
    hi: 2.5e9,
    text: "1e6 - 2.5e9",
};
/// Pipe Young's modulus E_p, Pa (model §3.1).
pub const PIPE_YOUNGS_MODULUS_RANGE: ValidRange = ValidRange {
    name: "pipe Young's modulus (Pa)",
    lo: 1e8,
    hi: 3e11,
    text: "1e8 - 3e11",
};
/// Pipe Poisson's ratio ν_p (model §3.1).
pub const PIPE_POISSON_RANGE: ValidRange = ValidRange {
    name: "pipe Poisson's ratio",
    lo: 0.0,
    hi: 0.49,
    text: "0 - 0.49",
};
/// Pipe density ρ_p, kg/m³ (model §3.1).
pub const PIPE_DENSITY_RANGE: ValidRange = ValidRange {
    name: "pipe density (kg/m3)",
    lo: 500.0,
    hi: 9000.0,
    text: "500 - 9000",
};
/// Pipe loss factor η_p (model §3.1).
pub const PIPE_LOSS_FACTOR_RANGE: ValidRange = ValidRange {
    name: "pipe loss factor",
    lo: 0.0,
    hi: 0.3,
    text: "0 - 0.3",
};
/// Mean radius a, m (model §3.1).
pub const MEAN_RADIUS_RANGE: ValidRange = ValidRange {
    name: "mean radius (m)",
    lo: 0.005,
    hi: 1.5,
    text: "0.005 - 1.5",
};
/// Soil density ρ_m, kg/m³ (model §3.1: from a soil test, never fitted).
pub const SOIL_DENSITY_RANGE: ValidRange = ValidRange {
    name: "soil density (kg/m3)",
    lo: 1000.0,
    hi: 2600.0,
    text: "1000 - 2600",
};

/// Angular frequencies the fit accepts, rad/s: from far below any pipe resonance to well above
/// the leak-noise band; the importer checks ω = 2πf against it too.
pub const OMEGA_RANGE: ValidRange = ValidRange {
    name: "angular frequency (rad/s)",
    lo: 1e-6,
    hi: 1e7,
    text: "1e-6 - 1e7",
};
/// Measured Re k the fit accepts, rad/m (> 0).
pub const K_RE_RANGE: ValidRange = ValidRange {
    name: "k_re (rad/m)",
    lo: 1e-9,
    hi: 1e4,
    text: "1e-9 - 1e4",
};
/// Measured attenuation the fit accepts, Np/m (>= 0).
pub const ATTENUATION_RANGE: ValidRange = ValidRange {
    name: "attenuation (Np/m)",
    lo: 0.0,
    hi: 1e3,
    text: "0 - 1e3",
};
/// A measurement's standard deviation (of Re k or of the attenuation) the fit accepts (> 0).
pub const MEASUREMENT_STD_RANGE: ValidRange = ValidRange {
    name: "standard deviation",
    lo: 1e-300,
    hi: 1e6,
    text: "1e-300 - 1e6",
};

/// Check that `value` is finite and in `[lo, hi]`.
pub(crate) fn check_range(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    range: &'static str,
) -> Result<f64, InputError> {
    if !value.is_finite() {
        return Err(InputError::NotFinite { name, value });
    }
    if value < lo || value > hi {
        return Err(InputError::OutOfRange { name, value, range });
    }
    Ok(value)
}

/// The fluid in the pipe (water, possibly with air: see [`crate::physics::effects`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fluid {
    /// Density ρ_f, kg/m³.
    pub density: f64,
    /// Bulk modulus B_f, Pa (real: the fluid is lossless, model §2).
    pub bulk_modulus: f64,
}

/// Density of water, kg/m³ (model §3.1 default).
pub const WATER_DENSITY: f64 = 1000.0;
/// Bulk modulus of water, Pa (model §3.1 default).
pub const WATER_BULK_MODULUS: f64 = 2.25e9;

impl Fluid {
    /// A checked fluid: ρ_f in 500–1100 kg/m³, B_f in 1e6–2.5e9 Pa (model §3.1).
    pub fn new(density: f64, bulk_modulus: f64) -> Result<Self, InputError> {
        FLUID_DENSITY_RANGE.check(density)?;
        FLUID_BULK_MODULUS_RANGE.check(bulk_modulus)?;
        Ok(Self {
            density,
            bulk_modulus,
        })
    }

    /// Water: 1000 kg/m³, 2.25e9 Pa.
    pub fn water() -> Self {
        Self {
            density: WATER_DENSITY,
            bulk_modulus: WATER_BULK_MODULUS,
        }
    }

    /// Free-field sound speed c_f = √(B_f/ρ_f), m/s, eq. P8.
    pub fn sound_speed(&self) -> f64 {
        (self.bulk_modulus / self.density).sqrt()
    }
}

/// The pipe wall, as a thin membrane shell of mean radius a and thickness h.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pipe {
    /// Young's modulus E_p (storage part), Pa.
    pub youngs_modulus: f64,
    /// Poisson's ratio ν_p.
    pub poisson: f64,
    /// Density ρ_p, kg/m³.
    pub density: f64,
    /// Loss factor η_p (E_p → E_p(1 + iη_p), eq. P4).
    pub loss_factor: f64,
    /// Mean radius a, m (eq. P6).
    pub mean_radius: f64,
    /// Wall thickness h, m.
    pub wall_thickness: f64,
    /// Exponent n of the causal power-law wall modulus of model §8 E7 (eq. P70); 0 means the
    /// constant-loss wall of eq. P9 (the default). When n > 0 it replaces `loss_factor`.
    pub viscoelastic_exponent: f64,
}

/// Reference angular frequency ω_ref of the power-law wall modulus, rad/s: 2π·100 (eq. P70).
pub const VISCOELASTIC_REFERENCE_OMEGA: f64 = 2.0 * std::f64::consts::PI * 100.0;

impl Pipe {
    /// The complex wall modulus Ê_p at angular frequency ω (rad/s): E_p(1 + iη_p) (eq. P9), or,
    /// with a viscoelastic exponent n > 0, E_p (ω/ω_ref)^n (1 + i tan(nπ/2)) (eqs. P70–P71).
    pub fn complex_modulus(&self, omega: f64) -> Complex64 {
        let n = self.viscoelastic_exponent;
        if n == 0.0 {
            return Complex64::new(self.youngs_modulus, self.youngs_modulus * self.loss_factor);
        }
        let storage = self.youngs_modulus * (omega / VISCOELASTIC_REFERENCE_OMEGA).powf(n);
        Complex64::new(storage, storage * (n * std::f64::consts::FRAC_PI_2).tan())
    }

    /// A checked pipe (model §3.1): E_p 1e8–3e11 Pa, ν_p 0–0.49, ρ_p 500–9000 kg/m³,
    /// η_p 0–0.3, a 0.005–1.5 m, h > 0 and h/a ≤ 0.25.
    pub fn new(
        youngs_modulus: f64,
        poisson: f64,
        density: f64,
        loss_factor: f64,
        mean_radius: f64,
        wall_thickness: f64,
    ) -> Result<Self, InputError> {
        PIPE_YOUNGS_MODULUS_RANGE.check(youngs_modulus)?;
        PIPE_POISSON_RANGE.check(poisson)?;
        PIPE_DENSITY_RANGE.check(density)?;
        PIPE_LOSS_FACTOR_RANGE.check(loss_factor)?;
        MEAN_RADIUS_RANGE.check(mean_radius)?;
        if !wall_thickness.is_finite() {
            return Err(InputError::NotFinite {
                name: "wall thickness (m)",
                value: wall_thickness,
            });
        }
        if wall_thickness <= 0.0 {
            return Err(InputError::OutOfRange {
                name: "wall thickness (m)",
                value: wall_thickness,
                range: "> 0",
            });
        }
        let ratio = wall_thickness / mean_radius;
        if ratio > MAX_WALL_RATIO {
            return Err(InputError::WallTooThick {
                h: wall_thickness,
                a: mean_radius,
                ratio,
            });
        }
        Ok(Self {
            youngs_modulus,
            poisson,
            density,
            loss_factor,
            mean_radius,
            wall_thickness,
            viscoelastic_exponent: 0.0,
        })
    }

    /// A pipe from its outside diameter D_o and wall thickness h (both m), a = (D_o − h)/2, eq. P6.
    pub fn from_outside_diameter(
        props: MaterialProps,
        outside_diameter: f64,
        wall_thickness: f64,
    ) -> Result<Self, InputError> {
        if !(outside_diameter.is_finite() && outside_diameter > 0.0) {
            return Err(InputError::OutOfRange {
                name: "outside diameter (m)",
                value: outside_diameter,
                range: "> 0",
            });
        }
        if wall_thickness >= outside_diameter / 2.0 {
            return Err(InputError::OutOfRange {
                name: "wall thickness (m)",
                value: wall_thickness,
                range: "< outside diameter / 2",
            });
        }
        Self::new(
            props.youngs_modulus,
            props.poisson,
            props.density,
            props.loss_factor,
            (outside_diameter - wall_thickness) / 2.0,
            wall_thickness,
        )
    }

    /// Longitudinal (plate) wave speed c_L = √(E_p/(ρ_p(1 − ν_p²))), m/s, eq. P7.
    pub fn plate_speed(&self) -> f64 {
        (self.youngs_modulus / (self.density * (1.0 - self.poisson * self.poisson))).sqrt()
    }

    /// Ring frequency f_ring = c_L/(2πa), Hz, eq. P7.
    pub fn ring_frequency_hz(&self) -> f64 {
        self.plate_speed() / (2.0 * std::f64::consts::PI * self.mean_radius)
    }
}

/// Largest wall thickness to mean radius ratio of the thin-shell model (model §3.2, P7).
pub const MAX_WALL_RATIO: f64 = 0.25;
/// Above this h/a the thin-shell model loses accuracy; a warning, not a rejection (model §3.1).
pub const WARN_WALL_RATIO: f64 = 0.15;

/// The soil: an isotropic elastic full space outside the pipe. `youngs_modulus = 0` means no soil
/// (in vacuo, model §3.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Soil {
    /// Young's modulus E_m, Pa (0 = no soil).
    pub youngs_modulus: f64,
    /// Poisson's ratio ν_m.
    pub poisson: f64,
    /// Density ρ_m, kg/m³.
    pub density: f64,
    /// Loss factor η_m (λ, μ → (1 + iη_m)(λ, μ), eq. P4).
    pub loss_factor: f64,
}

/// Largest soil Poisson's ratio: ν_m = 0.5 makes λ_m infinite (model §3.1, §7.1).
pub const MAX_SOIL_POISSON: f64 = 0.499;

impl Soil {
    /// A checked soil (model §3.1): E_m 0 (no soil) or 1e3–1e10 Pa, ν_m 0–0.499,
    /// ρ_m 1000–2600 kg/m³, η_m 0–0.3.
    pub fn new(
        youngs_modulus: f64,
        poisson: f64,
        density: f64,
        loss_factor: f64,
    ) -> Result<Self, InputError> {
        if youngs_modulus != 0.0 {
            check_range(
                "soil Young's modulus (Pa)",
                youngs_modulus,
                1e3,
                1e10,
                "0 (no soil) or 1e3 - 1e10",
            )?;
        }
        SOIL_DENSITY_RANGE.check(density)?;
        Self::new_unbounded(youngs_modulus, poisson, density, loss_factor)
    }

    /// A soil checked only for physical sense (finite, E_m ≥ 0, ρ_m ≥ 0, 0 ≤ ν_m ≤ 0.499,
    /// 0 ≤ η_m ≤ 0.3), not for the typical ranges. For limit studies such as E_m → 0 (model §6 T3).
    pub fn new_unbounded(
        youngs_modulus: f64,
        poisson: f64,
        density: f64,
        loss_factor: f64,
    ) -> Result<Self, InputError> {
        check_range(
            "soil Young's modulus (Pa)",
            youngs_modulus,
            0.0,
            1e12,
            ">= 0",
        )?;
        check_range(
            "soil Poisson's ratio",
            poisson,
            0.0,
            MAX_SOIL_POISSON,
            "0 - 0.499",
        )?;
        check_range("soil density (kg/m3)", density, 0.0, 1e4, ">= 0")?;
        check_range("soil loss factor", loss_factor, 0.0, 0.3, "0 - 0.3")?;
        Ok(Self {
            youngs_modulus,
            poisson,
            density,
            loss_factor,
        })
    }

    /// No soil: the pipe in vacuo.
    pub fn none() -> Self {
        Self {
            youngs_modulus: 0.0,
            poisson: 0.0,
            density: 0.0,
            loss_factor: 0.0,
        }
    }

    /// True when the soil is absent (E_m = 0 or ρ_m = 0), eq. P22.
    pub fn is_absent(&self) -> bool {
        self.youngs_modulus == 0.0 || self.density == 0.0
    }

    /// Real Lamé constants (λ_m, μ_m), Pa, eq. P13 without the loss factor.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.youngs_modulus, self.poisson);
        (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        )
    }

    /// Compressional and shear wave speeds (c_P, c_S), m/s, with real moduli (model §3.4).
    pub fn wave_speeds(&self) -> (f64, f64) {
        let (lambda, mu) = self.lame();
        (
            ((lambda + 2.0 * mu) / self.density).sqrt(),
            (mu / self.density).sqrt(),
        )
    }
}

/// Model variant, model §4.9.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Model {
    /// Exact fluid loading ψ (P24) and axial wall inertia (δ = 1). The default.
    #[default]
    Full,
    /// The paper's eq. (1): ψ ≡ 1 and δ = 0 (P33).
    Seed,
}

/// Reading of the contact coefficient ξ, model §4.10.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ContactMode {
    /// ξ scales the interface shear traction in the axial equation (P34). The default.
    #[default]
    Reciprocal,
    /// The paper's eq. (2) as printed, non-reciprocal (P35). Only to mimic the paper.
    Printed,
    /// Interpolation of the stiffness between bonded and true slip (P36–P37).
    Blend,
}

impl Model {
    /// The name used in CSV files and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            Model::Full => "full",
            Model::Seed => "seed",
        }
    }
}

impl ContactMode {
    /// The name used in CSV files and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            ContactMode::Reciprocal => "reciprocal",
            ContactMode::Printed => "printed",
            ContactMode::Blend => "blend",
        }
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Display for ContactMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Model {
    type Err = InputError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "full" => Ok(Model::Full),
            "seed" => Ok(Model::Seed),
            _ => Err(InputError::Unknown {
                what: "model",
                value: s.to_string(),
                expected: "full, seed",
            }),
        }
    }
}

impl FromStr for ContactMode {
    type Err = InputError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "reciprocal" => Ok(ContactMode::Reciprocal),
            "printed" => Ok(ContactMode::Printed),
            "blend" => Ok(ContactMode::Blend),
            _ => Err(InputError::Unknown {
                what: "contact mode",
                value: s.to_string(),
                expected: "reciprocal, printed, blend",
            }),
        }
    }
}

/// Everything the dispersion relation needs: fluid, pipe, soil, contact and model variant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct System {
    /// The fluid (possibly with air, after [`crate::physics::effects`]).
    pub fluid: Fluid,
    /// The pipe wall (its thickness possibly the effective one).
    pub pipe: Pipe,
    /// The soil (E_m = 0: none).
    pub soil: Soil,
    /// Contact coefficient ξ ∈ [0, 1].
    pub contact: f64,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
}

impl System {
    /// A checked system: ξ ∈ [0, 1]; the parts are checked by their own constructors.
    pub fn new(
        fluid: Fluid,
        pipe: Pipe,
        soil: Soil,
        contact: f64,
        model: Model,
        contact_mode: ContactMode,
    ) -> Result<Self, InputError> {
        check_range("contact coefficient", contact, 0.0, 1.0, "0 - 1")?;
        Ok(Self {
            fluid,
            pipe,
            soil,
            contact,
            model,
            contact_mode,
        })
    }
}

/// Typical properties of a pipe material (model §3.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialProps {
    /// Young's modulus E_p, Pa.
    pub youngs_modulus: f64,
    /// Poisson's ratio ν_p.
    pub poisson: f64,
    /// Density ρ_p, kg/m³.
    pub density: f64,
    /// Loss factor η_p.
    pub loss_factor: f64,
}

/// Pipe materials of the inventory (model §3.3; interface `segments.csv` codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Material {
    /// Grey cast iron.
    CastIron,
    /// Ductile iron.
    DuctileIron,
    /// Steel.
    Steel,
    /// PVC-U.
    Pvc,
    /// Medium-density polyethylene (PE80).
    Mdpe,
    /// High-density polyethylene (PE100).
    Hdpe,
    /// Asbestos cement.
    AsbestosCement,
}

impl Material {
    /// All materials, in the order of the table of model §3.3.
    pub const ALL: [Material; 7] = [
        Material::CastIron,
        Material::DuctileIron,
        Material::Steel,
        Material::Pvc,
        Material::Mdpe,
        Material::Hdpe,
        Material::AsbestosCement,
    ];

    /// The inventory code (`CI`, `DI`, `ST`, `PVC`, `MDPE`, `HDPE`, `AC`).
    pub fn code(self) -> &'static str {
        match self {
            Material::CastIron => "CI",
            Material::DuctileIron => "DI",
            Material::Steel => "ST",
            Material::Pvc => "PVC",
            Material::Mdpe => "MDPE",
            Material::Hdpe => "HDPE",
            Material::AsbestosCement => "AC",
        }
    }

    /// Plain name.
    pub fn name(self) -> &'static str {
        match self {
            Material::CastIron => "grey cast iron",
            Material::DuctileIron => "ductile iron",
            Material::Steel => "steel",
            Material::Pvc => "PVC-U",
            Material::Mdpe => "MDPE (PE80)",
            Material::Hdpe => "HDPE (PE100)",
            Material::AsbestosCement => "asbestos cement",
        }
    }

    /// True for the viscoelastic plastics.
    pub fn is_plastic(self) -> bool {
        matches!(self, Material::Pvc | Material::Mdpe | Material::Hdpe)
    }

    /// Typical properties, model §3.3. Sources: \[M1\] Fuji Tecom LC-50 manual; \[M2\] AMES Web;
    /// \[M3\] MakeItFrom; \[M4\] ASTM A48 table; \[M5\] steel constants; \[M6\] Uni-Bell / PPI via
    /// Aegion; \[M7\] asbestos-cement density; \[M8\] Muggleton group MDPE fits [R3, R4];
    /// \[M9\] Graf et al. 2014 (HDPE). Loss factors of DI, ST, PVC and AC are assumed (no source).
    pub fn typical(self) -> MaterialProps {
        let (youngs_modulus, poisson, density, loss_factor) = match self {
            Material::CastIron => (1.10e11, 0.26, 7200.0, 0.01),
            Material::DuctileIron => (1.70e11, 0.28, 7100.0, 0.01),
            Material::Steel => (2.07e11, 0.30, 7850.0, 0.001),
            Material::Pvc => (3.0e9, 0.40, 1400.0, 0.04),
            Material::Mdpe => (2.0e9, 0.40, 940.0, 0.06),
            Material::Hdpe => (2.2e9, 0.45, 955.0, 0.06),
            Material::AsbestosCement => (2.4e10, 0.20, 1900.0, 0.01),
        };
        MaterialProps {
            youngs_modulus,
            poisson,
            density,
            loss_factor,
        }
    }

    /// Plausible range of the pipe Young's modulus, Pa (model §3.3), used to judge whether a
    /// measured speed is possible for this material.
    pub fn youngs_modulus_range(self) -> (f64, f64) {
        match self {
            Material::CastIron => (0.7e11, 1.4e11),
            Material::DuctileIron => (1.57e11, 1.80e11),
            Material::Steel => (2.0e11, 2.1e11),
            Material::Pvc => (2.7e9, 3.6e9),
            Material::Mdpe => (1.4e9, 2.4e9),
            Material::Hdpe => (1.0e9, 2.6e9),
            Material::AsbestosCement => (2.0e10, 3.0e10),
        }
    }
}

impl fmt::Display for Material {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.code())
    }
}

impl FromStr for Material {
    type Err = InputError;
    /// Parse an inventory code, case-insensitive.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_uppercase();
        Material::ALL
            .into_iter()
            .find(|m| m.code() == t)
            .ok_or_else(|| InputError::Unknown {
                what: "material",
                value: s.to_string(),
                expected: "CI, DI, ST, PVC, MDPE, HDPE, AC",
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_reject_non_physical_values() {
        assert!(Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, -0.006).is_err());
        assert!(Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, 0.0).is_err());
        assert!(matches!(
            Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, 0.03),
            Err(InputError::WallTooThick { .. })
        ));
        assert!(Pipe::new(1.7e11, 0.6, 7100.0, 0.01, 0.082, 0.006).is_err());
        assert!(Pipe::new(f64::NAN, 0.28, 7100.0, 0.01, 0.082, 0.006).is_err());
        assert!(Soil::new(5e7, 0.5, 1900.0, 0.0).is_err());
        assert!(Soil::new(5e7, -0.1, 1900.0, 0.0).is_err());
        assert!(Soil::new(5e7, 0.3, 900.0, 0.0).is_err());
        assert!(Soil::new(10.0, 0.3, 1900.0, 0.0).is_err());
        assert!(Soil::new(0.0, 0.3, 1900.0, 0.0).unwrap().is_absent());
        assert!(Soil::new_unbounded(10.0, 0.3, 1900.0, 0.0).is_ok());
        assert!(Fluid::new(1000.0, 3e9).is_err());
        let p = Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, 0.006).unwrap();
        assert!(System::new(
            Fluid::water(),
            p,
            Soil::none(),
            1.5,
            Model::Full,
            ContactMode::Blend
        )
        .is_err());
        let msg = Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, 0.03)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("thin-shell"), "{msg}");
    }

    #[test]
    fn mean_radius_from_outside_diameter_eq_p6() {
        let p = Pipe::from_outside_diameter(Material::DuctileIron.typical(), 0.170, 0.006).unwrap();
        assert!((p.mean_radius - 0.082).abs() < 1e-15);
        assert!(Pipe::from_outside_diameter(Material::DuctileIron.typical(), 0.170, 0.09).is_err());
    }

    #[test]
    fn material_codes_round_trip_case_insensitive() {
        for m in Material::ALL {
            assert_eq!(m.code().parse::<Material>().unwrap(), m);
            assert_eq!(m.code().to_lowercase().parse::<Material>().unwrap(), m);
        }
        assert!("XX".parse::<Material>().is_err());
    }

    #[test]
    fn soil_wave_speeds_match_spec_table_3_4() {
        // Reference loam: c_P 205.5, c_S 98.7 m/s.
        let (cp, cs) = Soil::new(5.0e7, 0.35, 1900.0, 0.0).unwrap().wave_speeds();
        assert!(
            (cp - 205.5).abs() < 0.05 && (cs - 98.7).abs() < 0.05,
            "{cp} {cs}"
        );
    }

    #[test]
    fn ring_frequency_of_dn150_di_is_about_9_9_khz() {
        let p = Pipe::new(1.7e11, 0.28, 7100.0, 0.01, 0.082, 0.006).unwrap();
        let f = p.ring_frequency_hz();
        assert!((f - 9.9e3).abs() < 0.1e3, "{f}");
    }
}
