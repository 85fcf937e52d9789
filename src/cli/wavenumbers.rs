//! `pipewave wavenumbers --layout layout.csv --out measurements.csv [--band-hz W]
//! [--min-coherence C] [--fmin F] [--fmax F] [--campaign TEXT]`: field wavenumbers from
//! hydrant-test recordings (model §10).
//!
//! Writes the `measurements.csv` columns of docs/interface.md for the bands that carry
//! information, ready for `import`. A band's notes (`reflection_suspected`, ...) go in its
//! `note` column, so every band of one survey is in one campaign.
//! A segment whose recordings cannot be used is reported (file, line, what) and left out; the
//! others are written, and the exit code is 1.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pipewave::recordings::{
    self, analyse_segment, read_layout, write_measurements, EstimateOptions,
};

use super::{bounds, Outcome};

/// Highest frequency of `--band-hz`, `--fmin` and `--fmax`, Hz: hydrant-test wavenumbers of
/// buried mains are measured below a few kHz, where the pipe's fluid wave still carries.
const MAX_FREQUENCY_HZ: f64 = 10_000.0;

/// Recordings longer than this in all (s) get a progress bar on a terminal.
const PROGRESS_MIN_SECONDS: f64 = 60.0;

/// Arguments of `wavenumbers`.
#[derive(Debug, Args)]
pub struct WavenumbersArgs {
    /// The layout: segment_id, file, channel, position_m (one row per sensor).
    #[arg(long, value_name = "FILE")]
    layout: PathBuf,
    /// Where to write the measurements (measurements.csv format).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Band width, Hz: one measurement per band. Range 2 – 10000 Hz.
    #[arg(long, value_name = "W", default_value_t = EstimateOptions::default().band_hz,
          value_parser = bounds::real(2.0, MAX_FREQUENCY_HZ, "Hz"))]
    band_hz: f64,
    /// Lowest coherence γ² of a frequency bin to be used. Range 0 < C < 1.
    #[arg(long, value_name = "C", default_value_t = EstimateOptions::default().min_coherence,
          value_parser = bounds::real(0.0, 1.0, ""))]
    min_coherence: f64,
    /// Lower edge of the first band, Hz. Range 0 – 10000 Hz.
    #[arg(long, value_name = "HZ", default_value_t = EstimateOptions::default().fmin_hz,
          value_parser = bounds::real(0.0, MAX_FREQUENCY_HZ, "Hz"))]
    fmin: f64,
    /// Upper edge of the bands, Hz (default: 0.45 × the sample rate). Range: above --fmin +
    /// --band-hz, at most 10000 Hz.
    #[arg(long, value_name = "HZ", value_parser = bounds::real(0.0, MAX_FREQUENCY_HZ, "Hz"))]
    fmax: Option<f64>,
    /// Text for the campaign column (default: the layout file's name without extension).
    #[arg(long, value_name = "TEXT")]
    campaign: Option<String>,
}

/// Analyse every segment of the layout and write the measurements.
pub fn run(args: &WavenumbersArgs) -> anyhow::Result<Outcome> {
    super::guard_outputs(
        None,
        &[&args.layout],
        &[(&args.out, pipewave::outfile::Contents::Plain)],
    )?;
    let opts = EstimateOptions::new(args.band_hz, args.min_coherence, args.fmin, args.fmax)
        .map_err(anyhow::Error::msg)?;
    let layout = match read_layout(&args.layout) {
        Ok(l) => l,
        Err(errors) => {
            for e in &errors[..errors.len() - 1] {
                eprintln!("error: {e}");
            }
            bail!("{}", errors[errors.len() - 1]);
        }
    };
    // The recordings the layout names are inputs too: no output may replace one.
    for seg in &layout.segments {
        for s in &seg.sensors {
            pipewave::outfile::protect_input(&s.path);
        }
    }
    pipewave::outfile::check(
        &args.out,
        pipewave::outfile::Contents::Plain,
        "measurements.csv",
    )?;
    let campaign = args.campaign.clone().unwrap_or_else(|| {
        args.layout
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    });
    let bar = progress_bar(&layout.segments);
    let tick = |n: u64| {
        if let Some(b) = &bar {
            b.inc(n)
        }
    };
    let mut results = Vec::new();
    let mut failed = 0usize;
    for seg in &layout.segments {
        match analyse_segment(&layout.path, seg, &opts, &tick) {
            Ok(r) => results.push(r),
            Err(e) => {
                if let Some(b) = &bar {
                    b.suspend(|| eprintln!("error: {e}"));
                } else {
                    eprintln!("error: {e}");
                }
                failed += 1;
            }
        }
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    write_measurements(&args.out, &results, &campaign)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let rows: usize = results.iter().map(|r| r.bands.len()).sum();
    let reflections = results
        .iter()
        .flat_map(|r| &r.bands)
        .filter(|b| b.notes.contains(&recordings::estimate::NOTE_REFLECTION))
        .count();
    println!(
        "wavenumbers: {} of {} segments, {} bands -> {}{}",
        results.len(),
        layout.segments.len(),
        rows,
        args.out.display(),
        if reflections > 0 {
            format!(" ({reflections} bands with reflection_suspected)")
        } else {
            String::new()
        }
    );
    for r in &results {
        if r.bands.is_empty() {
            eprintln!(
                "note: segment {}: no band carries information (coherence below --min-coherence {} everywhere)",
                r.segment_id, opts.min_coherence
            );
        }
    }
    Ok(if failed > 0 {
        Outcome::SomeFailed
    } else {
        Outcome::Done
    })
}

/// A bar on a terminal when the recordings are long; `None` otherwise.
fn progress_bar(segments: &[recordings::SegmentLayout]) -> Option<ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let frames = recordings::wav::total_frames(segments)?;
    let rate = segments
        .first()
        .and_then(|s| s.sensors.first())
        .and_then(|s| hound::WavReader::open(&s.path).ok())
        .map(|r| r.spec().sample_rate)?;
    if (frames as f64) / (rate as f64) < PROGRESS_MIN_SECONDS {
        return None;
    }
    // Reading, and the two spectral passes, each go through every frame once.
    let bar = ProgressBar::new(3 * frames);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("wavenumbers");
    Some(bar)
}
