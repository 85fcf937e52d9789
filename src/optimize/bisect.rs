//! Bisection of a monotone crossing on an interval.

/// The bracket `(lo, hi)` of the crossing of a monotone predicate on `[lo, hi]` after `steps`
/// halvings: `below(x)` is true for x below the crossing and false above it (so `below(lo)` is
/// taken as true and `below(hi)` as false without being asked). Each step halves the bracket;
/// the caller chooses which end, or the midpoint, it needs (the end on a given side keeps the
/// predicate's value there).
pub fn bisect(
    mut lo: f64,
    mut hi: f64,
    steps: usize,
    mut below: impl FnMut(f64) -> bool,
) -> (f64, f64) {
    for _ in 0..steps {
        let mid = 0.5 * (lo + hi);
        if below(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// √2 as the crossing of x² < 2 on [0, 2]: 60 halvings bracket it to adjacent doubles
    /// (2⁻⁶⁰·2 is below their spacing near √2), with √2 inside and each end on its own side.
    #[test]
    fn brackets_a_crossing_on_its_own_sides() {
        let (lo, hi) = bisect(0.0, 2.0, 60, |x| x * x < 2.0);
        let root = 2f64.sqrt();
        assert!(lo <= root && root <= hi, "{lo} {hi}");
        assert!(hi - lo <= f64::EPSILON, "{}", hi - lo);
        assert!(lo * lo < 2.0 && hi * hi >= 2.0);
        // No step: the bracket as given.
        assert_eq!(bisect(0.0, 2.0, 0, |_| unreachable!()), (0.0, 2.0));
    }
}
