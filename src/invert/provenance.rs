//! What the search of one fit did, as data: the stage that found the optimum the answer stands
//! on, and for every stage why it stopped, the forward evaluations it spent and how much it
//! lowered the best misfit (in the manner of argmin's termination reasons and observers). Also
//! the search's typed errors, and [`StageStatistics`], which collects the records of many fits
//! (`pipewave bench` prints the share of fits each stage won).

use std::fmt;

use crate::optimize::OptimizeError;

use super::problem::SolvePath;

/// A stage of the segment search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// A differential-evolution run over the whole box, polished.
    Global,
    /// The polish from a base fit's optimum (a fit with effects).
    NestedStart,
    /// Candidates across a grazing cliff (P44) and in its gaps, polished and walked from.
    Grazing,
    /// The gap scan again from a best near grazing.
    GrazingRescan,
    /// The answer's continued polish (it refines an optimum another stage found).
    ContinuedPolish,
    /// Polishes from the faces of r and ξ of the speed coordinates at the best optimum of the
    /// DE runs in those coordinates.
    SpeedFaces,
    /// The polish from another campaign's optimum of the same pipe (model §7.14).
    CampaignStart,
}

impl Stage {
    /// Every stage, in the search's order.
    pub const ALL: [Stage; 7] = [
        Stage::Global,
        Stage::NestedStart,
        Stage::Grazing,
        Stage::GrazingRescan,
        Stage::ContinuedPolish,
        Stage::SpeedFaces,
        Stage::CampaignStart,
    ];

    /// Name used in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Global => "global",
            Stage::NestedStart => "nested start",
            Stage::Grazing => "grazing",
            Stage::GrazingRescan => "grazing rescan",
            Stage::ContinuedPolish => "continued polish",
            Stage::SpeedFaces => "speed faces",
            Stage::CampaignStart => "campaign start",
        }
    }

    fn index(self) -> usize {
        Stage::ALL
            .iter()
            .position(|&s| s == self)
            .expect("every stage is listed")
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a stage stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StageStop {
    /// A differential-evolution run ended for this reason.
    Population(crate::optimize::StopReason),
    /// The stage polished or walked from this many starts and returned that many optima.
    Polished {
        /// Starts polished or walked from.
        starts: usize,
        /// Optima it returned.
        optima: usize,
    },
    /// The polish stopped at its iteration cap, still descending.
    PolishCapped,
    /// The stage's condition did not hold at the best so far (not on a face of ξ, not at the
    /// upper bound of ν_m, not near grazing), or it found no candidate.
    NotApplicable,
    /// The stage's run gave no finite misfit.
    NoFiniteOptimum,
}

/// One stage of one search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageRecord {
    /// The stage.
    pub stage: Stage,
    /// Why it stopped.
    pub stop: StageStop,
    /// Forward evaluations it spent (on the search path).
    pub evaluations: usize,
    /// The best misfit of the search before it (+∞ before the first finite one).
    pub best_before: f64,
    /// The best misfit after it.
    pub best_after: f64,
}

impl StageRecord {
    /// How much the stage lowered the best misfit (0 when it did not; +∞ for the first
    /// finite one).
    pub fn improvement(&self) -> f64 {
        if self.best_after < self.best_before {
            self.best_before - self.best_after
        } else {
            0.0
        }
    }
}

/// The provenance of a fit's answer.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Provenance {
    /// The stage whose optimum the answer is (`None` for a failed fit).
    pub winner: Option<Stage>,
    /// Every stage of the search that gave the answer, in order.
    pub stages: Vec<StageRecord>,
    /// The path the answer's search ran on: fast, or safe where the fast path tracked another
    /// root at its optimum.
    pub path: Option<SolvePath>,
    /// The answer was moved just off a grazing cliff for the reference path to confirm it.
    pub moved_off_cliff: bool,
    /// Searches run (1, or 2 when a fit flagged `high_misfit` searched once more).
    pub searches: usize,
    /// The answer came from the second search.
    pub from_second_search: bool,
    /// Why a failed fit failed.
    pub error: Option<SearchError>,
}

impl Provenance {
    /// The record of a stage, when it ran (the first, for a stage that ran more than once).
    pub fn record(&self, stage: Stage) -> Option<&StageRecord> {
        self.stages.iter().find(|r| r.stage == stage)
    }

    /// Evaluations spent by every run of a stage.
    pub fn evaluations(&self, stage: Stage) -> usize {
        self.stages
            .iter()
            .filter(|r| r.stage == stage)
            .map(|r| r.evaluations)
            .sum()
    }
}

/// Why a search gives no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SearchError {
    /// The segment has no measurements.
    #[error("no measurements for this segment")]
    NoMeasurements,
    /// The optimiser's settings or the search box are invalid.
    #[error(transparent)]
    Optimizer(#[from] OptimizeError),
    /// No soil in the box gives a root: the reference solver's reason at a typical soil.
    #[error(
        "no s = 1 root for any soil in the search range; for a typical soil ({soil}): {reason}"
    )]
    NoRootAnywhere {
        /// The typical soil, as `name = value` pairs.
        soil: String,
        /// The reference solver's reason.
        reason: String,
    },
    /// The reference path finds no root at any optimum of the search.
    #[error("forward solve failed at the optimum: {reason}")]
    NoRootAtOptimum {
        /// The reference solver's reason at the best optimum.
        reason: String,
    },
}

/// Per-stage statistics over many fits: how often each stage found the answer, how often it
/// lowered the best misfit, and the evaluations it spent.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StageStatistics {
    /// Fits observed.
    pub fits: usize,
    /// Fits with an answer.
    pub answered: usize,
    won: [usize; Stage::ALL.len()],
    improved: [usize; Stage::ALL.len()],
    ran: [usize; Stage::ALL.len()],
    evaluations: [usize; Stage::ALL.len()],
    /// Fits whose answer came from the safe path.
    pub safe_path: usize,
    /// Fits that searched twice.
    pub second_search: usize,
}

impl StageStatistics {
    /// Take in the provenance of one fit.
    pub fn observe(&mut self, p: &Provenance) {
        self.fits += 1;
        if let Some(w) = p.winner {
            self.answered += 1;
            self.won[w.index()] += 1;
        }
        let mut seen = [false; Stage::ALL.len()];
        let mut better = [false; Stage::ALL.len()];
        for r in &p.stages {
            let i = r.stage.index();
            seen[i] |= r.stop != StageStop::NotApplicable;
            better[i] |= r.improvement() > 0.0 && r.best_before.is_finite();
            self.evaluations[i] += r.evaluations;
        }
        for i in 0..Stage::ALL.len() {
            self.ran[i] += usize::from(seen[i]);
            self.improved[i] += usize::from(better[i]);
        }
        self.safe_path += usize::from(p.path == Some(SolvePath::Safe));
        self.second_search += usize::from(p.searches > 1);
    }

    /// Fits whose answer the stage found.
    pub fn won(&self, stage: Stage) -> usize {
        self.won[stage.index()]
    }

    /// Share of the answered fits whose answer the stage found (0 when none was answered).
    pub fn share_won(&self, stage: Stage) -> f64 {
        self.won(stage) as f64 / self.answered.max(1) as f64
    }

    /// Fits in which the stage ran (its condition held at the best so far).
    pub fn ran(&self, stage: Stage) -> usize {
        self.ran[stage.index()]
    }

    /// Fits in which the stage lowered a finite best misfit.
    pub fn improved(&self, stage: Stage) -> usize {
        self.improved[stage.index()]
    }

    /// Mean evaluations a fit the stage spent (over every fit observed).
    pub fn mean_evaluations(&self, stage: Stage) -> f64 {
        self.evaluations[stage.index()] as f64 / self.fits.max(1) as f64
    }
}

impl fmt::Display for StageStatistics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "  search stages over {} fits ({} answered, {} on the safe path, {} searched twice):",
            self.fits, self.answered, self.safe_path, self.second_search
        )?;
        for s in Stage::ALL {
            writeln!(
                f,
                "    {:<17} won {:>5.1} %  ran in {:>5} fits, lowered the best in {:>5}, {:>6.0} evaluations/fit",
                s.as_str(),
                100.0 * self.share_won(s),
                self.ran(s),
                self.improved(s),
                self.mean_evaluations(s)
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::synthetic_mdpe_data;
    use crate::invert::{fit_segment, FitSettings};
    use crate::synth::bench::{bench_network, MaterialMix};
    use crate::types::FitStatus;

    /// Every fit of a bench network records the stage that found its answer, the global
    /// stage's stop reason, and evaluations per stage that add up to at most the fit's; the
    /// answer's misfit is at most the winning stage's best (the continued polish only lowers
    /// it, the reference path may rate it differently only near a cliff).
    #[test]
    fn every_fit_records_where_its_answer_came_from() {
        let mut stats = StageStatistics::default();
        for seg in bench_network(12, 848101, MaterialMix::PlasticHeavy) {
            let r = fit_segment(&seg.data, &FitSettings::default(), seg.seed);
            let p = &r.provenance;
            stats.observe(p);
            if r.status == FitStatus::Failed {
                assert!(p.winner.is_none());
                continue;
            }
            assert!(p.winner.is_some(), "{}", seg.id);
            assert!(p.searches == 1 || p.searches == 2, "{}", p.searches);
            assert!(!p.from_second_search || p.searches == 2);
            assert!(p.path.is_some());
            let global: Vec<&StageRecord> = p
                .stages
                .iter()
                .filter(|s| s.stage == Stage::Global)
                .collect();
            assert_eq!(global.len(), FitSettings::default().restarts, "{}", seg.id);
            assert!(global
                .iter()
                .all(|g| matches!(g.stop, StageStop::Population(_)) && g.evaluations > 0));
            let spent: usize = p.stages.iter().map(|s| s.evaluations).sum();
            assert!(
                spent > 0 && spent <= r.evaluations,
                "{spent} of {}",
                r.evaluations
            );
            // The best misfit never rises from stage to stage.
            for w in p.stages.windows(2) {
                assert!(w[1].best_before == w[0].best_after, "{:?}", p.stages);
                assert!(w[1].best_after <= w[1].best_before);
            }
        }
        assert_eq!(stats.fits, 12);
        assert!(stats.answered >= 11);
        let shares: f64 = Stage::ALL.iter().map(|&s| stats.share_won(s)).sum();
        assert!((shares - 1.0).abs() < 1e-12, "{shares}");
        assert_eq!(stats.ran(Stage::Global), stats.fits);
        assert!(stats.won(Stage::ContinuedPolish) == 0);
    }

    /// A fit without measurements fails with the typed reason and no winner; one of the bench
    /// cases is won by a recorded stage.
    #[test]
    fn a_failed_fit_records_no_winner() {
        let mut data = synthetic_mdpe_data();
        let ok = fit_segment(&data, &FitSettings::default(), 3);
        assert!(ok.provenance.winner.is_some());
        data.measurements.clear();
        let r = fit_segment(&data, &FitSettings::default(), 3);
        assert_eq!(r.status, FitStatus::Failed);
        assert!(r.provenance.winner.is_none() && r.provenance.stages.is_empty());
        assert_eq!(r.provenance.error, Some(SearchError::NoMeasurements));
        assert_eq!(
            r.message.as_deref(),
            Some("no measurements for this segment")
        );
    }
}
