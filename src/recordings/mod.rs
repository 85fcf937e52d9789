//! Field wavenumbers from hydrant-test recordings (model §10, eqs. P72–P77).
//!
//! A field team opens a hydrant (a broadband noise source at x = 0) and records sensors on the
//! pipe at signed positions. This module turns those recordings into the `measurements.csv`
//! rows the inversion takes:
//!
//! * [`layout`]: the layout file (`segment_id, file, channel, position_m`), checked;
//! * [`wav`]: the WAV channels (16/24-bit PCM, 32-bit float), checked for clipping, missing
//!   channels and mismatched sample rates;
//! * [`spectra`]: Welch auto- and cross-spectra;
//! * [`estimate`]: transfer functions (eq. P73, the three-channel estimator P77), the phase
//!   unwrapped from low frequency, Re k1 and the attenuation per band (P74) with standard errors
//!   from the coherence (P75–P76), combined over bins, sensor pairs and the two sides;
//! * [`synth::recordings`](crate::synth::recordings): synthetic recordings from the forward
//!   model, with their truth;
//! * [`synth::recordings::recovery`](crate::synth::recordings::recovery): the whole chain on a
//!   synthetic network (recordings → wavenumbers → calibrate), judged by the fitted c_P against
//!   the truth.

pub mod estimate;
pub mod layout;
pub mod spectra;
pub mod wav;

use std::path::{Path, PathBuf};

pub use estimate::{analyse_segment, BandEstimate, EstimateOptions, SegmentWavenumbers};
pub use layout::{read_layout, Layout, SegmentLayout, Sensor};

use crate::spreadsheet::{self, spreadsheet_safe};
use crate::units::sig;

/// Columns of the written measurements (docs/interface.md `measurements.csv`; `import` accepts no
/// other columns).
pub const MEASUREMENT_COLUMNS: [&str; 8] = [
    "segment_id",
    "frequency_hz",
    "k_re_rad_per_m",
    "attenuation_np_per_m",
    "k_re_std",
    "attenuation_std",
    "campaign",
    "note",
];

/// The one place the `wavenumbers` output file is written: one row per band. A band's notes
/// (`reflection_suspected`, ...) go in the `note` column, comma-separated, so that every band
/// of one survey is in the one campaign. Text cells follow the spreadsheet-safety rule of every
/// CSV pipewave writes.
pub fn write_measurements(
    path: &Path,
    results: &[SegmentWavenumbers],
    campaign: &str,
) -> Result<(), csv::Error> {
    let mut w = spreadsheet::writer_from_path(path)?;
    w.write_record(MEASUREMENT_COLUMNS)?;
    for r in results {
        for b in &r.bands {
            w.write_record([
                spreadsheet_safe(&r.segment_id).into_owned(),
                format!("{:.3}", b.frequency_hz),
                b.k_re.to_string(),
                b.attenuation.to_string(),
                b.k_re_std.to_string(),
                b.attenuation_std.to_string(),
                spreadsheet_safe(campaign).into_owned(),
                spreadsheet_safe(&b.notes.join(", ")).into_owned(),
            ])?;
        }
    }
    spreadsheet::finish(w)
}

/// A problem with the recordings of a field test. Every message names the file (and the layout
/// line and column, or the segment) and says what was expected.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// A file could not be read.
    #[error("cannot read {}: {message}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A problem in one cell of the layout file.
    #[error("{} line {line}, column {column}: {message}", file.display())]
    Layout {
        /// The layout file.
        file: PathBuf,
        /// Line number (1 = header).
        line: u64,
        /// Column name.
        column: String,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A problem with the layout file as a whole (missing column, no rows).
    #[error("{}: {message}", file.display())]
    LayoutFile {
        /// The layout file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A WAV file that cannot be used.
    #[error("segment {segment_id}: {} (named in {} line {line}): {message}", wav.display(), layout.display())]
    Wav {
        /// Segment.
        segment_id: String,
        /// The WAV file.
        wav: PathBuf,
        /// The layout file.
        layout: PathBuf,
        /// The layout line that names the file.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// The sensors of a segment are placed so that no estimate can be made, or the recordings
    /// contradict their positions.
    #[error("segment {segment_id} ({}): {message}", layout.display())]
    Positions {
        /// Segment.
        segment_id: String,
        /// The layout file.
        layout: PathBuf,
        /// What is wrong, naming the lines.
        message: String,
    },
}

/// Short number for messages (`1e308`, `0.0542`).
pub(crate) fn short(x: f64) -> String {
    sig(x, 3)
}
