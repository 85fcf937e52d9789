//! `pipewave synth --out DIR [--segments N] [--seed S] [--defects FRACTION] [--no-real-cases]
//! [--force] [--units N [--correlation-length M]] [--measured-fraction F] [--wrong-labels F]
//! [--campaign-out FILE] [--campaigns 2 [--changed-fraction F]]`: write a synthetic network
//! directory.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use pipewave::outfile::Contents;
use pipewave::synth::network::{
    published, NetworkTables, MEASUREMENTS_CSV, SEGMENTS_CSV, TRUTH_CSV,
};
use pipewave::synth::{generate, SynthOptions, NOISE_ATTENUATION, NOISE_K_RE};

use super::{bounds, Outcome};

/// Sub-directory of the network that holds copies of the published data files.
pub const REAL_DIR: &str = "real";

/// Arguments of `synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Directory to write segments.csv, measurements.csv, truth.csv (and real/) into; created
    /// if missing.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of synthetic segments. Range 1 – 1000000.
    #[arg(long, value_name = "N", default_value_t = 200,
          value_parser = bounds::count(1, bounds::MAX_SEGMENTS))]
    segments: u32,
    /// Seed of the generator (the same seed gives the same files). Range 0 – 2^64 − 1.
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Fraction of segments given a deliberate defect (outlier, attenuation in dB/m, wrong
    /// material, a single frequency), 0 - 1.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.03, value_parser = bounds::fraction())]
    defects: f64,
    /// Leave out the two published field cases (Lu et al. 2022; Muggleton et al. 2004).
    #[arg(long)]
    no_real_cases: bool,
    /// Replace the files if they exist.
    #[arg(long)]
    force: bool,
    /// Hide an effect in the data (for testing `diagnose`): soil_damping, air_in_water,
    /// wall_thinning or pipe_loss. Its value is in truth.csv.
    #[arg(long, value_name = "NAME")]
    hidden_effect: Option<String>,
    /// Value range of the hidden effect, LO,HI (default: one whose signature shows at the
    /// synthetic noise in some segments). Range: LO < HI, both inside the range of the effect's
    /// parameter.
    #[arg(long, value_name = "LO,HI", requires = "hidden_effect")]
    hidden_range: Option<String>,
    /// Fraction of the synthetic segments given the hidden effect (the rest are controls), 0 -
    /// 1.
    #[arg(
        long,
        value_name = "FRACTION",
        default_value_t = 1.0,
        requires = "hidden_effect",
        value_parser = bounds::fraction()
    )]
    hidden_fraction: f64,
    /// Also write hydrant-test recordings of these segments (comma-separated ids) into
    /// DIR/recordings/: layout.csv, one WAV per segment, truth_wavenumbers.csv.
    #[arg(long, value_name = "ID,...")]
    recordings: Option<String>,
    /// Write only the recordings, not segments.csv, measurements.csv and truth.csv.
    #[arg(long, requires = "recordings")]
    recordings_only: bool,
    /// Length of each recording, s. Range 6 – 600 s.
    #[arg(long, value_name = "S", requires = "recordings",
          default_value_t = pipewave::synth::recordings::DEFAULT_SECONDS,
          value_parser = recording_seconds)]
    recording_seconds: f64,
    /// Split the synthetic segments into N soil zones (contiguous blocks of streets), each one
    /// soil with a scatter per segment of 0.04 decade in E_m (about 10 %) and 0.01 in ν_m;
    /// the zone is written to segments.csv (`soil_zone`) and its true soil to truth.csv.
    /// Range 0 – --segments.
    #[arg(long, value_name = "N", default_value_t = 0,
          value_parser = bounds::count(0, bounds::MAX_SEGMENTS))]
    zones: u32,
    /// Also write N two-sensor leak recordings on paths of 1-4 segments into DIR/leaks/
    /// (jobs.csv for `locate`, one WAV per job, leaks_truth.csv), made from the true soils.
    /// Range 1 – 1000.
    #[arg(long, value_name = "N", value_parser = bounds::count(1, MAX_LEAKS))]
    leaks: Option<u32>,
    /// Length of each leak recording, s. Range 1 – 600 s.
    #[arg(long, value_name = "S", requires = "leaks",
          default_value_t = pipewave::synth::locate::DEFAULT_LEAK_SECONDS,
          value_parser = bounds::real(MIN_LEAK_SECONDS, MAX_LEAK_SECONDS, "s"))]
    leak_seconds: f64,
    /// Geological units: split the map into N contiguous units (a Voronoi partition), from
    /// soft to stiff ground, each with a soil that varies smoothly inside it (a Gaussian field
    /// of the soil's wave speeds, model §7.12); the unit is in truth.csv. Range 0 – --segments.
    #[arg(long, value_name = "N", default_value_t = 0,
          value_parser = bounds::count(0, bounds::MAX_SEGMENTS))]
    units: u32,
    /// Correlation length of the soil field inside the units, m (with --units; default 350).
    /// Range 1 – 100,000 m.
    #[arg(long, value_name = "M",
          value_parser = bounds::real(MIN_CORRELATION_LENGTH_M, MAX_CORRELATION_LENGTH_M, "m"))]
    correlation_length: Option<f64>,
    /// Keep the measurements of this fraction of the synthetic segments only (0 - 1, exactly
    /// round(F n) segments); truth.csv still describes every segment.
    #[arg(long, value_name = "F", default_value_t = 1.0, value_parser = bounds::fraction())]
    measured_fraction: f64,
    /// Give this fraction of the synthetic segments a wrong soil_type label (0 - 1): another
    /// unit's class, or another class without --units.
    #[arg(long, value_name = "F", default_value_t = 0.0, value_parser = bounds::fraction())]
    wrong_labels: f64,
    /// Also write every synthetic segment's measurements (campaign `later`) to FILE, in the
    /// measurements.csv format: what a later campaign would measure on any segment, for
    /// `import --measurements` of the segments chosen (e.g. by `plan`).
    #[arg(long, value_name = "FILE")]
    campaign_out: Option<PathBuf>,
    /// Campaigns of measurements, 1 – 2. With 2, every measured segment is measured again a
    /// year later at the same frequencies with fresh noise (campaigns FD-2026 and FD-2027,
    /// dated), some pipes having changed in between (--changed-fraction); truth.csv then
    /// states each change and its detectability.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = bounds::count(1, pipewave::synth::MAX_CAMPAIGNS))]
    campaigns: u32,
    /// With --campaigns 2: fraction of the measured segments whose pipe changed between the
    /// campaigns (exactly round(F m) of the m measured), 0 – 1 (default 0.3). The cause is
    /// drawn among soil_change, air_in_water, wall_thinning (iron, steel, AC) and pipe_loss.
    #[arg(long, value_name = "F", value_parser = bounds::fraction())]
    changed_fraction: Option<f64>,
}

/// Most leak recordings (`--leaks`): each takes about a second to make at the longest length.
const MAX_LEAKS: u32 = 1000;
/// Shortest leak recording, s: the delay's error falls as 1/√(T B) (P87), and a second of a
/// 700-Hz band already gives T B = 700.
const MIN_LEAK_SECONDS: f64 = 1.0;
/// Longest leak recording, s: both channels are held in memory while they are made (600 s at
/// 8 kHz is about 180 MB), as for the hydrant-test recordings.
const MAX_LEAK_SECONDS: f64 = pipewave::synth::recordings::MAX_RECORDING_S;
/// Shortest correlation length of the soil field inside a unit, m: below a metre the field
/// varies within a segment, which the per-segment scatter already stands for.
const MIN_CORRELATION_LENGTH_M: f64 = 1.0;
/// Longest correlation length, m: beyond 100 km the field is one soil over any utility's
/// network.
const MAX_CORRELATION_LENGTH_M: f64 = 100_000.0;

/// Campaign name of the measurements `--campaign-out` writes.
pub const LATER_CAMPAIGN: &str = "later";
/// `--recording-seconds`: a length `wavenumbers` can analyse, and a bounded one.
fn recording_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number of seconds"))?;
    pipewave::synth::recordings::check_recording_seconds(v)
}

/// Generate and write the network.
pub fn run(args: &SynthArgs) -> anyhow::Result<Outcome> {
    let network_files: Vec<PathBuf> = [SEGMENTS_CSV, MEASUREMENTS_CSV, TRUTH_CSV]
        .iter()
        .map(|n| args.out.join(n))
        .collect();
    let mut outputs: Vec<(&Path, Contents)> = network_files
        .iter()
        .map(|p| (p.as_path(), Contents::Plain))
        .collect();
    outputs.extend(args.campaign_out.as_deref().map(|p| (p, Contents::Plain)));
    super::guard_outputs(None, &[], &outputs)?;
    if !args.force && !args.recordings_only {
        for name in [SEGMENTS_CSV, MEASUREMENTS_CSV, TRUTH_CSV] {
            let p = args.out.join(name);
            if p.exists() {
                bail!(
                    "{} already exists; use --force to replace it (or choose another --out)",
                    p.display()
                );
            }
        }
    }
    let hidden_effect = match &args.hidden_effect {
        None => None,
        Some(name) => {
            let e: pipewave::physics::effects::Effect = name.parse().context("--hidden-effect")?;
            let range = match &args.hidden_range {
                Some(t) => {
                    let v: Vec<f64> = t
                        .split(',')
                        .map(|x| x.trim().parse::<f64>())
                        .collect::<Result<_, _>>()
                        .with_context(|| format!("--hidden-range '{t}': expected LO,HI"))?;
                    match v[..] {
                        [lo, hi] if lo < hi => (lo, hi),
                        _ => bail!("--hidden-range '{t}': expected LO,HI with LO < HI"),
                    }
                }
                None => pipewave::synth::default_hidden_range(e).with_context(|| {
                    format!("{e} has no parameter to hide (generate with full, fit with --model seed instead)")
                })?,
            };
            let p = e.parameter().context("effect without parameter")?;
            if range.0 < p.lower || range.1 > p.upper {
                bail!(
                    "--hidden-range {},{} is outside the range of {} ({} - {})",
                    range.0,
                    range.1,
                    p.name,
                    p.lower,
                    p.upper
                );
            }
            Some((e, range.0, range.1))
        }
    };
    if args.units > 0 && args.zones > 0 {
        bail!("--units and --zones are two ways to give the soil a structure: choose one");
    }
    if args.correlation_length.is_some() && args.units == 0 {
        bail!("--correlation-length needs --units (it is the scale of the soil inside a unit)");
    }
    if args.changed_fraction.is_some() && args.campaigns < 2 {
        bail!("--changed-fraction needs --campaigns 2 (it is the share of pipes that changed between them)");
    }
    let correlation_length_m = args
        .correlation_length
        .unwrap_or(pipewave::synth::DEFAULT_CORRELATION_LENGTH_M);
    let opts = SynthOptions {
        segments: args.segments as usize,
        seed: args.seed,
        defect_fraction: args.defects,
        hidden_effect,
        hidden_fraction: args.hidden_fraction,
        zones: args.zones as usize,
        units: args.units as usize,
        correlation_length_m,
        measured_fraction: args.measured_fraction,
        wrong_label_fraction: args.wrong_labels,
        campaigns: args.campaigns as usize,
        changed_fraction: args
            .changed_fraction
            .unwrap_or(pipewave::synth::DEFAULT_CHANGED_FRACTION),
        ..SynthOptions::default()
    };
    if opts.zones > opts.segments {
        bail!(
            "--zones {} is more than --segments {} (every zone needs segments)",
            opts.zones,
            opts.segments
        );
    }
    if opts.units > opts.segments {
        bail!(
            "--units {} is more than --segments {} (every unit needs segments)",
            opts.units,
            opts.segments
        );
    }
    let synthetic = generate(&opts);
    if let Some(n) = args.leaks {
        let dir = args.out.join("leaks");
        let written = pipewave::synth::locate::write_leaks(
            &dir,
            &synthetic,
            &opts,
            n as usize,
            args.leak_seconds,
        )
        .map_err(anyhow::Error::msg)?;
        println!(
            "synth: wrote {written} leak recordings to {}",
            dir.display()
        );
    }
    if let Some(ids) = &args.recordings {
        let ids: Vec<String> = ids.split(',').map(|s| s.trim().to_string()).collect();
        let rec = pipewave::synth::recordings::record_network_segments(
            &synthetic,
            &opts,
            &ids,
            args.recording_seconds,
        )
        .map_err(anyhow::Error::msg)?;
        let dir = args.out.join("recordings");
        pipewave::synth::recordings::write_recordings(&dir, &rec)
            .with_context(|| format!("cannot write the recordings in {}", dir.display()))?;
        println!(
            "synth: wrote recordings of {} segments to {}",
            rec.len(),
            dir.display()
        );
        if args.recordings_only {
            return Ok(Outcome::Done);
        }
    }
    let mut tables = NetworkTables::from_synth(&synthetic, opts.srid);
    if !args.no_real_cases {
        for case in published::published_cases()? {
            tables.push_published(case);
        }
    }
    tables.write_dir(&args.out)?;
    if let Some(path) = &args.campaign_out {
        let campaign = NetworkTables::campaign(&synthetic, LATER_CAMPAIGN);
        pipewave::outfile::write_bytes(
            path,
            Contents::Plain,
            campaign.measurements_csv().as_bytes(),
        )
        .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if !args.no_real_cases {
        write_real_copies(&args.out.join(REAL_DIR))?;
    }
    let n_defects = synthetic
        .iter()
        .filter(|s| s.defect != pipewave::synth::Defect::None)
        .count();
    println!(
        "synth: wrote {} segments ({} synthetic, {} with a defect, {} published) and {} \
         measurements (noise {} % on Re k, {} % on attenuation) to {}",
        tables.segments.len(),
        synthetic.len(),
        n_defects,
        tables.segments.len() - synthetic.len(),
        tables.measurement_count(),
        100.0 * NOISE_K_RE,
        100.0 * NOISE_ATTENUATION,
        args.out.display()
    );
    let measured = synthetic.iter().filter(|s| s.measured).count();
    if measured < synthetic.len() {
        println!(
            "synth: measurements kept for {measured} of {} synthetic segments",
            synthetic.len()
        );
    }
    if opts.units > 0 || opts.wrong_label_fraction > 0.0 {
        println!(
            "synth: {} geological units (correlation length {} m), {} wrong soil_type labels",
            opts.units,
            opts.correlation_length_m,
            synthetic
                .iter()
                .filter(|s| s.soil_label != s.soil_type)
                .count()
        );
    }
    if opts.campaigns >= 2 {
        let second: Vec<&pipewave::synth::SecondCampaign> =
            synthetic.iter().filter_map(|s| s.second.as_ref()).collect();
        let changed: Vec<f64> = second
            .iter()
            .filter(|c| c.change != pipewave::synth::Change::None)
            .map(|c| c.change_z)
            .collect();
        println!(
            "synth: two campaigns ({} and {}) of {} segments; {} pipes changed between them, \
             {} of them detectable (z >= 3)",
            pipewave::synth::FIRST_CAMPAIGN,
            pipewave::synth::SECOND_CAMPAIGN,
            second.len(),
            changed.len(),
            changed.iter().filter(|&&z| z >= 3.0).count()
        );
    }
    if let Some(path) = &args.campaign_out {
        println!(
            "synth: wrote every synthetic segment's later-campaign measurements to {}",
            path.display()
        );
    }
    if synthetic.len() < opts.segments {
        eprintln!(
            "note: only {} of {} segments could be generated (the forward model failed for \
             the others)",
            synthetic.len(),
            opts.segments
        );
    }
    Ok(Outcome::Done)
}

/// Copy the published data files and their README, so the network stands alone.
fn write_real_copies(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for (name, body) in [
        ("seed_cast_iron_table2.csv", published::LU2022_CSV),
        (
            "muggleton2004_buried_mdpe.csv",
            published::MUGGLETON2004_CSV,
        ),
        ("README.md", published::README_MD),
    ] {
        let p = dir.join(name);
        pipewave::outfile::write_bytes(&p, Contents::Plain, body.as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}
