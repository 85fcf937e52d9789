//! `pipewave import --db DB [--segments FILE] [--layer NAME] [--map COLUMN=FIELD]...
//! [--measurements FILE] [--skip-invalid] [--strict]`.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use pipewave::db::{self, Database, ImportOptions, ImportReport, ImportSource};
use pipewave::units::escape_controls;

use super::Outcome;

/// Arguments of `import`.
#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("files").required(true).multiple(true).args(["segments", "measurements"]))]
pub struct ImportArgs {
    /// The database (created if it does not exist).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// Inventory of pipe segments: segments.csv, or a GIS layer (GeoPackage .gpkg, GeoJSON
    /// .geojson, ESRI Shapefile .shp with its .dbf and .prj).
    #[arg(long, value_name = "FILE")]
    segments: Option<PathBuf>,
    /// The layer of a GeoPackage that holds several.
    #[arg(long, value_name = "NAME")]
    layer: Option<String>,
    /// The file's field for one of pipewave's columns, e.g. --map segment_id=ASSET_ID
    /// (repeatable).
    #[arg(long = "map", value_name = "COLUMN=FIELD", value_parser = parse_map)]
    map: Vec<(String, String)>,
    /// Reject columns pipewave does not know, instead of ignoring them with a note.
    #[arg(long)]
    strict: bool,
    /// Field wavenumbers (measurements.csv); their segments must be in the database or in
    /// --segments.
    #[arg(long, value_name = "FILE")]
    measurements: Option<PathBuf>,
    /// Import the valid rows and report the invalid ones, instead of importing nothing.
    #[arg(long)]
    skip_invalid: bool,
    /// EPSG code of the coordinates when the file does not name its CRS: a GeoJSON without
    /// `crs` (otherwise WGS 84), CSV geometry without a srid column.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(i64).range(1..))]
    srid: Option<i64>,
}

/// Read the files, import, print each bad row on stderr and a summary on stdout.
pub fn run(args: &ImportArgs) -> anyhow::Result<Outcome> {
    // Read the inputs before touching the database, so a mistyped path creates no file.
    let segments = args
        .segments
        .as_deref()
        .map(ImportSource::from_path)
        .transpose()?;
    let measurements = args
        .measurements
        .as_deref()
        .map(ImportSource::from_path)
        .transpose()?;
    let mut database = Database::open(&args.db)?;
    let report = db::import(
        database.conn_mut(),
        segments.as_ref(),
        measurements.as_ref(),
        ImportOptions {
            skip_invalid: args.skip_invalid,
            strict: args.strict,
            layer: args.layer.clone(),
            map: args.map.clone(),
            srid: args.srid,
        },
    )
    .with_context(|| {
        format!(
            "import into {} failed; nothing was written",
            args.db.display()
        )
    })?;
    for n in &report.notes {
        eprintln!("note: {}", escape_controls(n));
    }
    for e in &report.errors {
        eprintln!("{e}");
    }
    let n_bad = report.problems;
    if n_bad > report.errors.len() {
        eprintln!(
            "... and {} more problems (the first {} are listed)",
            n_bad - report.errors.len(),
            report.errors.len()
        );
    }
    if report.rejected {
        let hint = if report.unusable_file {
            "a file as a whole is unusable, see above; --skip-invalid does not help with that"
        } else {
            "fix the rows above, or use --skip-invalid to import the valid rows"
        };
        bail!(
            "import rejected: {n_bad} problem{} found, nothing was written ({hint})",
            plural(n_bad)
        );
    }
    println!("{}", summary(&report));
    if n_bad > 0 {
        eprintln!(
            "skipped {n_bad} invalid row{} (listed above); the valid rows were imported",
            plural(n_bad)
        );
    }
    Ok(Outcome::Done)
}

/// `COLUMN=FIELD`, COLUMN one of pipewave's columns.
fn parse_map(s: &str) -> Result<(String, String), String> {
    let (c, f) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not COLUMN=FIELD (such as segment_id=ASSET_ID)"))?;
    let (c, f) = (c.trim(), f.trim());
    let known = db::known_columns();
    if !known.iter().any(|k| k.eq_ignore_ascii_case(c)) {
        return Err(format!(
            "'{c}' is not a pipewave column; the columns are: {}",
            known.join(", ")
        ));
    }
    if f.is_empty() {
        return Err(format!("--map {c}=: the field name is missing"));
    }
    Ok((c.to_ascii_lowercase(), f.to_string()))
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// The one-line summary of an import.
pub(super) fn summary(r: &ImportReport) -> String {
    format!(
        "imported: segments {} new, {} updated, {} unchanged; measurements {} written for {} \
         segment{}; fit inputs changed for {} segment{}",
        r.segments_inserted,
        r.segments_updated,
        r.segments_unchanged,
        r.measurements_written,
        r.segments_with_changed_measurements,
        plural(r.segments_with_changed_measurements),
        r.segments_with_changed_inputs,
        plural(r.segments_with_changed_inputs),
    )
}
