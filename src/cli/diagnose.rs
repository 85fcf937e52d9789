//! `pipewave diagnose --db DB [--segment ID]... --out DIR [--candidates NAME,...] [--no-apply]
//! [--group-by COLUMN] [--jobs N] [--convert-units ID=MIXUP]...`: the discrepancy workflow
//! (find, name, add, show).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use pipewave::diagnose::group::GroupBy;
use pipewave::diagnose::run::{diagnose_database, DiagnoseOptions};
use pipewave::diagnose::units::UnitMixUp;
use pipewave::physics::effects::{parse_effects, Effect};

use super::Outcome;

/// Arguments of `diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The database (its segments must have been calibrated).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// Diagnose only this segment (repeat for several; default: every fitted segment).
    #[arg(long = "segment", value_name = "ID")]
    segments: Vec<String>,
    /// Where to write diagnosis.csv (one row per segment), diagnosis.html (the report) and
    /// groups.csv (the pooled test of each group of pipes, see --group-by).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Candidate effects, comma-separated (default: all of soil_damping, air_in_water,
    /// wall_thinning, pipe_loss, full_model, viscoelastic_wall, inventory_error).
    #[arg(long, value_name = "NAME,...")]
    candidates: Option<String>,
    /// Report only: do not store the extended fits or switch the named effects on for the
    /// segments.
    #[arg(long)]
    no_apply: bool,
    /// Group the pooled test by this inventory column: soil_zone, material, soil_type or
    /// install_year (by decade); default: material x age class (30-year classes).
    #[arg(long, value_name = "COLUMN")]
    group_by: Option<String>,
    /// Confirm a unit mix-up the diagnosis names, and convert that segment's stored
    /// measurements (repeatable): ID=attenuation_db (attenuation recorded in dB/m),
    /// attenuation_over_db, omega_as_hz (frequency column holds rad/s) or hz_as_omega. Done only
    /// when the diagnosis of ID names that mix-up; the next calibrate refits the segment.
    #[arg(long = "convert-units", value_name = "ID=MIXUP")]
    convert_units: Vec<String>,
    /// Worker threads (default: one per core). Range 1 – 512.
    #[arg(long, value_name = "N", value_parser = super::bounds::jobs())]
    jobs: Option<u32>,
}

/// Skipped segments listed one line each; the rest are counted.
const SKIPPED_LISTED: usize = 20;

/// Run the diagnosis and print its summary.
pub fn run(args: &DiagnoseArgs) -> anyhow::Result<Outcome> {
    let candidates = match &args.candidates {
        Some(t) => parse_effects(t).context("--candidates")?,
        None => Effect::ALL.to_vec(),
    };
    let group_by = match &args.group_by {
        Some(c) => c
            .parse::<GroupBy>()
            .map_err(|e| anyhow::anyhow!("--group-by: {e}"))?,
        None => GroupBy::default(),
    };
    let convert_units = args
        .convert_units
        .iter()
        .map(|t| {
            let (id, mix) = t
                .rsplit_once('=')
                .ok_or_else(|| anyhow::anyhow!("--convert-units {t:?}: expected ID=MIXUP"))?;
            let mix = mix
                .parse::<UnitMixUp>()
                .map_err(|e| anyhow::anyhow!("--convert-units {t:?}: {e}"))?;
            Ok((id.to_string(), mix))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let reports: Vec<std::path::PathBuf> = ["diagnosis.csv", "groups.csv", "diagnosis.html"]
        .iter()
        .map(|n| args.out.join(n))
        .collect();
    let outputs: Vec<(&std::path::Path, pipewave::outfile::Contents)> = reports
        .iter()
        .map(|p| (p.as_path(), pipewave::outfile::Contents::Plain))
        .collect();
    super::guard_outputs(Some(&args.db), &[], &outputs)?;
    let mut database = super::open_database(&args.db)?;
    let opts = DiagnoseOptions {
        segments: (!args.segments.is_empty()).then(|| args.segments.clone()),
        jobs: args
            .jobs
            .map(|j| j as usize)
            .unwrap_or_else(pipewave::batch::default_jobs),
        apply: !args.no_apply,
        candidates,
        out_dir: args.out.clone(),
        group_by,
        convert_units,
    };
    let s = diagnose_database(database.conn_mut(), &opts)?;
    for (id, why) in s.skipped.iter().take(SKIPPED_LISTED) {
        eprintln!("{}: segment {id}: skipped: {why}", args.db.display());
    }
    if s.skipped.len() > SKIPPED_LISTED {
        eprintln!(
            "{}: {} more segments skipped (the first {SKIPPED_LISTED} are listed above)",
            args.db.display(),
            s.skipped.len() - SKIPPED_LISTED
        );
    }
    println!("{}", s.line());
    for (id, what) in &s.conversions {
        println!("{id}: {what}");
    }
    println!(
        "report: {}, {} and {}",
        args.out.join("diagnosis.csv").display(),
        args.out.join("groups.csv").display(),
        args.out.join("diagnosis.html").display()
    );
    Ok(Outcome::Done)
}
