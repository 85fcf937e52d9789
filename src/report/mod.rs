//! Reports: self-contained HTML pages with inline SVG plots.
//!
//! - [`audit`]: fit quality across the network (`pipewave audit`).
//! - [`svg`]: the small SVG pieces plotters does not draw well for us (the network map, whose
//!   segments are grouped by colour class into one path each, and inline bars), and escaping.
//! - [`charts`]: the XY charts, drawn with `plotters`' SVG backend.

pub mod audit;
pub mod charts;
pub mod field;
pub mod svg;
pub mod zones;

/// Linear-interpolated quantile `q` in [0, 1] of sorted finite values (type 7, as R's default
/// and numpy's `linear`). `None` for an empty slice.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let i = pos.floor() as usize;
    let frac = pos - i as f64;
    let next = sorted.get(i + 1).copied().unwrap_or(sorted[i]);
    Some(sorted[i] + frac * (next - sorted[i]))
}

/// The finite values, sorted.
pub fn sorted_finite(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_linearly() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.5), Some(3.0));
        assert_eq!(quantile(&v, 0.9), Some(4.6));
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 1.0), Some(5.0));
        assert_eq!(quantile(&[7.0], 0.9), Some(7.0));
        assert_eq!(quantile(&[], 0.5), None);
        assert_eq!(
            sorted_finite([3.0, f64::NAN, 1.0].into_iter()),
            vec![1.0, 3.0]
        );
    }
}
