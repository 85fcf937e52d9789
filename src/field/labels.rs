//! Labels are evidence, not truth (model §7.12): a geological map's unit is wrong for some
//! pipes, but units are contiguous and mistakes isolated. Each segment's class is its own label
//! unless a strict majority of its [`LABEL_VOTERS`] nearest segments (itself included) carry
//! another one; the segment is then reported as one whose label its neighbourhood rejects.
//! A segment without a label takes its neighbourhood's majority when there is one.

use super::model::index_of;

/// Segments whose labels vote on a segment's class: itself and its 8 nearest (the prototype of
/// §7.12 that recovered most of the loss to 10 % wrong labels).
pub const LABEL_VOTERS: usize = 9;

/// Votes another label needs to overrule a segment's own: a strict majority of the voters.
pub const REJECTING_VOTES: usize = LABEL_VOTERS / 2 + 1;

/// The class of each segment and whether its own label was rejected. `labels[i]` is segment
/// i's label (an index, `None` when it has none), `pos[i]` its midpoint.
pub fn smooth(labels: &[Option<usize>], pos: &[Option<[f64; 2]>]) -> Vec<(Option<usize>, bool)> {
    let tree = index_of(pos.iter().copied());
    labels
        .iter()
        .zip(pos)
        .map(|(&own, p)| {
            let Some(p) = p else {
                return (own, false);
            };
            let mut votes: Vec<(usize, usize)> = Vec::new();
            for g in tree.nearest_neighbor_iter(p).take(LABEL_VOTERS) {
                if let Some(l) = labels[g.data as usize] {
                    match votes.iter_mut().find(|v| v.0 == l) {
                        Some(v) => v.1 += 1,
                        None => votes.push((l, 1)),
                    }
                }
            }
            // The most voted label (ties: the smaller index, so the answer is one order).
            let best = votes
                .iter()
                .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
                .copied();
            match (own, best) {
                (Some(o), Some((b, n))) if b != o && n >= REJECTING_VOTES => (Some(b), true),
                (None, Some((b, _))) => (Some(b), false),
                _ => (own, false),
            }
        })
        .collect()
}

/// The classes of [`smooth`] with the engineer's overrides applied: a segment whose class is
/// `forced` (the inventory's `soil_class_override`, given as its label `own`) keeps that class
/// and is never reported as rejected, whatever its neighbours carry.
pub fn with_overrides(
    smoothed: Vec<(Option<usize>, bool)>,
    own: &[Option<usize>],
    forced: &[bool],
) -> Vec<(Option<usize>, bool)> {
    smoothed
        .into_iter()
        .zip(own.iter().zip(forced))
        .map(|(c, (&o, &f))| if f { (o, false) } else { c })
        .collect()
}

/// Bounds of the label error rate used by [`class_probabilities`]: at least one label in a
/// hundred is taken as possibly wrong, at most three in ten.
pub const LABEL_ERROR_RANGE: (f64, f64) = (0.01, 0.3);

/// Each segment's probabilities of its true class (model §7.12: labels are evidence), from the
/// labels of its [`LABEL_VOTERS`] nearest segments (itself included) read as independent noisy
/// reports of one true class: P(k) ∝ Π_j [(1 − ε) if label_j = k, else ε/(K − 1)], with ε the
/// network's label error rate. Deep inside a unit a lone wrong label leaves its class almost
/// certain (each agreeing vote is worth a factor (1 − ε)(K − 1)/ε); a segment whose
/// neighbourhood is split keeps a share for each class. Classes under `min_share` are dropped
/// and the rest renormalised; a segment without a position or voters gets `fallback` (its
/// class) with probability 1.
pub fn class_probabilities(
    labels: &[Option<usize>],
    pos: &[Option<[f64; 2]>],
    fallback: &[usize],
    n_classes: usize,
    error_rate: f64,
    min_share: f64,
) -> Vec<Vec<(usize, f64)>> {
    let tree = index_of(pos.iter().copied());
    let eps = error_rate.clamp(LABEL_ERROR_RANGE.0, LABEL_ERROR_RANGE.1);
    let k = n_classes.max(2) as f64;
    let (agree, disagree) = ((1.0 - eps).ln(), (eps / (k - 1.0)).ln());
    pos.iter()
        .zip(fallback)
        .map(|(p, &own)| {
            let Some(p) = p else {
                return vec![(own, 1.0)];
            };
            let votes: Vec<usize> = tree
                .nearest_neighbor_iter(p)
                .take(LABEL_VOTERS)
                .filter_map(|g| labels[g.data as usize])
                .collect();
            if votes.is_empty() {
                return vec![(own, 1.0)];
            }
            let mut cands: Vec<usize> = votes.clone();
            cands.push(own);
            cands.sort_unstable();
            cands.dedup();
            let logp: Vec<f64> = cands
                .iter()
                .map(|&c| {
                    votes
                        .iter()
                        .map(|&v| if v == c { agree } else { disagree })
                        .sum()
                })
                .collect();
            let top = logp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let w: Vec<f64> = logp.iter().map(|l| (l - top).exp()).collect();
            let total: f64 = w.iter().sum();
            let mut out: Vec<(usize, f64)> = cands
                .iter()
                .zip(&w)
                .map(|(&c, &x)| (c, x / total))
                .filter(|&(c, x)| x >= min_share || c == own)
                .collect();
            let kept: f64 = out.iter().map(|x| x.1).sum();
            for x in &mut out {
                x.1 /= kept;
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of 30 segments, two units of 15; one wrong label inside each unit is rejected
    /// and given its unit's class, the boundary is kept, an unlabelled segment takes its
    /// unit's label.
    #[test]
    fn isolated_wrong_labels_are_rejected_and_boundaries_kept() {
        let pos: Vec<Option<[f64; 2]>> = (0..30).map(|i| Some([i as f64 * 50.0, 0.0])).collect();
        let mut labels: Vec<Option<usize>> = (0..30).map(|i| Some(usize::from(i >= 15))).collect();
        labels[5] = Some(1);
        labels[24] = Some(0);
        labels[10] = None;
        let out = smooth(&labels, &pos);
        assert_eq!(out[5], (Some(0), true));
        assert_eq!(out[24], (Some(1), true));
        assert_eq!(out[10], (Some(0), false));
        assert_eq!(out[14], (Some(0), false));
        assert_eq!(out[15], (Some(1), false));
        let rejected = out.iter().filter(|o| o.1).count();
        assert_eq!(rejected, 2);
    }

    /// An override keeps its class inside a unit of the other class (where its label alone
    /// would be rejected) and is not reported; the others are unchanged.
    #[test]
    fn an_overridden_class_is_kept_and_not_reported() {
        let pos: Vec<Option<[f64; 2]>> = (0..30).map(|i| Some([i as f64 * 50.0, 0.0])).collect();
        let mut labels: Vec<Option<usize>> = (0..30).map(|i| Some(usize::from(i >= 15))).collect();
        labels[5] = Some(1);
        labels[24] = Some(0);
        let mut forced = vec![false; 30];
        forced[5] = true;
        let out = with_overrides(smooth(&labels, &pos), &labels, &forced);
        assert_eq!(out[5], (Some(1), false));
        assert_eq!(out[24], (Some(1), true));
        assert_eq!(out[4], (Some(0), false));
    }

    /// Class probabilities: a lone wrong label deep inside a unit leaves the class certain; a
    /// segment at the boundary of two units keeps a share of each, as the independent-report
    /// model gives: 5 votes against 4 with ε = 0.1, K = 2 is a ratio of 9¹ = 9, i.e. 0.9/0.1.
    #[test]
    fn class_probabilities_follow_the_votes() {
        let pos: Vec<Option<[f64; 2]>> = (0..30).map(|i| Some([i as f64 * 50.0, 0.0])).collect();
        let mut labels: Vec<Option<usize>> = (0..30).map(|i| Some(usize::from(i >= 15))).collect();
        labels[5] = Some(1);
        let fallback: Vec<usize> = smooth(&labels, &pos).iter().map(|c| c.0.unwrap()).collect();
        let p = class_probabilities(&labels, &pos, &fallback, 2, 0.1, 1e-3);
        // Segment 5: 8 votes for class 0, 1 for class 1: ratio 9⁷, class 1 below 1e-3 kept as
        // the segment's own class only if it is the fallback (it is not).
        assert_eq!(p[5].len(), 1);
        assert_eq!(p[5][0].0, 0);
        // Segment 14 (the last of unit 0): its 9 nearest are 10..=18, 5 of class 0, 4 of 1.
        let p14 = &p[14];
        let share0 = p14.iter().find(|x| x.0 == 0).unwrap().1;
        assert!((share0 - 0.9).abs() < 1e-9, "{p14:?}");
    }
}
