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
}
