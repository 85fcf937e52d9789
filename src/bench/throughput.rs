//! Calibrate throughput, for `pipewave bench --calibrate N`: a synthetic network of N segments
//! in a temporary database, calibrated once, timed (speed is measured here, never asserted in
//! tests).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use crate::batch::{calibrate, BatchError, CalibrateOptions, CalibrateSummary};
use crate::db::{self, Database, DbError, ImportOptions, ImportSource};
use crate::synth::network::NetworkTables;
use crate::synth::{generate, SynthOptions};

/// Seed of the benchmark network (fixed so figures are comparable between builds).
pub const BENCH_NETWORK_SEED: u64 = 2024;

/// The figures of one timed calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Throughput {
    /// Segments fitted.
    pub segments: usize,
    /// Worker threads.
    pub jobs: usize,
    /// Wall-clock time of the calibration (lock to end, including the writes), s.
    pub wall_s: f64,
    /// Time to generate and import the network, s (not part of `wall_s`).
    pub setup_s: f64,
    /// Mean time a worker spent on one segment (fit and curve), ms.
    pub worker_ms_per_segment: f64,
    /// The run's summary.
    pub summary: CalibrateSummary,
    /// Peak resident memory of this process (VmHWM), kB, where /proc tells it.
    pub peak_rss_kb: Option<u64>,
}

impl Throughput {
    /// Fitted segments per second of wall-clock time.
    pub fn segments_per_second(&self) -> f64 {
        self.segments as f64 / self.wall_s.max(f64::MIN_POSITIVE)
    }
    /// Wall-clock time per segment, ms.
    pub fn wall_ms_per_segment(&self) -> f64 {
        1e3 * self.wall_s / self.segments.max(1) as f64
    }
}

/// Why the benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum ThroughputError {
    /// The temporary directory.
    #[error("cannot create the temporary directory {}", path.display())]
    TempDir {
        /// Its path.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The database.
    #[error(transparent)]
    Db(#[from] DbError),
    /// The generated network did not import (a bug in the generator).
    #[error("the synthetic network did not import: {0}")]
    Import(String),
    /// The run.
    #[error(transparent)]
    Batch(#[from] BatchError),
}

/// Peak resident set size of this process, kB (`VmHWM` of /proc/self/status; Linux only).
pub fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
}

/// A directory removed when dropped.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Generate `segments` synthetic segments (no defects), import them into a temporary database,
/// calibrate them on `jobs` threads with `opts`, and time it. The database is deleted after.
pub fn calibrate_throughput(
    segments: usize,
    opts: &CalibrateOptions,
) -> Result<Throughput, ThroughputError> {
    let t0 = Instant::now();
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    let dir =
        std::env::temp_dir().join(format!("pipewave-bench-{}-{nanos:09}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|source| ThroughputError::TempDir {
        path: dir.clone(),
        source,
    })?;
    let dir = TempDir(dir);
    let synth = SynthOptions {
        segments,
        seed: BENCH_NETWORK_SEED,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    };
    let tables = NetworkTables::from_synth(&generate(&synth), synth.srid);
    let mut database = Database::open(dir.0.join("bench.sqlite"))?;
    let report = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes(
            "segments.csv",
            tables.segments_csv(),
        )),
        Some(&ImportSource::from_bytes(
            "measurements.csv",
            tables.measurements_csv(),
        )),
        ImportOptions::default(),
    )?;
    if report.rejected {
        let first = report
            .errors
            .first()
            .map(|e| e.to_string())
            .unwrap_or_default();
        return Err(ThroughputError::Import(first));
    }
    let setup_s = t0.elapsed().as_secs_f64();
    let opts = CalibrateOptions {
        force: true,
        segments: None,
        ..opts.clone()
    };
    let summary = calibrate(database.conn_mut(), &opts, &mut (), &AtomicBool::new(false))?;
    let n = summary.stored();
    Ok(Throughput {
        segments: n,
        jobs: summary.jobs,
        wall_s: summary.elapsed_s,
        setup_s,
        worker_ms_per_segment: summary.worker_ms / n.max(1) as f64,
        peak_rss_kb: peak_rss_kb(),
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_rss_is_read_on_linux() {
        if std::path::Path::new("/proc/self/status").exists() {
            let kb = peak_rss_kb().expect("VmHWM");
            assert!(kb > 100, "{kb}");
        }
    }
}
