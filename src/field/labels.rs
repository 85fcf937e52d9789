//! Labels are evidence, not truth (model §7.12): a geological map's unit is wrong for some
//! pipes, but units are contiguous patches and the mistakes are isolated. Each segment's true
//! class c_i is inferred jointly with its neighbours' under two pieces of evidence:
//!
//! * **its own label**, a report of c_i that is wrong with the network's rate ε:
//!   L_i(k) = 1 − ε if the label is k, else ε / (K − 1) (uniform without a label);
//! * **contiguity**: neighbouring pipes lie in the same unit unless a boundary passes between
//!   them, a Potts prior P(c) ∝ exp(J Σ_{i~j} [c_i = c_j]) over each segment and its
//!   `LABEL_VOTERS − 1` nearest others.
//!
//! The posterior is found by mean field, q_i(k) ∝ L_i(k) exp(J Σ_{j ∈ N(i)} q_j(k)), damped
//! and iterated a fixed number of sweeps (deterministic, one order). The neighbours' labels
//! thus enter through their own posteriors, so a label wrong with its neighbour is not a
//! pocket, while on a unit boundary, where the neighbours are split, the own label decides
//! and the other side keeps its share. A segment is reported as one whose label its
//! neighbourhood rejects when its likeliest class is not its label. ε is the network's own:
//! the expectation–maximisation estimate, the mean over the labelled segments of
//! 1 − q_i(label_i).
//!
//! Contiguity is a property of a geological map, not of every inventory: labels from per-pipe
//! records or scattered trial pits need not agree with their neighbours at all. It is
//! therefore checked on the labels first. Where they disagree with their neighbours more often
//! than contiguity at the largest label error rate explains, and their join count (the number
//! of neighbour pairs with the same label) is no larger than with the labels permuted among the
//! labelled segments (which keeps each class's share and breaks any spatial pattern; p ≥ 0.01),
//! the map carries no contiguity to use: each label is taken as given, none is rejected, and ε,
//! which only the disagreement with contiguous neighbours identifies, is not estimated.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::model::index_of;

/// Segments of a neighbourhood: a segment and its 8 nearest (the prototype of §7.12 that
/// recovered most of the loss to 10 % wrong labels).
pub const LABEL_VOTERS: usize = 9;

/// Potts coupling J per neighbour pair. Its range follows from two cases, with a label
/// error worth ln((1 − ε)(K − 1)/ε) ≈ 2.9 (ε = 0.1, K = 3): two adjacent wrong labels inside a
/// unit must cost more as a pocket (about 14 discordant pairs, 14 J) than as two label errors
/// (5.8), so J > 0.41; a right label on a boundary with 3 of its 8 neighbours on its side must
/// be kept (2 J below 2.9), so J < 1.45. Within it, 1.2: a lone wrong label's own class then
/// keeps a share of about 18 e^(−8J) ≈ 1e-3, below the mixture's 1 % floor, so it does not
/// pull the prediction towards the wrong class's mean (at J = 0.8 the share was about 3 %, and
/// the wrongly labelled pipes' predictions were 2–3 points worse on synthetic networks).
pub const POTTS_COUPLING: f64 = 1.2;

/// Bounds of the label error rate ε: at least one label in a hundred is taken as possibly
/// wrong, at most three in ten.
pub const LABEL_ERROR_RANGE: (f64, f64) = (0.01, 0.3);

/// Permutations of the labels in the contiguity test: the labels count as contiguous when
/// their join count exceeds that of every one of them (one-sided p < 0.01).
pub const CONTIGUITY_PERMUTATIONS: usize = 99;

/// The seed of the test's permutations (fixed: the same labels give the same answer).
const CONTIGUITY_SEED: u64 = 0x636f_6e74_6967;

/// Mean-field sweeps (each damped by a half; the posteriors change by less than 1e-6 after
/// about 20 on a network with 10 % wrong labels) and the ε updates between them.
const SWEEPS: usize = 40;
const ERROR_RATE_EVERY: usize = 4;

/// A segment's classes: its class probabilities (classes under `min_share` dropped, unless the
/// likeliest, and the rest renormalised), its likeliest class and whether that rejects its
/// own label. Empty probabilities and `None` when neither it nor its neighbours are labelled.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassBelief {
    pub probabilities: Vec<(usize, f64)>,
    pub class: Option<usize>,
    pub rejected: bool,
}

/// The own-label likelihood L_i(c) of class `c` for a label `own` among `k` classes.
fn likelihood(own: Option<usize>, k: usize, eps: f64, c: usize) -> f64 {
    match own {
        Some(o) if c == o => 1.0 - eps,
        Some(_) => eps / (k as f64 - 1.0),
        None => 1.0,
    }
}

/// The mean-field posteriors, one row of `k` values per segment in one flat array (segment
/// i's q_i is `q[i * k..(i + 1) * k]`): a network of 100,000 segments then holds two arrays
/// of 100,000 k values rather than 100,000 small vectors per sweep.
struct MeanField {
    q: Vec<f64>,
    k: usize,
    /// The label error rate; `None` when the labels are not contiguous.
    eps: Option<f64>,
}

impl MeanField {
    fn row(&self, i: usize) -> &[f64] {
        &self.q[i * self.k..(i + 1) * self.k]
    }
}

/// Each segment's `LABEL_VOTERS − 1` nearest others (none without a position), as one flat
/// list: segment i's are `hood[start[i]..start[i + 1]]`.
struct Hoods {
    start: Vec<usize>,
    hood: Vec<u32>,
}

impl Hoods {
    fn of(pos: &[Option<[f64; 2]>]) -> Hoods {
        let tree = index_of(pos.iter().copied());
        let mut start = Vec::with_capacity(pos.len() + 1);
        let mut hood = Vec::with_capacity(pos.len() * (LABEL_VOTERS - 1));
        start.push(0);
        for (i, p) in pos.iter().enumerate() {
            if let Some(p) = p {
                hood.extend(
                    tree.nearest_neighbor_iter(p)
                        .map(|g| g.data)
                        .filter(|&j| j as usize != i)
                        .take(LABEL_VOTERS - 1),
                );
            }
            start.push(hood.len());
        }
        Hoods { start, hood }
    }

    fn of_site(&self, i: usize) -> &[u32] {
        &self.hood[self.start[i]..self.start[i + 1]]
    }
}

/// The join count of `labels`: ordered pairs (i, j), j among i's neighbours, both labelled
/// with the same class.
fn join_count(labels: &[Option<usize>], hoods: &Hoods) -> usize {
    (0..labels.len())
        .filter_map(|i| labels[i].map(|l| (i, l)))
        .map(|(i, l)| {
            hoods
                .of_site(i)
                .iter()
                .filter(|&&j| labels[j as usize] == Some(l))
                .count()
        })
        .sum()
}

/// Whether the labels are contiguous among `k` classes. Contiguity is the map's prior and is
/// dropped only where the labels contradict it on both counts:
///
/// * they disagree with their neighbours more often than contiguity explains at the largest
///   label error rate ε_max of [`LABEL_ERROR_RANGE`]: inside a unit two labels disagree with
///   probability 1 − (1 − ε)² − ε²/(K − 1) (both right, or both wrong alike, agree); and
/// * their join count does not exceed that of each of [`CONTIGUITY_PERMUTATIONS`]
///   permutations of the labels among the labelled segments.
///
/// A map of one class with a few odd labels thus stays contiguous (its labels cannot tell),
/// and so does one with no two labelled neighbours.
fn labels_are_contiguous(labels: &[Option<usize>], hoods: &Hoods, k: usize) -> bool {
    let observed = join_count(labels, hoods);
    let labelled: Vec<usize> = (0..labels.len()).filter(|&i| labels[i].is_some()).collect();
    let pairs: usize = labelled
        .iter()
        .map(|&i| {
            hoods
                .of_site(i)
                .iter()
                .filter(|&&j| labels[j as usize].is_some())
                .count()
        })
        .sum();
    let eps = LABEL_ERROR_RANGE.1;
    let explained = 1.0 - (1.0 - eps).powi(2) - eps * eps / (k.max(2) - 1) as f64;
    if pairs == 0 || (pairs - observed) as f64 <= explained * pairs as f64 {
        return true;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(CONTIGUITY_SEED);
    let mut values: Vec<Option<usize>> = labelled.iter().map(|&i| labels[i]).collect();
    let mut permuted = labels.to_vec();
    (0..CONTIGUITY_PERMUTATIONS).all(|_| {
        values.shuffle(&mut rng);
        for (&i, &v) in labelled.iter().zip(&values) {
            permuted[i] = v;
        }
        join_count(&permuted, hoods) < observed
    })
}

/// The mean-field posteriors and the label error rate (arguments as for [`posteriors`]).
fn mean_field(
    labels: &[Option<usize>],
    forced: &[bool],
    pos: &[Option<[f64; 2]>],
    n_classes: usize,
) -> MeanField {
    let k = n_classes.max(2);
    let hoods = Hoods::of(pos);
    if labels_are_contiguous(labels, &hoods, k) {
        smoothed(labels, forced, &hoods, k)
    } else {
        // No contiguity to use: each label as given; an unlabelled segment has no class.
        let mut q = vec![0.0; labels.len() * k];
        for (i, l) in labels.iter().enumerate() {
            if let Some(c) = l {
                q[i * k + c] = 1.0;
            }
        }
        MeanField { q, k, eps: None }
    }
}

/// The mean field under the contiguity prior, `k` ≥ 2 classes.
fn smoothed(labels: &[Option<usize>], forced: &[bool], hoods: &Hoods, k: usize) -> MeanField {
    let n = labels.len();
    let mut eps = 0.1_f64;
    // Start from the labels alone; a segment without a label starts uniform.
    let mut w = vec![0.0; k];
    let mut q: Vec<f64> = Vec::with_capacity(n * k);
    for (&l, &f) in labels.iter().zip(forced) {
        match (l, f) {
            (Some(o), true) => q.extend((0..k).map(|c| f64::from(u8::from(c == o)))),
            _ => {
                for (c, x) in w.iter_mut().enumerate() {
                    *x = likelihood(l, k, eps, c);
                }
                let t: f64 = w.iter().sum();
                q.extend(w.iter().map(|x| x / t));
            }
        }
    }
    let is_labelled = |i: &usize| labels[*i].is_some() && !forced[*i];
    let n_labelled = (0..n).filter(is_labelled).count();
    let mut next = vec![0.0; n * k];
    let mut field = vec![0.0; k];
    for sweep in 0..SWEEPS {
        for (i, out) in next.chunks_exact_mut(k).enumerate() {
            let own = &q[i * k..(i + 1) * k];
            let hood = hoods.of_site(i);
            if hood.is_empty() || forced[i] {
                out.copy_from_slice(own);
                continue;
            }
            field.fill(0.0);
            for &j in hood {
                let j = j as usize;
                for (f, x) in field.iter_mut().zip(&q[j * k..(j + 1) * k]) {
                    *f += x;
                }
            }
            let top = field.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            for (c, (x, f)) in w.iter_mut().zip(&field).enumerate() {
                *x = likelihood(labels[i], k, eps, c) * (POTTS_COUPLING * (f - top)).exp();
            }
            let t: f64 = w.iter().sum();
            for ((o, x), b) in out.iter_mut().zip(&w).zip(own) {
                *o = 0.5 * (x / t + b);
            }
        }
        std::mem::swap(&mut q, &mut next);
        if (sweep + 1) % ERROR_RATE_EVERY == 0 && n_labelled > 0 {
            let wrong: f64 = (0..n)
                .filter(is_labelled)
                .map(|i| 1.0 - q[i * k + labels[i].expect("labelled")])
                .sum();
            eps = (wrong / n_labelled as f64).clamp(LABEL_ERROR_RANGE.0, LABEL_ERROR_RANGE.1);
        }
    }
    drop(next);
    // A segment without a position keeps its own label, certain; one without a label and
    // without labelled neighbours has no class.
    for (i, qi) in q.chunks_exact_mut(k).enumerate() {
        let hood = hoods.of_site(i);
        if labels[i].is_none() && hood.iter().all(|&j| labels[j as usize].is_none()) {
            qi.fill(0.0);
        } else if hood.is_empty() {
            for (c, x) in qi.iter_mut().enumerate() {
                *x = f64::from(u8::from(labels[i] == Some(c)));
            }
        }
    }
    MeanField {
        q,
        k,
        eps: Some(eps),
    }
}

/// The mean-field posteriors q_i (length `k`; all zero for a segment with no evidence at all)
/// and the label error rate (`None` when the labels are not contiguous). `labels[i]` is segment i's label (a class index, `None` when it
/// has none), `forced[i]` whether that label is the engineer's override (the class is then
/// certain, never rejected, and counts as a neighbour's evidence at full weight), `pos[i]` its
/// midpoint.
pub fn posteriors(
    labels: &[Option<usize>],
    forced: &[bool],
    pos: &[Option<[f64; 2]>],
    n_classes: usize,
) -> (Vec<Vec<f64>>, Option<f64>) {
    let m = mean_field(labels, forced, pos, n_classes);
    (m.q.chunks_exact(m.k).map(<[f64]>::to_vec).collect(), m.eps)
}

/// Every segment's [`ClassBelief`] and the network's label error rate, `None` when the labels
/// are not contiguous (arguments as for [`posteriors`]).
pub fn classes(
    labels: &[Option<usize>],
    forced: &[bool],
    pos: &[Option<[f64; 2]>],
    n_classes: usize,
    min_share: f64,
) -> (Vec<ClassBelief>, Option<f64>) {
    let m = mean_field(labels, forced, pos, n_classes);
    let beliefs = labels
        .iter()
        .enumerate()
        .map(|(i, &own)| {
            let qi = m.row(i);
            // The likeliest class (ties: the smaller index, so the answer is one order).
            let best = qi
                .iter()
                .copied()
                .enumerate()
                .filter(|x| x.1 > 0.0)
                .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
                .map(|x| x.0);
            // Sized to the classes kept (usually one): every segment keeps its list.
            let keep = |&(c, x): &(usize, f64)| x > 0.0 && (x >= min_share || Some(c) == best);
            let n_kept = qi.iter().copied().enumerate().filter(keep).count();
            let mut kept: Vec<(usize, f64)> = Vec::with_capacity(n_kept);
            kept.extend(qi.iter().copied().enumerate().filter(keep));
            let total: f64 = kept.iter().map(|x| x.1).sum();
            for x in &mut kept {
                x.1 /= total;
            }
            ClassBelief {
                probabilities: kept,
                class: best,
                rejected: matches!((own, best), (Some(o), Some(b)) if o != b),
            }
        })
        .collect();
    (beliefs, m.eps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of 30 segments 50 m apart, two units of 15: a lone wrong label and a pair of
    /// adjacent wrong labels are rejected and given their unit's class, the right labels on
    /// both sides of the boundary are kept (with a share of the other side), an unlabelled
    /// segment takes its unit's class.
    #[test]
    fn wrong_labels_are_rejected_and_boundaries_kept_on_a_row() {
        let pos: Vec<Option<[f64; 2]>> = (0..30).map(|i| Some([i as f64 * 50.0, 0.0])).collect();
        let mut labels: Vec<Option<usize>> = (0..30).map(|i| Some(usize::from(i >= 15))).collect();
        labels[6] = Some(1);
        labels[7] = Some(1);
        labels[24] = Some(0);
        labels[10] = None;
        let (b, _) = classes(&labels, &vec![false; labels.len()], &pos, 2, 1e-3);
        for i in [6, 7] {
            assert_eq!(
                (b[i].class, b[i].rejected),
                (Some(0), true),
                "{i}: {:?}",
                b[i]
            );
        }
        assert_eq!((b[24].class, b[24].rejected), (Some(1), true));
        assert_eq!((b[10].class, b[10].rejected), (Some(0), false));
        for i in [13, 14] {
            assert_eq!(
                (b[i].class, b[i].rejected),
                (Some(0), false),
                "{i}: {:?}",
                b[i]
            );
        }
        for i in [15, 16] {
            assert_eq!(
                (b[i].class, b[i].rejected),
                (Some(1), false),
                "{i}: {:?}",
                b[i]
            );
        }
        let rejected = b.iter().filter(|x| x.rejected).count();
        assert_eq!(rejected, 3);
        // The boundary pair is less certain than the interior.
        let share = |i: usize, c: usize| {
            b[i].probabilities
                .iter()
                .find(|x| x.0 == c)
                .map_or(0.0, |x| x.1)
        };
        assert!(share(14, 1) > 0.01 && share(14, 1) < 0.5, "{:?}", b[14]);
        assert!(share(2, 1) < share(14, 1), "{:?} {:?}", b[2], b[14]);
    }

    /// On a 30 × 30 grid of two units (a vertical boundary), 30 wrong labels (every 20th
    /// segment away from the boundary; some have a wrong neighbour within their 8 nearest):
    /// the estimated error rate is near their share, at least 90 % of them are rejected and
    /// given their unit's class, and no right label is rejected.
    #[test]
    fn an_overridden_class_is_kept_and_not_reported() {
        let pos: Vec<Option<[f64; 2]>> = (0..30).map(|i| Some([i as f64 * 50.0, 0.0])).collect();
        let mut labels: Vec<Option<usize>> = (0..30).map(|i| Some(usize::from(i >= 15))).collect();
        labels[5] = Some(1);
        labels[24] = Some(0);
        let mut forced = vec![false; 30];
        forced[5] = true;
        let (b, _) = classes(&labels, &forced, &pos, 2, 1e-3);
        assert_eq!((b[5].class, b[5].rejected), (Some(1), false));
        assert_eq!(b[5].probabilities, vec![(1, 1.0)]);
        assert_eq!((b[24].class, b[24].rejected), (Some(1), true));
        assert_eq!((b[2].class, b[2].rejected), (Some(0), false));
    }

    /// Midpoints of an n × n grid of segments 40 m apart, row by row (segment i in column
    /// i mod n).
    fn grid(n: usize) -> Vec<Option<[f64; 2]>> {
        (0..n * n)
            .map(|i| Some([(i % n) as f64 * 40.0, (i / n) as f64 * 40.0]))
            .collect()
    }

    #[test]
    fn wrong_labels_are_rejected_and_boundaries_kept_on_a_grid() {
        let n: usize = 30;
        let pos = grid(n);
        let truth: Vec<usize> = (0..n * n).map(|i| usize::from(i % n >= 13)).collect();
        let mut labels: Vec<Option<usize>> = truth.iter().map(|&t| Some(t)).collect();
        let wrong: Vec<usize> = (0..n * n)
            .step_by(20)
            .filter(|&i| (i % n).abs_diff(12) > 2)
            .collect();
        for &i in &wrong {
            labels[i] = Some(1 - truth[i]);
        }
        let share = wrong.len() as f64 / (n * n) as f64;
        let (beliefs, eps) = classes(&labels, &vec![false; labels.len()], &pos, 2, 0.01);
        let eps = eps.expect("contiguous labels");
        assert!(
            (0.5 * share..2.0 * share).contains(&eps),
            "ε {eps} for a wrong share {share}"
        );
        let fixed = wrong
            .iter()
            .filter(|&&i| beliefs[i].rejected && beliefs[i].class == Some(truth[i]))
            .count();
        assert!(fixed * 10 >= wrong.len() * 9, "{fixed} of {}", wrong.len());
        let right_rejected = (0..n * n)
            .filter(|i| !wrong.contains(i) && beliefs[*i].rejected)
            .count();
        assert_eq!(right_rejected, 0);
        // A right label on the boundary is kept, less certain than one inside its unit.
        assert_eq!(beliefs[12].class, Some(0));
        let (q, _) = posteriors(&labels, &vec![false; labels.len()], &pos, 2);
        assert!(
            q[12][1] > 10.0 * q[5 * n + 5][1],
            "{:?} {:?}",
            q[12],
            q[5 * n + 5]
        );
    }

    /// Labels drawn independently for each segment of a 20 × 20 grid (three classes, all
    /// right: a per-pipe survey, not a map): they agree with their neighbours no more than
    /// chance, so each is taken as given and none is rejected, where the contiguity prior
    /// would overrule more than a third of them. Labels in three bands by column are
    /// contiguous, and smoothed.
    #[test]
    fn labels_without_contiguity_are_taken_as_given() {
        let n: usize = 20;
        let pos = grid(n);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let labels: Vec<Option<usize>> = (0..n * n)
            .map(|_| Some(rand::Rng::gen_range(&mut rng, 0..3)))
            .collect();
        let forced = vec![false; labels.len()];
        let hoods = Hoods::of(&pos);
        assert!(!labels_are_contiguous(&labels, &hoods, 3));
        let (b, eps) = classes(&labels, &forced, &pos, 3, 0.01);
        assert_eq!(eps, None);
        assert!(b.iter().all(|x| !x.rejected));
        for (x, l) in b.iter().zip(&labels) {
            assert_eq!(x.class, *l);
            assert_eq!(x.probabilities, vec![(l.unwrap(), 1.0)]);
        }
        // What the contiguity prior alone would have done with them.
        let m = smoothed(&labels, &forced, &hoods, 3);
        let overruled = (0..n * n)
            .filter(|&i| {
                let q = m.row(i);
                (0..3).any(|c| q[c] > q[labels[i].unwrap()])
            })
            .count();
        assert!(overruled * 3 > n * n, "{overruled} of {}", n * n);
        let banded: Vec<Option<usize>> = (0..n * n).map(|i| Some(3 * (i % n) / n)).collect();
        assert!(labels_are_contiguous(&banded, &hoods, 3));
        let (b, eps) = classes(&banded, &forced, &pos, 3, 0.01);
        assert!(eps.is_some());
        assert_eq!(b.iter().filter(|x| x.rejected).count(), 0);
    }

    /// Without a position a segment keeps its label, certain; with neither a label nor
    /// labelled neighbours it has no class.
    #[test]
    fn segments_without_evidence() {
        let pos = vec![None, Some([0.0, 0.0]), Some([10.0, 0.0])];
        let labels = vec![Some(1), None, None];
        let (b, _) = classes(&labels, &vec![false; labels.len()], &pos, 2, 0.01);
        assert_eq!(b[0].probabilities, vec![(1, 1.0)]);
        assert_eq!(b[0].class, Some(1));
        assert!(!b[0].rejected);
        assert_eq!(b[1].class, None);
        assert!(b[1].probabilities.is_empty());
    }
}
