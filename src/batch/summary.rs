//! What a calibrate run did ([`CalibrateSummary`]): the counts the run returns and the one
//! line the command prints, with the change tests counted by cause (model §7.14).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::db::changes::ChangeRecord;
use crate::db::{FitRow, FitStatus};

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateSummary {
    /// The `runs` row (`None` when the run was interrupted while waiting for the lock).
    pub run_id: Option<i64>,
    /// Worker threads.
    pub jobs: usize,
    /// The settings hash of the run's fits.
    pub settings_hash: String,
    /// Segments selected for fitting: as counted before the fits, and once every one was
    /// handed out, as the pages held when the fits read them (the two differ only if an import
    /// changed the inventory meanwhile).
    pub selected: usize,
    /// Segments in scope whose latest fit was current.
    pub up_to_date: usize,
    /// Selected segments whose latest fit was made by another version of the fitting
    /// algorithm (refitted on that account).
    pub algorithm_refits: usize,
    /// Segments named with `segments` that have no measurements (nothing to fit).
    pub without_measurements: Vec<String>,
    /// Fits stored with status ok.
    pub ok: usize,
    /// Fits stored with status flagged.
    pub flagged: usize,
    /// Fits stored with status failed.
    pub failed: usize,
    /// Flag codes over the stored fits, with how many fits carry each.
    pub flag_counts: BTreeMap<String, usize>,
    /// The failed segments and why, in the order they were stored.
    pub failures: Vec<(String, String)>,
    /// True when the run was stopped before every selected segment was fitted.
    pub interrupted: bool,
    /// Wall-clock time of the run (from the lock to the end), s.
    pub elapsed_s: f64,
    /// Sum of the workers' time over the stored fits, ms.
    pub worker_ms: f64,
    /// The soil zones estimated with the field after the fits (the zone classes' means), if
    /// the run finished and the field was rebuilt.
    pub zones: Option<crate::zones::ZoneUpdate>,
    /// The soil field's update after the fits (model §7.12), if the run finished.
    pub field: Option<crate::field::FieldUpdate>,
    /// Fits of segments measured in two or more campaigns: how many were tested and found
    /// unchanged (pooled), and the changes by named cause (`unexplained` included), model §7.14.
    pub changes: ChangeCounts,
}

/// The change tests of a run's fits (model §7.14).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChangeCounts {
    /// Segments whose latest campaign was tested against an earlier one.
    pub tested: usize,
    /// Of those, unchanged (their campaigns pooled).
    pub unchanged: usize,
    /// Changed, by named cause.
    pub changed: BTreeMap<String, usize>,
    /// With two campaigns but not tested (a failed fit, no standard deviations).
    pub untested: usize,
}

impl ChangeCounts {
    /// Changed segments in all.
    pub fn changed_total(&self) -> usize {
        self.changed.values().sum()
    }
}

impl CalibrateSummary {
    /// Fits stored by this run.
    pub fn stored(&self) -> usize {
        self.ok + self.flagged + self.failed
    }

    /// Selected segments not fitted because the run was stopped.
    pub fn not_attempted(&self) -> usize {
        self.selected.saturating_sub(self.stored())
    }

    /// Stored fits per second of wall-clock time.
    pub fn segments_per_second(&self) -> f64 {
        if self.elapsed_s > 0.0 {
            self.stored() as f64 / self.elapsed_s
        } else {
            0.0
        }
    }

    /// The one-line summary printed at the end of a run, e.g. `calibrate: 12 fitted (9 ok,
    /// 3 flagged: at_bound 1, modulus_uncertain 3; 0 failed), 4 up to date, in 2.1 s (5.7
    /// segments/s, 2 jobs)`.
    pub fn line(&self) -> String {
        let mut s = format!(
            "calibrate: {} fitted ({} ok, {} flagged",
            self.stored(),
            self.ok,
            self.flagged
        );
        if !self.flag_counts.is_empty() {
            s.push_str(": ");
            let parts: Vec<String> = self
                .flag_counts
                .iter()
                .map(|(code, n)| format!("{code} {n}"))
                .collect();
            s.push_str(&parts.join(", "));
        }
        let _ = write!(
            s,
            "; {} failed), {} up to date, in {:.1} s ({:.1} segments/s, {} job{})",
            self.failed,
            self.up_to_date,
            self.elapsed_s,
            self.segments_per_second(),
            self.jobs,
            if self.jobs == 1 { "" } else { "s" }
        );
        if self.algorithm_refits > 0 {
            let _ = write!(
                s,
                "; {} refitted because the fitting algorithm changed (now version {})",
                self.algorithm_refits,
                crate::types::FIT_ALGORITHM_VERSION
            );
        }
        let c = &self.changes;
        if c.tested + c.untested > 0 {
            let _ = write!(
                s,
                "; campaigns: {} tested, {} unchanged (pooled), {} changed",
                c.tested,
                c.unchanged,
                c.changed_total()
            );
            if !c.changed.is_empty() {
                let parts: Vec<String> = c
                    .changed
                    .iter()
                    .map(|(cause, n)| format!("{cause} {n}"))
                    .collect();
                let _ = write!(s, " ({})", parts.join(", "));
            }
            if c.untested > 0 {
                let _ = write!(s, ", {} untested", c.untested);
            }
        }
        if self.interrupted {
            let _ = write!(
                s,
                "; interrupted: {} not fitted (the next run fits them)",
                self.not_attempted()
            );
        }
        s
    }
}

impl CalibrateSummary {
    /// Count one stored fit's change test.
    pub(super) fn record_change(&mut self, change: Option<&ChangeRecord>) {
        let Some(c) = change.map(|c| &c.change) else {
            return;
        };
        let counts = &mut self.changes;
        match c.status.as_str() {
            "changed" => {
                counts.tested += 1;
                let cause = c.effect.clone().unwrap_or_else(|| "unexplained".into());
                *counts.changed.entry(cause).or_insert(0) += 1;
            }
            "unchanged" => {
                counts.tested += 1;
                counts.unchanged += 1;
            }
            "untested" => counts.untested += 1,
            _ => {}
        }
    }

    /// Count one stored fit.
    pub(super) fn record(&mut self, fit: &FitRow) {
        match fit.status {
            FitStatus::Ok => self.ok += 1,
            FitStatus::Flagged => self.flagged += 1,
            FitStatus::Failed => {
                self.failed += 1;
                self.failures.push((
                    fit.segment_id.clone(),
                    fit.message
                        .clone()
                        .unwrap_or_else(|| "no reason given".into()),
                ));
            }
        }
        for code in fit.flags.split(',').filter(|c| !c.is_empty()) {
            *self.flag_counts.entry(code.to_string()).or_insert(0) += 1;
        }
        self.worker_ms += fit.elapsed_ms.unwrap_or(0.0);
    }
}
