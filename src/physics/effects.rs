//! Extensions of the model ("effects"), model §8: inputs the effects change.
//!
//! Each effect changes one forward-model input: soil damping the soil loss factor η_m (E1,
//! eq. P13), pipe loss the wall loss factor η_p (E2, eq. P9), air in the water the fluid's bulk
//! modulus and density by Wood's equation (E3, eqs. P60–P61), wall thinning the effective wall
//! thickness (E4, eq. P62), the full model the model variant (E6, eq. P33), and the
//! viscoelastic wall the frequency dependence of the wall modulus (E7, eqs. P70–P71).
//! `inventory_error` (E8) is not a model input: it is tested by refitting candidate inventory
//! records ([`crate::diagnose::inventory`]).

use super::inputs::{check_range, Fluid, InputError, Model, Pipe, System};

/// Specific gas constant of air, J/(kg·K) (P61).
pub const R_AIR: f64 = 287.05;
/// Default absolute line pressure, Pa (3 bar gauge; model §8 E3 example).
pub const DEFAULT_LINE_PRESSURE_PA: f64 = 4e5;
/// Default polytropic index of the bubbles (isothermal), model §8 E3.
pub const DEFAULT_POLYTROPIC_INDEX: f64 = 1.0;
/// Default water temperature, K (15 °C), model §8 E3.
pub const DEFAULT_TEMPERATURE_K: f64 = 288.15;
/// Largest air volume fraction the effect allows (model §8 E3).
pub const MAX_AIR_FRACTION: f64 = 0.02;
/// Smallest effective / nominal wall thickness ratio (model §8 E4).
pub const MIN_WALL_RATIO: f64 = 0.3;
/// Largest exponent n of the power-law wall modulus (model §8 E7: η_p = tan(nπ/2) ≤ 0.32).
pub const MAX_VISCOELASTIC_EXPONENT: f64 = 0.2;

/// The exponent n of the power-law wall modulus whose loss factor tan(nπ/2) equals η (eq. P71
/// inverted): the viscoelastic wall closest to a constant-loss wall of loss factor η.
pub fn exponent_of_loss_factor(eta: f64) -> f64 {
    eta.atan() / std::f64::consts::FRAC_PI_2
}

/// Free air in the water (model §8 E3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirContent {
    /// Air volume fraction φ at line pressure, 0–0.02.
    pub fraction: f64,
    /// Absolute line pressure p_abs, Pa (> 0).
    pub pressure_abs: f64,
    /// Polytropic index γ, 1–1.4.
    pub polytropic_index: f64,
    /// Temperature T, K.
    pub temperature: f64,
}

impl AirContent {
    /// Checked air content.
    pub fn new(
        fraction: f64,
        pressure_abs: f64,
        polytropic_index: f64,
        temperature: f64,
    ) -> Result<Self, InputError> {
        check_range(
            "air volume fraction",
            fraction,
            0.0,
            MAX_AIR_FRACTION,
            "0 - 0.02",
        )?;
        check_range(
            "absolute line pressure (Pa)",
            pressure_abs,
            1e3,
            1e8,
            "1e3 - 1e8",
        )?;
        check_range("polytropic index", polytropic_index, 1.0, 1.4, "1 - 1.4")?;
        check_range("temperature (K)", temperature, 250.0, 350.0, "250 - 350")?;
        Ok(Self {
            fraction,
            pressure_abs,
            polytropic_index,
            temperature,
        })
    }

    /// Air fraction φ at the default line pressure, γ and temperature.
    pub fn with_fraction(fraction: f64) -> Result<Self, InputError> {
        Self::new(
            fraction,
            DEFAULT_LINE_PRESSURE_PA,
            DEFAULT_POLYTROPIC_INDEX,
            DEFAULT_TEMPERATURE_K,
        )
    }

    /// The bubbly mixture by Wood's equation \[R19\]: 1/B_eff = (1 − φ)/B_w + φ/(γ p_abs) (P60),
    /// ρ_eff = (1 − φ)ρ_w + φ p_abs/(R_air T) (P61). Lossless, below bubble resonance.
    pub fn mix(&self, water: &Fluid) -> Fluid {
        let phi = self.fraction;
        let inv_b =
            (1.0 - phi) / water.bulk_modulus + phi / (self.polytropic_index * self.pressure_abs);
        let rho_air = self.pressure_abs / (R_AIR * self.temperature);
        Fluid {
            density: (1.0 - phi) * water.density + phi * rho_air,
            bulk_modulus: 1.0 / inv_b,
        }
    }
}

/// The pipe with an effective wall thickness r_h·h, eq. P62 (a unchanged).
pub fn thinned(pipe: &Pipe, ratio: f64) -> Result<Pipe, InputError> {
    check_range(
        "effective / nominal wall thickness",
        ratio,
        MIN_WALL_RATIO,
        1.0,
        "0.3 - 1",
    )?;
    Ok(Pipe {
        wall_thickness: pipe.wall_thickness * ratio,
        ..*pipe
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Model Appendix A.4 footnote 2: B_eff = 339673913.04347825 Pa, ρ_eff = 999.0048359724293.
    #[test]
    fn wood_equation_matches_appendix_a4() {
        let air = AirContent::new(1e-3, 4e5, 1.0, 288.15).unwrap();
        let f = air.mix(&Fluid::water());
        assert!(
            (f.bulk_modulus / 339673913.04347825 - 1.0).abs() < 1e-13,
            "{}",
            f.bulk_modulus
        );
        assert!(
            (f.density / 999.0048359724293 - 1.0).abs() < 1e-13,
            "{}",
            f.density
        );
        assert!(AirContent::with_fraction(0.05).is_err());
    }

    #[test]
    fn effects_state_the_materials_they_apply_to() {
        use crate::physics::Material;
        for m in Material::ALL {
            // A polymer wall neither thins nor is stiff like iron; iron, steel and cement thin.
            assert_eq!(Effect::WallThinning.applies_to(m), !m.is_plastic(), "{m:?}");
            assert_eq!(
                Effect::ViscoelasticWall.applies_to(m),
                m.is_plastic(),
                "{m:?}"
            );
            for e in [
                Effect::SoilDamping,
                Effect::AirInWater,
                Effect::PipeLoss,
                Effect::FullModel,
                Effect::InventoryError,
                Effect::MeasurementUnits,
            ] {
                assert!(
                    e.applies_to(m) && e.not_applicable_note(m).is_none(),
                    "{e} {m:?}"
                );
            }
        }
        let note = Effect::WallThinning
            .not_applicable_note(Material::Pvc)
            .unwrap();
        assert!(
            note.starts_with("wall_thinning skipped: PVC walls"),
            "{note}"
        );
        assert!(Effect::MeasurementUnits.is_discrete() && !Effect::PipeLoss.is_discrete());
        assert_eq!(
            "measurement_units".parse::<Effect>().unwrap(),
            Effect::MeasurementUnits
        );
    }
}

/// The effects that extend the model, by their canonical names (docs/interface.md, "Effects").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// E1: soil material loss η_m.
    SoilDamping,
    /// E3: free air in the water, volume fraction φ.
    AirInWater,
    /// E4: effective / nominal wall thickness r_h.
    WallThinning,
    /// E2: pipe wall loss factor η_p above the material's typical value.
    PipeLoss,
    /// E6: the `full` model in place of `seed` (no parameter).
    FullModel,
    /// E7: a causal power-law wall modulus, exponent n (replaces the constant η_p).
    ViscoelasticWall,
    /// E8: the inventory describes another pipe (no continuous parameter: candidate records
    /// are refitted, [`crate::diagnose::inventory`]).
    InventoryError,
    /// The measurements were recorded in other units (attenuation in dB/m for Np/m, ω for f or
    /// f for ω): a measurement error, found by refitting the converted data
    /// ([`crate::diagnose::units`]), reported and never applied silently.
    MeasurementUnits,
}

impl Effect {
    /// Every effect, in the interface's order.
    pub const ALL: [Effect; 8] = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
        Effect::FullModel,
        Effect::ViscoelasticWall,
        Effect::InventoryError,
        Effect::MeasurementUnits,
    ];

    /// The effects that change the physics of the model (every effect but `inventory_error`,
    /// which changes the record).
    pub const PHYSICAL: [Effect; 6] = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
        Effect::FullModel,
        Effect::ViscoelasticWall,
    ];

    /// Canonical name.
    pub fn name(self) -> &'static str {
        match self {
            Effect::SoilDamping => "soil_damping",
            Effect::AirInWater => "air_in_water",
            Effect::WallThinning => "wall_thinning",
            Effect::PipeLoss => "pipe_loss",
            Effect::FullModel => "full_model",
            Effect::ViscoelasticWall => "viscoelastic_wall",
            Effect::InventoryError => "inventory_error",
            Effect::MeasurementUnits => "measurement_units",
        }
    }

    /// The parameter it adds, its range and the value that means "effect absent"; `None` for
    /// `full_model`, which is a switch, and for `inventory_error`, which is a choice among
    /// records. A NaN neutral value depends on the pipe: see [`Effect::neutral_value`].
    pub fn parameter(self) -> Option<EffectParameter> {
        let p = |name, lower, upper, neutral| {
            Some(EffectParameter {
                name,
                lower,
                upper,
                neutral,
            })
        };
        match self {
            Effect::SoilDamping => p("soil_loss_factor", 0.0, 0.3, 0.0),
            Effect::AirInWater => p("air_fraction", 0.0, MAX_AIR_FRACTION, 0.0),
            Effect::WallThinning => p("wall_thickness_ratio", MIN_WALL_RATIO, 1.0, 1.0),
            Effect::PipeLoss => p("pipe_loss_factor", 0.0, 0.3, f64::NAN),
            Effect::ViscoelasticWall => p(
                "viscoelastic_exponent",
                0.0,
                MAX_VISCOELASTIC_EXPONENT,
                f64::NAN,
            ),
            Effect::FullModel | Effect::InventoryError | Effect::MeasurementUnits => None,
        }
    }

    /// Whether a pipe of `material` can have this effect. A polymer wall neither corrodes nor
    /// graphitises, so it cannot thin (E4 is for iron, steel and cement); only polymers have
    /// the causal power-law modulus of E7 at leak-noise frequencies. Every other effect applies
    /// to every material.
    pub fn applies_to(self, material: crate::physics::Material) -> bool {
        match self {
            Effect::WallThinning => !material.is_plastic(),
            Effect::ViscoelasticWall => material.is_plastic(),
            _ => true,
        }
    }

    /// Why a pipe of `material` cannot have this effect (None when it can): the note a fit
    /// that leaves the effect out carries.
    pub fn not_applicable_note(self, material: crate::physics::Material) -> Option<String> {
        if self.applies_to(material) {
            return None;
        }
        Some(match self {
            Effect::WallThinning => format!(
                "{} skipped: {} walls neither corrode nor graphitise, so they do not thin \
                 (a thinner wall is a record to check: inventory_error)",
                self.name(),
                material.code()
            ),
            _ => format!(
                "{} skipped: {} walls have no power-law modulus at leak-noise frequencies",
                self.name(),
                material.code()
            ),
        })
    }

    /// True for the effects that are not a change of the model but a discrete alternative to
    /// the stored inputs (an inventory record, the measurements' units).
    pub fn is_discrete(self) -> bool {
        matches!(self, Effect::InventoryError | Effect::MeasurementUnits)
    }

    /// The parameter value at which the effect changes the least for `system`: the neutral
    /// value of [`Effect::parameter`], or where that depends on the pipe, the material's own
    /// loss factor (`pipe_loss`) and the exponent with the same loss factor, tan(nπ/2) = η_p
    /// (`viscoelastic_wall`, eq. P71; its storage modulus still rises by 10^n per decade, so
    /// this wall equals the constant-loss one only at ω_ref). `None` without a parameter.
    pub fn neutral_value(self, system: &System) -> Option<f64> {
        let p = self.parameter()?;
        Some(match self {
            Effect::PipeLoss => system.pipe.loss_factor,
            Effect::ViscoelasticWall => exponent_of_loss_factor(system.pipe.loss_factor),
            _ => p.neutral,
        })
    }

    /// Physical meaning, for reports.
    pub fn meaning(self) -> &'static str {
        match self {
            Effect::SoilDamping => "hysteretic loss in the soil skeleton (complex Lame moduli)",
            Effect::AirInWater => "free air bubbles softening the water (Wood's equation)",
            Effect::WallThinning => "corrosion or graphitisation thinning the load-bearing wall",
            Effect::PipeLoss => {
                "wall material and joint damping above the material's typical value"
            }
            Effect::FullModel => "exact radial fluid loading and axial wall inertia (full model)",
            Effect::ViscoelasticWall => {
                "a viscoelastic wall: modulus rising with frequency, loss tied to it (power law)"
            }
            Effect::InventoryError => {
                "the inventory describes another pipe (material, wall class or diameter units)"
            }
            Effect::MeasurementUnits => {
                "the measurements were recorded in other units (dB/m for Np/m, rad/s for Hz)"
            }
        }
    }

    /// Apply the effect with parameter `value` to a system (the base is unchanged).
    /// `full_model` ignores `value`. `inventory_error` is not a change of the system and is an
    /// error here (its candidates are whole records: [`crate::diagnose::inventory`]).
    pub fn apply(self, system: &System, value: f64) -> Result<System, InputError> {
        let mut s = *system;
        match self {
            Effect::SoilDamping => {
                s.soil.loss_factor = check_range("soil loss factor", value, 0.0, 0.3, "0 - 0.3")?;
            }
            Effect::AirInWater => {
                s.fluid = AirContent::with_fraction(value)?.mix(&system.fluid);
            }
            Effect::WallThinning => s.pipe = thinned(&system.pipe, value)?,
            Effect::PipeLoss => {
                s.pipe.loss_factor = check_range("pipe loss factor", value, 0.0, 0.3, "0 - 0.3")?;
            }
            Effect::FullModel => s.model = Model::Full,
            Effect::ViscoelasticWall => {
                s.pipe.viscoelastic_exponent = check_range(
                    "viscoelastic exponent",
                    value,
                    0.0,
                    MAX_VISCOELASTIC_EXPONENT,
                    "0 - 0.2",
                )?;
            }
            Effect::InventoryError | Effect::MeasurementUnits => {
                return Err(InputError::Unknown {
                    what: "model change",
                    value: self.name().into(),
                    expected: "an effect with a parameter (inventory_error refits candidate \
                               records, measurement_units converted measurements)",
                })
            }
        }
        Ok(s)
    }
}

/// The parameter an effect adds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectParameter {
    /// Column name in `fits` (without `_std`).
    pub name: &'static str,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// The value at which the effect is absent (NaN: the material's own value).
    pub neutral: f64,
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Effect {
    type Err = InputError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        Effect::ALL
            .into_iter()
            .find(|e| e.name() == t)
            .ok_or_else(|| InputError::Unknown {
                what: "effect",
                value: s.to_string(),
                expected: "soil_damping, air_in_water, wall_thinning, pipe_loss, full_model, viscoelastic_wall, inventory_error, measurement_units",
            })
    }
}

/// Parse a comma-separated list of effect names (empty text: none). Sorted, without repeats.
pub fn parse_effects(text: &str) -> Result<Vec<Effect>, InputError> {
    let mut v: Vec<Effect> = text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    v.sort();
    v.dedup();
    Ok(v)
}

/// Comma-separated names (the `fits.effects` column).
pub fn effects_text(effects: &[Effect]) -> String {
    effects
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join(",")
}
