//! `pipewave import --db DB [--segments FILE] [--layer NAME] [--map COLUMN=FIELD]...
//! [--measurements FILE] [--skip-invalid] [--strict]`.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use pipewave::db::{self, ImportOptions, ImportReport, ImportSource};
use pipewave::units::escape_controls;

use super::Outcome;

/// The input formats, shown by `pipewave import --help` (and in docs/your-own-data.md, which
/// says the same at more length). The example files import as they stand.
const FORMATS: &str = "\
YOUR OWN DATA
Two CSV files (comma-separated, UTF-8, one header row). Columns may come in any order; column
names are matched case-insensitively; columns pipewave does not know are ignored with one note
(--strict rejects them); --map COLUMN=FIELD names your field for one of pipewave's columns.
Units are SI unless the column name says otherwise (_mm, _hz).

segments.csv: one row per pipe segment
  segment_id            required  text, unique: your asset id (GIS FACILITYID)
  material              required  CI grey cast iron, DI ductile iron, ST steel, PVC (uPVC),
                                  MDPE, HDPE, AC asbestos cement; also understood, any case:
                                  Cast Iron, Grey Iron, Ductile Iron, DICL, Steel, MSCL, uPVC,
                                  PVC-U, PE80 (= MDPE), PE100 (= HDPE), Asbestos Cement, ...
  outer_diameter_mm     required  outside diameter, mm, > 0; mean radius a = (D - h)/2 within
                                  5-1500 mm
  wall_thickness_mm     required  wall thickness h, mm, > 0 and < outer_diameter_mm / 2, with
                                  0.005 <= h/a <= 0.25 (the thin-shell model's walls)
  soil_density_kg_m3    required  soil bulk density, kg/m3, 1000-2600 (from a soil test; not
                                  fitted; most soils lie between 1600 and 2200)
  pipe_youngs_modulus_pa, pipe_poisson, pipe_density_kg_m3, pipe_loss_factor
                        optional  override the material's typical values: 1e8-3e11 Pa,
                                  0-0.49, 500-9000 kg/m3, 0-0.3
  fluid_density_kg_m3, fluid_bulk_modulus_pa
                        optional  default water: 1000 kg/m3, 2.25e9 Pa; 500-1100 kg/m3,
                                  1e6-2.5e9 Pa
  length_m, soil_type, install_year
                        optional  informational: m, > 0 and <= 100000; text; year 1600-2100
  soil_zone             optional  text: the soil unit the segment lies in
  risk_weight           optional  0-1e9: the segment's weight in plan (default: its length, m)
  soil_class_override   optional  text: the soil class the field must use for the segment
  geometry_wkt, srid    optional  LINESTRING (x y, x y, ...) in EPSG:srid (for the maps): a
                                  known EPSG code, two distinct points or more, |lon| <= 180
                                  and |lat| <= 90 (geographic), |x|, |y| <= 1e8 (projected)

measurements.csv: one row per segment, campaign and frequency (field wavenumbers)
  segment_id            required  must be in the inventory (this file's segments or earlier)
  frequency_hz          one of    frequency, Hz, > 0
  omega_rad_s             these   angular frequency, rad/s, > 0 (not both); 2 pi f within
                                  1e-6-1e7 rad/s
  k_re_rad_per_m        required  real part of the measured wavenumber, rad/m, 1e-9-1e4
                                  (phase speed = 2 pi f / k_re)
  attenuation_np_per_m  required  decay rate, Np/m, 0-1e3 (positive, as in field reports;
                                  1 Np/m = 8.686 dB/m)
  k_re_std, attenuation_std
                        optional  one standard deviation of each, same units, <= 1e6 and
                                  >= 1e-6 k_re (without them the fit assumes the noise and
                                  chi2/dof is not defined)
  measured_on, campaign optional  ISO date, text (blank campaign: `unnamed`); a campaign
                                  imported again updates its rows, a new one is added beside
                                  the earlier ones (--replace-campaign NAME deletes the rows
                                  of NAME that the file does not hold)
  note                  optional  text (the wavenumber estimate's band notes)

Example segments.csv:
  segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,geometry_wkt,srid
  MAIN-0001,Ductile Iron,118,6,1900,\"LINESTRING (441800 111900, 441920 111900)\",27700

Example measurements.csv:
  segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m,k_re_std,attenuation_std
  MAIN-0001,224,1.0519,0.00203,0.0105,0.00011
  MAIN-0001,360,1.6682,0.00346,0.0168,0.00015

A file with any invalid row imports nothing and lists the bad rows (file, line, column, what
was expected); --skip-invalid imports the valid rows. Re-importing the same file changes
nothing. Then: pipewave calibrate --db DB.";

/// Arguments of `import`.
#[derive(Debug, Args)]
#[command(after_long_help = FORMATS)]
#[command(
    after_help = "The columns, units and material codes of the files, with examples: `pipewave import --help`."
)]
#[command(group = clap::ArgGroup::new("files").required(true).multiple(true).args(["segments", "measurements"]))]
pub struct ImportArgs {
    /// The database (created if it does not exist); `pipewave calibrate --db DB` fits what is
    /// imported into it.
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
    /// Make the measurements file the whole of campaign NAME: its stored rows that the file
    /// does not hold are deleted (repeatable). Without it nothing stored is ever deleted: a
    /// re-imported campaign updates its rows and keeps the others, and a new campaign adds rows
    /// beside the earlier ones.
    #[arg(
        long = "replace-campaign",
        value_name = "NAME",
        requires = "measurements"
    )]
    replace_campaign: Vec<String>,
    /// EPSG code of the coordinates when the file does not name its CRS: a GeoJSON without
    /// `crs` (otherwise WGS 84), CSV geometry without a srid column. Range 1 – 2147483647.
    #[arg(long, value_name = "N", value_parser = super::bounds::srid())]
    srid: Option<i64>,
}

/// Read the files, import, print each bad row on stderr and a summary on stdout.
pub fn run(args: &ImportArgs) -> anyhow::Result<Outcome> {
    let inputs: Vec<&std::path::Path> = [args.segments.as_deref(), args.measurements.as_deref()]
        .into_iter()
        .flatten()
        .collect();
    super::guard_database(&args.db, &inputs)?;
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
    let mut database = super::create_database(&args.db)?;
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
            replace_campaigns: args.replace_campaign.clone(),
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
        bail!(
            "import rejected: {n_bad} problem{} found, nothing was written ({})",
            plural(n_bad),
            rejected_hint(&report, "use --skip-invalid to import the valid rows")
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

/// What to do about a rejected import: a file unusable as a whole (a required column missing,
/// not a CSV) cannot be helped by skipping rows; bad rows can, as `skip` says.
pub(super) fn rejected_hint(report: &ImportReport, skip: &str) -> String {
    if report.unusable_file {
        "a file as a whole is unusable, see above; --skip-invalid does not help with that"
            .to_string()
    } else {
        format!("fix the rows above, or {skip}")
    }
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

/// The one-line summary of an import, ending with what it did to each campaign the
/// measurements file held.
pub(super) fn summary(r: &ImportReport) -> String {
    let mut out = headline(r);
    for (name, c) in &r.campaigns {
        out.push_str(&format!(
            "; campaign {}: {} rows added, {} updated, {} kept{}",
            escape_controls(name),
            c.added,
            c.updated,
            c.kept,
            if c.removed > 0 {
                format!(", {} removed (--replace-campaign)", c.removed)
            } else {
                String::new()
            }
        ));
    }
    out
}

fn headline(r: &ImportReport) -> String {
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
