//! Progress of a long run written as plain lines, for a log rather than a terminal (stderr
//! redirected by cron or a scheduler): one line every [`LINE_INTERVAL`] or every
//! [`LINE_FRACTION`] of the work, whichever comes first, so a log shows the run advancing without
//! one line per segment.

use std::time::Duration;

/// The longest time between two progress lines.
pub const LINE_INTERVAL: Duration = Duration::from_secs(10);
/// The largest share of the work between two progress lines.
pub const LINE_FRACTION: f64 = 0.05;

/// Decides when a progress line is due and writes it.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgressLines {
    total: usize,
    /// Work done at the last line.
    last_done: usize,
    /// Time of the last line, from the start.
    last_at: Duration,
}

impl ProgressLines {
    /// Progress over `total` items.
    pub fn new(total: usize) -> Self {
        Self {
            total,
            last_done: 0,
            last_at: Duration::ZERO,
        }
    }

    /// The line to print after `done` items at `elapsed` since the start, if one is due: 10 s
    /// after the last line, or once another 5 % of the items are done, or at the last item.
    /// `detail` follows the counts (for instance the statuses so far).
    pub fn line(&mut self, done: usize, elapsed: Duration, detail: &str) -> Option<String> {
        let step = ((self.total as f64 * LINE_FRACTION).ceil() as usize).max(1);
        let due = done >= self.total
            || done >= self.last_done + step
            || elapsed >= self.last_at + LINE_INTERVAL;
        if !due || done == self.last_done {
            return None;
        }
        self.last_done = done;
        self.last_at = elapsed;
        let pct = if self.total == 0 {
            100.0
        } else {
            100.0 * done as f64 / self.total as f64
        };
        let eta = (done > 0 && done < self.total)
            .then(|| elapsed.as_secs_f64() * (self.total - done) as f64 / done as f64);
        Some(format!(
            "progress: {done}/{} segments ({pct:.0} %), {}, {} elapsed{}",
            self.total,
            detail,
            clock(elapsed.as_secs_f64()),
            eta.map_or_else(String::new, |s| format!(", about {} left", clock(s)))
        ))
    }
}

/// A duration for a log: `42 s`, `3 min 05 s`, `2 h 07 min`.
fn clock(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..=59 => format!("{s} s"),
        60..=3599 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn secs(s: u64) -> Duration {
        Duration::from_secs(s)
    }

    #[test]
    fn a_fast_run_prints_every_five_percent() {
        let mut p = ProgressLines::new(1000);
        let printed: Vec<usize> = (1..=1000)
            .filter(|&i| p.line(i, Duration::from_millis(i as u64), "x").is_some())
            .collect();
        assert_eq!(printed, (1..=20).map(|k| 50 * k).collect::<Vec<_>>());
    }

    #[test]
    fn a_slow_run_prints_every_ten_seconds() {
        // 1,000 items at 3 s each: 5 % takes 150 s, so the 10 s rule sets the pace.
        let mut p = ProgressLines::new(1000);
        let mut at = Vec::new();
        for i in 1..=40 {
            if p.line(i, secs(3 * i as u64), "x").is_some() {
                at.push(3 * i);
            }
        }
        assert_eq!(at, vec![12, 24, 36, 48, 60, 72, 84, 96, 108, 120]);
    }

    #[test]
    fn the_line_says_counts_share_and_time_left() {
        let mut p = ProgressLines::new(200);
        assert_eq!(p.line(5, secs(4), "ok 5"), None);
        assert_eq!(
            p.line(10, secs(8), "ok 9 flagged 1 failed 0").as_deref(),
            Some(
                "progress: 10/200 segments (5 %), ok 9 flagged 1 failed 0, 8 s elapsed, about \
                 2 min 32 s left"
            )
        );
        assert_eq!(
            p.line(200, secs(3700), "done").as_deref(),
            Some("progress: 200/200 segments (100 %), done, 1 h 01 min elapsed")
        );
        assert_eq!(p.line(200, secs(3800), "done"), None, "once per count");
    }
}
