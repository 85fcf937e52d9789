//! Effects the data cannot tell apart: why (the physical quantity both change) and
//! which measurement would separate them (a frequency band where the two fitted models'
//! predictions differ by more than the noise, or a field test).

use num_complex::Complex64;

use crate::invert::problem::{predict, SegmentData};
use crate::invert::FitResult;
use crate::physics::effects::Effect;

/// Two fitted models are told apart at a frequency where their predictions of Re k or of the
/// attenuation differ by more than this many standard deviations of a measurement there.
pub const SEPARATION_SIGMAS: f64 = 2.0;
/// The frequency grid searched for a separating band: from this fraction of the lowest
/// measured frequency …
pub const BAND_LOW_FACTOR: f64 = 0.5;
/// … to this multiple of the highest (capped at 0.45 of the ring frequency, the model's
/// validity, model §3.2) …
pub const BAND_HIGH_FACTOR: f64 = 2.0;
/// … on this many log-spaced points.
pub const BAND_POINTS: usize = 40;

/// One effect the data cannot tell apart from the named one.
#[derive(Debug, Clone, PartialEq)]
pub struct Ambiguity {
    /// The other effect.
    pub effect: Effect,
    /// The physical quantity both change.
    pub quantity: &'static str,
    /// The measurement that would separate them.
    pub separating: String,
}

/// What two effects without a known shared quantity both change.
pub const GENERIC_QUANTITY: &str =
    "the same change of the fitted wavenumbers over the measured band";

/// The physical quantity two effects both change (model §8 signatures).
pub fn shared_quantity(a: Effect, b: Effect) -> &'static str {
    use Effect::*;
    let pair = if a <= b { (a, b) } else { (b, a) };
    match pair {
        (AirInWater, WallThinning) => {
            "compliance of the water-filled pipe: both lower the wave speed uniformly (Korteweg)"
        }
        (SoilDamping, PipeLoss) => "loss: both raise the attenuation roughly in proportion to f",
        (PipeLoss, ViscoelasticWall) => "wall loss: both set the wall's loss factor",
        (WallThinning, InventoryError) => {
            "wall stiffness E_p·h: a thinner wall class and a thinned wall are the same pipe"
        }
        (WallThinning, ViscoelasticWall) => "wall stiffness: both change E_p·h",
        (AirInWater, InventoryError) => {
            "compliance: a softer pipe record and air both slow the wave"
        }
        (SoilDamping, ViscoelasticWall) => "loss rising with frequency",
        (PipeLoss, InventoryError) => {
            "wall loss: another wall class or material has another stiffness and loss factor"
        }
        (ViscoelasticWall, InventoryError) => {
            "wall stiffness and loss: a thicker wall class or a stiffer material and a modulus \
             rising with frequency both speed the wave up"
        }
        _ => GENERIC_QUANTITY,
    }
}

/// True when two effects change the same physical quantity (a pair of [`shared_quantity`]).
pub fn same_quantity(a: Effect, b: Effect) -> bool {
    a != b && shared_quantity(a, b) != GENERIC_QUANTITY
}

/// A field test that measures the effect directly.
pub fn field_test(e: Effect) -> &'static str {
    match e {
        Effect::AirInWater => "a pressure-transient test (air shows as a slow, damped wave)",
        Effect::WallThinning => "an ultrasonic wall-thickness gauge on an excavated section",
        Effect::PipeLoss => {
            "a wall-loss measurement on a pipe sample (or a pipe of the same batch)"
        }
        Effect::SoilDamping => "a resonant-column or bender-element test of a soil sample",
        Effect::ViscoelasticWall => "a dynamic modulus test of a pipe sample (DMA over frequency)",
        Effect::InventoryError => {
            "a trial hole to read the pipe's markings and measure its diameter"
        }
        Effect::FullModel => "none needed: the full model is the default",
        Effect::MeasurementUnits => {
            "the units of the measurement export (or the field sheet) checked at its source"
        }
    }
}

/// Where the predictions of two fitted models differ by more than [`SEPARATION_SIGMAS`] of
/// the noise: the lowest and highest such frequency (Hz) on the searched grid, or `None`.
/// The noise at a frequency is the data's median relative standard deviation times the
/// predicted value (each fit carries its own system, so an inventory candidate's pipe is used).
pub fn separating_band(
    data: &SegmentData,
    fit_a: &FitResult,
    fit_b: &FitResult,
) -> Option<(f64, f64)> {
    let (sa, sb) = (fit_a.system?, fit_b.system?);
    let ms = &data.measurements;
    if ms.is_empty() {
        return None;
    }
    let median = |mut v: Vec<f64>| -> f64 {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let r_re = median(
        ms.iter()
            .map(|m| m.k_re_std.unwrap_or(f64::NAN) / m.k_re)
            .collect(),
    );
    let r_att = median(
        ms.iter()
            .map(|m| m.attenuation_std.unwrap_or(f64::NAN) / m.attenuation.max(1e-12))
            .collect(),
    );
    let f_lo = ms.iter().map(|m| m.omega).fold(f64::INFINITY, f64::min) / std::f64::consts::TAU
        * BAND_LOW_FACTOR;
    let ring = sa.pipe.ring_frequency_hz().min(sb.pipe.ring_frequency_hz());
    let f_hi = (ms.iter().map(|m| m.omega).fold(0.0, f64::max) / std::f64::consts::TAU
        * BAND_HIGH_FACTOR)
        .min(0.45 * ring);
    if f_hi.partial_cmp(&f_lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let freqs: Vec<f64> = (0..BAND_POINTS)
        .map(|i| f_lo * (f_hi / f_lo).powf(i as f64 / (BAND_POINTS - 1) as f64))
        .collect();
    let omegas: Vec<f64> = freqs.iter().map(|f| f * std::f64::consts::TAU).collect();
    let (ka, kb): (Vec<Complex64>, Vec<Complex64>) =
        (predict(&sa, &omegas)?, predict(&sb, &omegas)?);
    let apart: Vec<f64> = freqs
        .iter()
        .zip(ka.iter().zip(&kb))
        .filter(|(_, (a, b))| {
            let d_re = (a.re - b.re).abs() / (r_re * a.re.abs());
            let d_att = (a.im - b.im).abs() / (r_att * a.im.abs().max(1e-12));
            d_re > SEPARATION_SIGMAS || d_att > SEPARATION_SIGMAS
        })
        .map(|(f, _)| *f)
        .collect();
    Some((*apart.first()?, *apart.last()?))
}

/// The description of an ambiguity between the named effect and `other`.
pub fn describe(named: Effect, other: Effect, band: Option<(f64, f64)>) -> Ambiguity {
    let separating = match band {
        Some((lo, hi)) => format!(
            "measure at {}-{} Hz, where the two fitted models differ by more than {} sigma; or {} / {}",
            crate::units::sig(lo, 3),
            crate::units::sig(hi, 3),
            SEPARATION_SIGMAS,
            field_test(named),
            field_test(other)
        ),
        None => format!(
            "no frequency separates them at this noise; {} / {}",
            field_test(named),
            field_test(other)
        ),
    };
    Ambiguity {
        effect: other,
        quantity: shared_quantity(named, other),
        separating,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_name_the_shared_quantity_in_either_order() {
        for (a, b, word) in [
            (Effect::AirInWater, Effect::WallThinning, "compliance"),
            (Effect::PipeLoss, Effect::SoilDamping, "loss"),
        ] {
            assert!(shared_quantity(a, b).starts_with(word));
            assert_eq!(shared_quantity(a, b), shared_quantity(b, a));
        }
        let d = describe(Effect::AirInWater, Effect::WallThinning, None);
        assert!(d.separating.contains("pressure-transient") && d.separating.contains("ultrasonic"));
        let d = describe(
            Effect::AirInWater,
            Effect::WallThinning,
            Some((800.0, 1500.0)),
        );
        assert!(
            d.separating.starts_with("measure at 800-1500 Hz"),
            "{}",
            d.separating
        );
    }
}
