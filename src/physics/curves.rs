//! Wave-speed and attenuation curves over a frequency grid (model §2, P2): the form every later part
//! stores and exports.

use super::inputs::System;
use super::solver::{solve_curve, Continuation, RootFlags, SolveError};
use crate::units::{hz_to_omega, np_to_db};

/// The standard frequency grid of stored curves, Hz: 10–2000 Hz, dense over the leak-noise band
/// 100–800 Hz, and containing the export frequencies 100, 200, 500 and 1000 Hz.
pub const STANDARD_GRID_HZ: [f64; 32] = [
    10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 125.0, 150.0, 175.0, 200.0, 250.0, 300.0,
    350.0, 400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0, 750.0, 800.0, 900.0, 1000.0, 1200.0,
    1400.0, 1500.0, 1600.0, 1800.0, 2000.0,
];

/// The typical leak-noise band a correlator operator uses, Hz. Its mean speed is
/// [`band_mean`].
pub const LEAK_BAND_HZ: (f64, f64) = (100.0, 800.0);

/// One point of a curve.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvePoint {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Phase speed ω/Re k1, m/s (NaN when the root was not found).
    pub phase_speed: f64,
    /// Attenuation −(20/ln 10)·Im k1, dB/m (NaN when the root was not found).
    pub attenuation_db: f64,
    /// The root's warnings, or why it was not found.
    pub status: Result<RootFlags, SolveError>,
}

/// Phase speed and attenuation at the given frequencies (Hz), by continuation (P41–P43).
pub fn curve(system: &System, frequencies_hz: &[f64]) -> Vec<CurvePoint> {
    let omegas: Vec<f64> = frequencies_hz.iter().map(|&f| hz_to_omega(f)).collect();
    solve_curve(system, &omegas, Continuation::default())
        .into_iter()
        .zip(frequencies_hz)
        .map(|(r, &f)| match r {
            Ok(root) => CurvePoint {
                frequency_hz: f,
                phase_speed: root.phase_speed(),
                attenuation_db: np_to_db(root.attenuation_np()),
                status: Ok(root.flags),
            },
            Err(e) => CurvePoint {
                frequency_hz: f,
                phase_speed: f64::NAN,
                attenuation_db: f64::NAN,
                status: Err(e),
            },
        })
        .collect()
}

/// Mean of a curve over a band: (1/(f₂ − f₁)) ∫ v(f) df by the trapezoidal rule over the points
/// `(f, v)` (increasing f) with f₁ ≤ f ≤ f₂. On the standard grid the leak band 100–800 Hz holds
/// 17 points (25–50 Hz apart), on which the speed varies smoothly, so this differs from a dense
/// quadrature by far less than the fit's own uncertainty.
///
/// `None` unless the points cover the whole band (a point at each end, to 1e-9 relative) and
/// every point in it has a value: a mean over part of the band would be a different figure
/// under the same name. The one exception is a wave that ends inside the band, whose band is
/// [`carried_band`]; whoever takes that mean says so.
pub fn band_mean(points: &[(f64, Option<f64>)], band_hz: (f64, f64)) -> Option<f64> {
    const REL_TOL: f64 = 1e-9;
    let (lo, hi) = band_hz;
    let tol = |f: f64| REL_TOL * f.abs();
    let pts: Vec<&(f64, Option<f64>)> = points
        .iter()
        .filter(|p| p.0 >= lo - tol(lo) && p.0 <= hi + tol(hi))
        .collect();
    let (first, last) = (pts.first()?, pts.last()?);
    if pts.len() < 2 || (first.0 - lo).abs() > tol(lo) || (last.0 - hi).abs() > tol(hi) {
        return None;
    }
    let mut integral = 0.0;
    for w in pts.windows(2) {
        let c0 = w[0].1.filter(|v| v.is_finite())?;
        let c1 = w[1].1.filter(|v| v.is_finite())?;
        integral += 0.5 * (c0 + c1) * (w[1].0 - w[0].0);
    }
    Some(integral / (last.0 - first.0))
}

/// The part of `band_hz` over which a wave is carried (model §7.12, P81): from the band's low
/// end up to the last of the frequencies `carried` (ascending, each with whether the wave is
/// found there; those outside the band are ignored) before the first where it is not. Above
/// that frequency the wave is damped beyond measurement and its root is lost, so no correlator
/// hears it there. The whole band when the wave is carried at every frequency, and also when
/// at fewer than two, or not at the low end: [`band_mean`] is then left to say `None` rather
/// than average a stub.
pub fn carried_band(carried: &[(f64, bool)], band_hz: (f64, f64)) -> (f64, f64) {
    let inside: Vec<(f64, bool)> = carried
        .iter()
        .copied()
        .filter(|&(f, _)| f >= band_hz.0 && f <= band_hz.1)
        .collect();
    let n = inside.iter().take_while(|p| p.1).count();
    if n == inside.len() || n < 2 || inside[0].0 != band_hz.0 {
        band_hz
    } else {
        (band_hz.0, inside[n - 1].0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The band is cut at the last frequency before the wave is lost, and kept whole when the
    /// wave is carried throughout, lost at the low end, or carried at only one frequency.
    #[test]
    fn a_band_is_cut_where_the_wave_is_lost() {
        let at = |lost_from: f64| -> Vec<(f64, bool)> {
            [50.0, 100.0, 200.0, 350.0, 500.0, 650.0, 800.0, 900.0]
                .iter()
                .map(|&f| (f, f < lost_from))
                .collect()
        };
        assert_eq!(carried_band(&at(650.0), LEAK_BAND_HZ), (100.0, 500.0));
        assert_eq!(carried_band(&at(800.0), LEAK_BAND_HZ), (100.0, 650.0));
        // Lost only above the band: the whole band.
        assert_eq!(carried_band(&at(900.0), LEAK_BAND_HZ), LEAK_BAND_HZ);
        // Carried at 100 Hz alone, or lost below the band's low end: no stub, the whole band.
        assert_eq!(carried_band(&at(200.0), LEAK_BAND_HZ), LEAK_BAND_HZ);
        assert_eq!(carried_band(&at(80.0), LEAK_BAND_HZ), LEAK_BAND_HZ);
        // A gap below a carried stretch cuts at the gap.
        let gap = [
            (100.0, true),
            (200.0, true),
            (350.0, false),
            (500.0, true),
            (800.0, true),
        ];
        assert_eq!(carried_band(&gap, LEAK_BAND_HZ), (100.0, 200.0));
    }
}
