//! `pipewave locate --db DB --input jobs.csv --out located.csv [--jobs N]` or one correlation on
//! the command
//! line (`--sensor1 ID:CHAINAGE --sensor2 ID:CHAINAGE --delay S --delay-std S`, or
//! `--recording1 FILE:CH --recording2 FILE:CH`): the leak's position across a path of one or
//! more segments with its 95 % interval and error budget (model §11, P84–P87).
//!
//! Exit codes: 0 every job located; 1 some jobs failed (each reported on its own row and in
//! the summary); 2 the command could not run (bad arguments, unusable jobs file or database; a
//! single correlation that cannot be located).

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use pipewave::locate::gcc::RecordingPair;
use pipewave::locate::jobs::{read_jobs, write_csv, write_geojson, write_gpkg, Answer, RowFailure};
use pipewave::locate::model::Weighting;
use pipewave::locate::network::{SensorSpec, DEFAULT_JOIN_TOLERANCE_M, DEFAULT_SNAP_TOLERANCE_M};
use pipewave::locate::{
    DelayInput, Job, LocateOptions, Located, Locator, DEFAULT_BAND_HZ, DEFAULT_SPAN_STD_FRACTION,
    MAX_DELAY_S, MAX_SPAN_STD_FRACTION,
};
use pipewave::units::escape_controls;

use pipewave::outfile::Contents;

use super::{bounds, open_database, Outcome};

/// Largest `--snap-tolerance`, m: a sensor a kilometre from every pipe is not on the network.
const MAX_SNAP_TOLERANCE_M: f64 = 1000.0;
/// Largest `--join-tolerance`, m: end points 100 m apart are not one junction.
const MAX_JOIN_TOLERANCE_M: f64 = 100.0;

/// Arguments of `locate`.
#[derive(Debug, Args)]
pub struct LocateArgs {
    /// The pipewave database (inventory, fits, predictions).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// A CSV of correlations, one a row (job_id, sensor1_segment, sensor1_chainage_m,
    /// sensor2_segment, sensor2_chainage_m, then delay_s, delay_std_s or recording1, channel1,
    /// recording2, channel2; optional band_lo_hz, band_hi_hz, path).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["sensor1", "sensor2", "delay", "recording1"])]
    input: Option<PathBuf>,
    /// Worker threads for the rows of --input, as in every other command (default: one per
    /// core, at most one per row); the answers do not depend on it. Range 1 – 512. A value that
    /// is not a whole number is read as the jobs file, the option's old meaning (now --input),
    /// with a note.
    #[arg(long, value_name = "N", value_parser = jobs_arg)]
    jobs: Option<JobsArg>,
    /// Where to write the answers as CSV.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Also write the answers as GeoJSON (a point per leak, its 95 % interval as a line).
    #[arg(long, value_name = "FILE")]
    geojson: Option<PathBuf>,
    /// Also write them as two layers of a GeoPackage (added to it if it exists).
    #[arg(long, value_name = "FILE")]
    gpkg: Option<PathBuf>,
    /// Sensor 1: SEGMENT:CHAINAGE (metres along its geometry from the first vertex) or X,Y (map
    /// coordinates in the network's CRS, snapped to the nearest segment). Range: CHAINAGE 0 –
    /// the segment's length; X, Y finite, within --snap-tolerance of a segment.
    #[arg(long, value_name = "ID:M | X,Y")]
    sensor1: Option<String>,
    /// Sensor 2, as sensor 1. Range as sensor 1's.
    #[arg(long, value_name = "ID:M | X,Y")]
    sensor2: Option<String>,
    /// The correlator's delay t(sensor 2) − t(sensor 1), s. Range −10 – 10 s.
    #[arg(
        long,
        value_name = "S",
        allow_negative_numbers = true,
        requires = "delay_std",
        value_parser = bounds::real(-MAX_DELAY_S, MAX_DELAY_S, "s")
    )]
    delay: Option<f64>,
    /// Its standard error, s. Range 0 – 10 s.
    #[arg(long, value_name = "S", value_parser = bounds::real(0.0, MAX_DELAY_S, "s"))]
    delay_std: Option<f64>,
    /// Sensor 1's recording: FILE or FILE:CHANNEL (WAV, channel from 0). Range: CHANNEL 0 – the
    /// file's channels − 1.
    #[arg(
        long,
        value_name = "FILE[:CH]",
        requires = "recording2",
        conflicts_with = "delay"
    )]
    recording1: Option<String>,
    /// Sensor 2's recording, as sensor 1's. Range: CHANNEL 0 – the file's channels − 1.
    #[arg(long, value_name = "FILE[:CH]")]
    recording2: Option<String>,
    /// The path, segment ids from sensor 1's to sensor 2's (instead of routing), each segment
    /// once.
    #[arg(long, value_name = "ID,ID,...")]
    path: Option<String>,
    /// Correlation band LO,HI in Hz: 0 < LO, HI ≤ 20000, at least 5 Hz wide (default 100,800).
    #[arg(long, value_name = "LO,HI", value_parser = bounds::band)]
    band: Option<(f64, f64)>,
    /// Weighting of the cross-correlation of recordings: phat, scot or plain.
    #[arg(long, value_name = "NAME", default_value = "scot")]
    weighting: String,
    /// How the correlator that measured a given delay weighted it: plain (band-filtered
    /// cross-correlation), phat or scot.
    #[arg(long, value_name = "NAME", default_value = "plain")]
    given_weighting: String,
    /// Map coordinates farther than this from every segment are off the network, m. Range
    /// 0 – 1000 m.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_SNAP_TOLERANCE_M,
          value_parser = bounds::real(0.0, MAX_SNAP_TOLERANCE_M, "m"))]
    snap_tolerance: f64,
    /// Segment end points closer than this are one junction, m. Range 0 – 100 m.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_JOIN_TOLERANCE_M,
          value_parser = bounds::real(0.0, MAX_JOIN_TOLERANCE_M, "m"))]
    join_tolerance: f64,
    /// Relative error of the span measured along the GIS geometry (0 for a measured span).
    /// Range 0 – 0.5.
    #[arg(long, value_name = "F", default_value_t = DEFAULT_SPAN_STD_FRACTION,
          value_parser = bounds::real(0.0, MAX_SPAN_STD_FRACTION, ""))]
    span_std_fraction: f64,
}

/// `--jobs`: a thread count, or (its old meaning) the jobs file.
#[derive(Debug, Clone, PartialEq)]
enum JobsArg {
    /// Worker threads.
    Threads(u32),
    /// A jobs file given the old way, `--jobs FILE`.
    File(PathBuf),
}

/// Read `--jobs`: a whole number is a thread count, refused outside 1 – [`bounds::MAX_JOBS`];
/// anything else is the jobs file of older versions.
fn jobs_arg(text: &str) -> Result<JobsArg, String> {
    let t = text.trim();
    if !t.is_empty()
        && t.trim_start_matches(['-', '+'])
            .bytes()
            .all(|b| b.is_ascii_digit())
    {
        return match t.parse::<i128>() {
            Ok(n) if (1..=i128::from(bounds::MAX_JOBS)).contains(&n) => {
                Ok(JobsArg::Threads(n as u32))
            }
            _ => Err(format!(
                "{t} worker threads: the range is 1 – {} (the jobs file is --input FILE)",
                bounds::MAX_JOBS
            )),
        };
    }
    Ok(JobsArg::File(PathBuf::from(text)))
}

fn sensor(text: &str, name: &str) -> anyhow::Result<SensorSpec> {
    if let Some((x, y)) = text.split_once(',') {
        let (x, y) = (x.trim().parse::<f64>(), y.trim().parse::<f64>());
        if let (Ok(x), Ok(y)) = (x, y) {
            if !(x.is_finite() && y.is_finite()) {
                bail!("--{name} '{text}': map coordinates must be finite numbers");
            }
            return Ok(SensorSpec::Map { x, y });
        }
    }
    match text.rsplit_once(':') {
        Some((id, ch)) if !id.trim().is_empty() => {
            let c: f64 = ch
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .with_context(|| {
                    format!("--{name} '{text}': the chainage '{ch}' is not a number of metres")
                })?;
            Ok(SensorSpec::OnSegment {
                segment_id: id.trim().to_string(),
                chainage_m: c,
            })
        }
        _ => bail!("--{name} '{text}': expected SEGMENT:CHAINAGE (e.g. WM10231:12.5) or X,Y"),
    }
}

fn recording(text: &str) -> anyhow::Result<(PathBuf, u16)> {
    if let Some((f, c)) = text.rsplit_once(':') {
        if let Ok(c) = c.parse::<u16>() {
            return Ok((PathBuf::from(f), c));
        }
    }
    Ok((PathBuf::from(text), 0))
}

/// The one-line answer.
pub fn summary_line(l: &Located) -> String {
    format!(
        "leak at {:.1} m from sensor 1 (95 %: {:.1}–{:.1} m) on {}; table speed would say {:.1} m",
        l.distance_m, l.lo_m, l.hi_m, l.leak_segment, l.table_distance_m
    )
}

fn detail(l: &Located) -> String {
    let largest = l
        .budget
        .first()
        .map(|t| format!("{} (±{:.2} m)", t.name, t.shift_m.abs()))
        .unwrap_or_default();
    format!(
        "  chainage {:.2} m on {} (span {:.1} m via {}); delay {:.6} s ± {:.2e} s in {:.0}–{:.0} Hz ({}); \
         largest error: {largest}: {}",
        l.leak_chainage_m,
        l.leak_segment,
        l.span_m,
        l.path_ids.join(", "),
        l.delay_s,
        l.delay_std_s,
        l.band_used_hz.0,
        l.band_used_hz.1,
        l.band_note,
        l.advice
    )
}

/// One job's answer, its failure worded for the command line or the jobs file.
fn answer(locator: &mut Locator<'_>, job: Result<Job, RowFailure>, single: bool) -> Answer {
    let job = job?;
    locator.locate(&job).map_err(|e| RowFailure {
        job_id: job.id.clone(),
        message: if single {
            e.to_string()
        } else {
            format!("{} line {}: {e}", job.source.display(), job.line)
        },
    })
}

/// Locate every job, in order, on `threads` workers: the first uses `locator`, each other its
/// own connection to the database and its own locator, over a contiguous share of the rows.
/// Every row is located alone, so the answers do not depend on the number of workers.
fn locate_all(
    args: &LocateArgs,
    mut locator: Locator<'_>,
    options: &LocateOptions,
    jobs: Vec<Result<Job, RowFailure>>,
    threads: usize,
    single: bool,
) -> anyhow::Result<Vec<Answer>> {
    if threads <= 1 {
        return Ok(jobs
            .into_iter()
            .map(|j| answer(&mut locator, j, single))
            .collect());
    }
    let share = jobs.len().div_ceil(threads);
    let mut chunks: Vec<Vec<Result<Job, RowFailure>>> = Vec::new();
    let mut rest = jobs.into_iter();
    loop {
        let c: Vec<_> = rest.by_ref().take(share).collect();
        if c.is_empty() {
            break;
        }
        chunks.push(c);
    }
    let mut chunks = chunks.into_iter();
    let first = chunks.next().unwrap_or_default();
    std::thread::scope(|scope| {
        let workers: Vec<_> = chunks
            .map(|chunk| {
                scope.spawn(move || -> anyhow::Result<Vec<Answer>> {
                    let db = open_database(&args.db)?;
                    let mut own = Locator::new(db.conn(), options.clone(), args.join_tolerance)
                        .with_context(|| {
                            format!("cannot read the network of {}", args.db.display())
                        })?;
                    Ok(chunk
                        .into_iter()
                        .map(|j| answer(&mut own, j, single))
                        .collect())
                })
            })
            .collect();
        let mut all: Vec<Answer> = first
            .into_iter()
            .map(|j| answer(&mut locator, j, single))
            .collect();
        for w in workers {
            match w.join() {
                Ok(part) => all.extend(part?),
                Err(p) => std::panic::resume_unwind(p),
            }
        }
        Ok(all)
    })
}

/// Locate the correlations and write the answers.
pub fn run(args: &LocateArgs) -> anyhow::Result<Outcome> {
    let (input, threads) = match (&args.input, &args.jobs) {
        (Some(_), Some(JobsArg::File(f))) => bail!(
            "--jobs '{}' is not a number of worker threads (the jobs file is --input FILE, given \
             already)",
            f.display()
        ),
        (_, Some(JobsArg::File(f))) => {
            if args.sensor1.is_some()
                || args.sensor2.is_some()
                || args.delay.is_some()
                || args.recording1.is_some()
            {
                bail!(
                    "--jobs '{}' reads as a jobs file, which cannot be combined with a single \
                     correlation (--sensor1, --sensor2, --delay, --recording1); --jobs N is the \
                     number of worker threads",
                    f.display()
                );
            }
            eprintln!(
                "note: reading {} as the jobs file: that option is now --input FILE; --jobs N \
                 sets the worker threads, as in every other command",
                escape_controls(&f.display().to_string())
            );
            (Some(f.clone()), None)
        }
        (i, Some(JobsArg::Threads(n))) => (i.clone(), Some(*n as usize)),
        (i, None) => (i.clone(), None),
    };
    let mut outputs: Vec<(&std::path::Path, Contents)> = Vec::new();
    outputs.extend(args.out.as_deref().map(|p| (p, Contents::Plain)));
    outputs.extend(args.geojson.as_deref().map(|p| (p, Contents::Plain)));
    outputs.extend(args.gpkg.as_deref().map(|p| (p, Contents::GeoPackage)));
    let inputs: Vec<&std::path::Path> = input.as_deref().into_iter().collect();
    super::guard_outputs(Some(&args.db), &inputs, &outputs)?;
    let weighting: Weighting = args.weighting.parse().map_err(anyhow::Error::msg)?;
    let given_weighting: Weighting = args.given_weighting.parse().map_err(anyhow::Error::msg)?;
    let band = args.band.unwrap_or(DEFAULT_BAND_HZ);
    let single = input.is_none();
    let jobs: Vec<Result<Job, RowFailure>> = match &input {
        Some(file) => {
            if args.out.is_none() {
                bail!("--input needs --out FILE for the answers");
            }
            read_jobs(file)?
        }
        None => {
            let (Some(s1), Some(s2)) = (&args.sensor1, &args.sensor2) else {
                bail!(
                    "give --input FILE --out FILE, or one correlation: --sensor1 ID:M --sensor2 \
                     ID:M with --delay S --delay-std S or --recording1 FILE:CH --recording2 FILE:CH"
                );
            };
            let delay = match (
                args.delay,
                args.delay_std,
                &args.recording1,
                &args.recording2,
            ) {
                (Some(d), Some(s), None, _) => DelayInput::Given {
                    delay_s: d,
                    std_s: s,
                },
                (None, _, Some(r1), Some(r2)) => {
                    let ((file1, channel1), (file2, channel2)) = (recording(r1)?, recording(r2)?);
                    DelayInput::Recordings(RecordingPair {
                        file1,
                        channel1,
                        file2,
                        channel2,
                    })
                }
                _ => bail!("give --delay S --delay-std S, or --recording1 and --recording2"),
            };
            vec![Ok(Job {
                id: "1".into(),
                source: PathBuf::from("the command line"),
                line: 0,
                sensor1: sensor(s1, "sensor1")?,
                sensor2: sensor(s2, "sensor2")?,
                delay,
                band_hz: None,
                path: args
                    .path
                    .as_ref()
                    .map(|p| p.split(',').map(|s| s.trim().to_string()).collect()),
            })]
        }
    };
    // The recordings the jobs name are inputs too: no output may replace one.
    let recordings: Vec<&std::path::Path> = jobs
        .iter()
        .filter_map(|j| match j {
            Ok(Job {
                delay: DelayInput::Recordings(r),
                ..
            }) => Some([r.file1.as_path(), r.file2.as_path()]),
            _ => None,
        })
        .flatten()
        .collect();
    super::guard_outputs(None, &recordings, &outputs)?;
    let db = open_database(&args.db)?;
    let options = LocateOptions {
        band_hz: band,
        weighting,
        given_weighting,
        snap_tolerance_m: args.snap_tolerance,
        span_std_fraction: args.span_std_fraction,
        ..LocateOptions::default()
    };
    let locator = Locator::new(db.conn(), options.clone(), args.join_tolerance)
        .with_context(|| format!("cannot read the network of {}", args.db.display()))?;
    let srid = locator.network.srid;
    let threads = threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from))
        .clamp(1, jobs.len().max(1));
    let answers = locate_all(args, locator, &options, jobs, threads, single)?;
    if single {
        match &answers[0] {
            Ok(l) => {
                // Segment and job ids come from the user's files: their control characters are
                // escaped, as in every message.
                println!("{}", escape_controls(&summary_line(l)));
                println!("{}", escape_controls(&detail(l)));
                for n in &l.notes {
                    println!("  note: {}", escape_controls(n));
                }
            }
            Err(f) => bail!("{}", f.message),
        }
    }
    if let Some(out) = &args.out {
        write_csv(out, &answers).map_err(anyhow::Error::msg)?;
    }
    let mut warnings = Vec::new();
    if let Some(p) = &args.geojson {
        warnings.extend(write_geojson(p, &answers, srid).map_err(anyhow::Error::msg)?);
    }
    if let Some(p) = &args.gpkg {
        warnings.extend(write_gpkg(p, &answers, srid).map_err(anyhow::Error::msg)?);
    }
    for w in &warnings {
        eprintln!("warning: {}", escape_controls(w));
    }
    let failed: Vec<&RowFailure> = answers.iter().filter_map(|a| a.as_ref().err()).collect();
    if !single {
        for f in &failed {
            eprintln!(
                "{}",
                escape_controls(&format!("job {}: {}", f.job_id, f.message))
            );
        }
        let line = format!(
            "locate: {} of {} jobs located, {} failed{}",
            answers.len() - failed.len(),
            answers.len(),
            failed.len(),
            args.out
                .as_ref()
                .map(|o| format!("; answers in {}", o.display()))
                .unwrap_or_default()
        );
        println!("{}", escape_controls(&line));
    }
    Ok(if failed.is_empty() {
        Outcome::Done
    } else {
        Outcome::SomeFailed
    })
}
