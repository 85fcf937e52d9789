//! Measurement-unit mix-ups (`measurement_units`): the measurements were recorded in other
//! units than `measurements.csv` states. Each mix-up is a constant factor on one column:
//!
//! * attenuation in dB/m entered as Np/m: the recorded numbers are 20/ln 10 = 8.686 times the
//!   true ones (1 Np = 8.686 dB), and its reverse;
//! * ω entered as f (the frequency column holds rad/s): the recorded frequency is 2π times the
//!   true one, and its reverse (f entered as ω).
//!
//! A mix-up is tested like an inventory record: the converted data are refitted and the refit
//! must pass the same likelihood-ratio, AICc and held-out tests, with the number of mix-ups
//! tried in the level. It is a discrepancy in the stored measurements, reported with its
//! factor: the stored measurements are never changed by the diagnosis (the user re-imports a
//! corrected file, or confirms the conversion explicitly, [`convert_measurements`]).

use rusqlite::{params, Connection};

use crate::invert::problem::SegmentData;

/// Decibels per neper: 20/ln 10.
pub const DB_PER_NEPER: f64 = 8.685_889_638_065_037;

/// One unit mix-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum UnitMixUp {
    /// The attenuation (and its standard deviation) was recorded in dB/m.
    AttenuationInDb,
    /// The attenuation was converted from Np/m to dB/m twice over: recorded 1/8.686 of the truth.
    AttenuationDividedByDb,
    /// The frequency column holds ω (rad/s): recorded 2π times the true frequency.
    OmegaAsFrequency,
    /// The ω column holds f (Hz): recorded 1/2π of the true angular frequency.
    FrequencyAsOmega,
}

impl UnitMixUp {
    /// Every mix-up tried.
    pub const ALL: [UnitMixUp; 4] = [
        UnitMixUp::AttenuationInDb,
        UnitMixUp::AttenuationDividedByDb,
        UnitMixUp::OmegaAsFrequency,
        UnitMixUp::FrequencyAsOmega,
    ];

    /// The factor recorded / true.
    pub fn factor(self) -> f64 {
        match self {
            UnitMixUp::AttenuationInDb => DB_PER_NEPER,
            UnitMixUp::AttenuationDividedByDb => 1.0 / DB_PER_NEPER,
            UnitMixUp::OmegaAsFrequency => std::f64::consts::TAU,
            UnitMixUp::FrequencyAsOmega => 1.0 / std::f64::consts::TAU,
        }
    }

    /// The column the factor is on.
    pub fn column(self) -> &'static str {
        match self {
            UnitMixUp::AttenuationInDb | UnitMixUp::AttenuationDividedByDb => {
                "attenuation_np_per_m"
            }
            UnitMixUp::OmegaAsFrequency | UnitMixUp::FrequencyAsOmega => "frequency",
        }
    }

    /// Plain words, e.g. `attenuation recorded in dB/m, not Np/m`.
    pub fn describe(self) -> &'static str {
        match self {
            UnitMixUp::AttenuationInDb => "attenuation recorded in dB/m, not Np/m",
            UnitMixUp::AttenuationDividedByDb => {
                "attenuation divided by 8.686 once too often (Np/m converted as if dB/m)"
            }
            UnitMixUp::OmegaAsFrequency => "frequency recorded as omega (rad/s), not Hz",
            UnitMixUp::FrequencyAsOmega => "omega recorded as the frequency in Hz, not rad/s",
        }
    }

    /// The value of the `effect_value` column: the mix-up and its factor.
    pub fn label(self) -> String {
        format!(
            "{} (recorded = {} x true)",
            self.describe(),
            crate::units::sig(self.factor(), 4)
        )
    }

    /// The name used on the command line (`diagnose --convert-units ID=NAME`).
    pub fn code(self) -> &'static str {
        match self {
            UnitMixUp::AttenuationInDb => "attenuation_db",
            UnitMixUp::AttenuationDividedByDb => "attenuation_over_db",
            UnitMixUp::OmegaAsFrequency => "omega_as_hz",
            UnitMixUp::FrequencyAsOmega => "hz_as_omega",
        }
    }

    /// The data as they would be with the mix-up undone (standard deviations converted with
    /// their values).
    pub fn corrected(self, data: &SegmentData) -> SegmentData {
        let mut d = data.clone();
        let k = self.factor();
        for m in &mut d.measurements {
            match self {
                UnitMixUp::AttenuationInDb | UnitMixUp::AttenuationDividedByDb => {
                    m.attenuation /= k;
                    m.attenuation_std = m.attenuation_std.map(|s| s / k);
                }
                UnitMixUp::OmegaAsFrequency | UnitMixUp::FrequencyAsOmega => m.omega /= k,
            }
        }
        d
    }
}

impl std::str::FromStr for UnitMixUp {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        UnitMixUp::ALL
            .into_iter()
            .find(|u| u.code() == s.trim())
            .ok_or_else(|| {
                format!(
                    "unknown unit mix-up {s:?}: expected one of {}",
                    UnitMixUp::ALL.map(|u| u.code()).join(", ")
                )
            })
    }
}

/// Undo a unit mix-up in the stored measurements of one segment, on the user's explicit
/// request: the attenuation and its standard deviation divided by the factor, or the
/// frequency (Hz and rad/s columns alike) divided by it, in one transaction. The segment's
/// inputs hash is recomputed, so the next `calibrate` refits it. Returns the number of
/// measurement rows changed.
pub fn convert_measurements(
    conn: &mut Connection,
    segment_id: &str,
    mix: UnitMixUp,
) -> Result<usize, crate::db::DbError> {
    let k = mix.factor();
    let tx = conn.transaction()?;
    let n = match mix {
        UnitMixUp::AttenuationInDb | UnitMixUp::AttenuationDividedByDb => tx.execute(
            "UPDATE measurements SET attenuation_np_per_m = attenuation_np_per_m / ?1, \
             attenuation_std = attenuation_std / ?1 WHERE segment_id = ?2",
            params![k, segment_id],
        )?,
        UnitMixUp::OmegaAsFrequency | UnitMixUp::FrequencyAsOmega => tx.execute(
            "UPDATE measurements SET frequency_hz = frequency_hz / ?1, \
             omega_rad_s = omega_rad_s / ?1 WHERE segment_id = ?2",
            params![k, segment_id],
        )?,
    };
    crate::db::refresh_inputs_hash(&tx, segment_id)?;
    tx.commit()?;
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_and_codes() {
        assert!((UnitMixUp::AttenuationInDb.factor() - 20.0 / 10f64.ln()).abs() < 1e-12);
        for u in UnitMixUp::ALL {
            assert_eq!(u.code().parse::<UnitMixUp>(), Ok(u));
        }
        assert!("dB".parse::<UnitMixUp>().is_err());
        assert_eq!(
            UnitMixUp::AttenuationInDb.label(),
            "attenuation recorded in dB/m, not Np/m (recorded = 8.686 x true)"
        );
    }
}
