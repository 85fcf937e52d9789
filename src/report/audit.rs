//! The network audit report (`pipewave audit`): one self-contained HTML page (inline CSS and
//! SVG, no script, nothing fetched), leading with what a water utility needs.
//!
//! Sections (each a `<section id=...>`), in order: `trust` (how many predictions are
//! trustworthy, status `ok`, and the flags that need action, each with its advice), `actions`
//! (every flagged or failed segment with its flags, what to do and its speed ± error, longest
//! pipe first: what a wrong speed would cost), `changes` (what changed since the last
//! campaign: the change test's findings by cause, the changed pipes and a map), `map`
//! (segments coloured by the leak-band wave speed, and a second map of its relative error),
//! `least-certain` (the segments whose leak-band speed is least certain), `soil-speeds` (the
//! soil's c_P and c_S by soil type, with errors), `notes` (what the data leave undetermined,
//! summarised), then fit quality: `summary` (misfit statistics, runs), `misfit`
//! (distribution), `speed-diameter` (wave speed against diameter by material), `worst-fits`
//! (the worst fits, each with its measured points over the fitted curves), `failed` (segments
//! without a fit).
//!
//! The report streams: one pass over the records ([`Records`], a page at a time) tallies what
//! the sections show, keeping a few numbers per segment and never a curve; a second pass over
//! the geometries alone draws the map; the worst fits are read again for their curves.
//!
//! Everything aggregates, so the page reads the same for 200 or 20,000 segments: see
//! [`svg::MAP_TOOLTIP_LIMIT`], [`charts::SCATTER_LIMIT`], [`WORST_FITS`], [`FAILED_LISTED`],
//! [`LEAST_CERTAIN_LISTED`], [`SOIL_TYPES_SHOWN`].

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

use super::charts::{self, ChartError, SoilSpeeds, SpeedPoint, WithStd};
use super::svg::{self, escape, ColourScale, MapCanvas, MapLine, MapStyle};
use crate::db::crs;
use crate::db::wkt::LineString;
use crate::db::zones::ZoneFitRow;
use crate::db::{self, Database, FitStatus, RunRow};
use crate::export::gpkg::CommonGeometry;
use crate::export::numbers;
use crate::export::record::UNFITTED;
use crate::export::{
    check_out_path, write_file_atomically, ExportError, ExportSummary, Records, SegmentExport,
    PAGE_SIZE,
};
use crate::invert::flags::{SPEED_DETERMINED_RSTD, SPEED_RSTD_MAX};
use crate::invert::FlagCode;
use crate::stats::{quantile, sorted_finite};
use crate::types::Trust;
use crate::units::{np_to_db, sig};
use crate::zones::ZoneFlag;

/// The worst fits shown with their curves.
pub const WORST_FITS: usize = 12;
/// Failed segments listed by id (the rest are counted).
pub const FAILED_LISTED: usize = 25;
/// Soil types shown on their own (the rest are pooled as "other types").
pub const SOIL_TYPES_SHOWN: usize = 15;
/// Segments listed in the least-certain table.
pub const LEAST_CERTAIN_LISTED: usize = 20;
/// Width of each of the two maps, px.
const MAP_WIDTH_PX: f64 = 1000.0;
/// Width of the relative-error map, px (a second, smaller map).
const ERROR_MAP_WIDTH_PX: f64 = 640.0;
/// Metres in a degree of latitude (WGS 84 mean, 111.32 km), for the scale bar of a map in
/// longitude and latitude (the map scales longitude by cos(latitude)).
const METRES_PER_DEGREE: f64 = 111_320.0;

const CSS: &str = "body{font-family:sans-serif;margin:24px auto;max-width:1100px;color:#222;\
line-height:1.4}h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:4px;\
margin-top:2em}table{border-collapse:collapse;margin:8px 0}td,th{padding:3px 10px;\
border-bottom:1px solid #eee;text-align:left;vertical-align:middle}td.n{text-align:right;\
font-variant-numeric:tabular-nums}.note{color:#555;font-size:.9em}.worst{display:flex;\
flex-wrap:wrap;gap:4px 16px}.worst figure{margin:8px 0;border:1px solid #ddd;padding:6px}\
figcaption{font-size:.85em;max-width:730px}svg{max-width:100%;height:auto}.warn{color:#a33}";

/// Write the audit report of the database to `out_path`, reading the database
/// [`PAGE_SIZE`] segments at a time.
pub fn write(db: &Database, out_path: &Path) -> Result<ExportSummary, ExportError> {
    write_paged(db, out_path, PAGE_SIZE)
}

/// [`write()`], reading the database `page_size` segments at a time: the page is the same for
/// every page size. The report's figures come from one pass over the records that keeps a few
/// numbers per segment (`Tally`: no curve, no measurement), the map from a second pass over
/// the geometries alone, and the worst fits' curves are read again for those shown.
pub fn write_paged(
    db: &Database,
    out_path: &Path,
    page_size: usize,
) -> Result<ExportSummary, ExportError> {
    check_out_path(db, out_path, crate::outfile::Contents::Plain, "report.html")?;
    let records = Records::new(db, page_size);
    let _snapshot = records.snapshot()?;
    let mut warnings = Vec::new();
    let mut map_warnings = Vec::new();
    let mut t = Tally::new(CommonGeometry::new(records.dominant_srid()?));
    records.for_each(&mut warnings, |rec| {
        t.add(&rec, &mut map_warnings);
        Ok(())
    })?;
    t.finish();
    warnings.append(&mut map_warnings);
    let runs = load_runs(db, &t.run_ids)?;
    let (name, worst_ids) = t.worst();
    let mut worst = Vec::with_capacity(worst_ids.len());
    for (id, v) in worst_ids {
        // Warnings about these records were given by the pass above.
        if let Some(r) = records.load(&id, &mut Vec::new())? {
            worst.push((r, v));
        }
    }
    let (map, change_map) = map_section(&records, &mut t)?;
    let map = map + &super::field::section(db)?;
    let encode = |e: ChartError| ExportError::Encode {
        path: out_path.to_path_buf(),
        message: e.to_string(),
    };
    let html = render(
        &db.path().display().to_string(),
        &t,
        &runs,
        &map,
        change_map,
        (name, &worst),
        &warnings,
    )
    .map_err(encode)?;
    write_file_atomically(out_path, html.as_bytes())?;
    Ok(ExportSummary {
        segments: t.segments,
        with_geometry: t.with_geometry,
        fitted: t.fitted,
        warnings,
    })
}

/// The runs that produced the segments' latest fits, by id.
fn load_runs(db: &Database, ids: &BTreeSet<i64>) -> Result<Vec<RunRow>, ExportError> {
    let mut runs = Vec::new();
    for &id in ids {
        if let Some(r) = db::load_run(db.conn(), id).map_err(ExportError::db(db))? {
            runs.push(r);
        }
    }
    Ok(runs)
}

/// The `k` first items by `cmp`, of all pushed, holding at most `2 k` at a time.
struct Top<T> {
    k: usize,
    items: Vec<T>,
    cmp: fn(&T, &T) -> Ordering,
}

impl<T> Top<T> {
    fn new(k: usize, cmp: fn(&T, &T) -> Ordering) -> Self {
        Top {
            k,
            items: Vec::new(),
            cmp,
        }
    }

    fn push(&mut self, item: T) {
        self.items.push(item);
        if self.items.len() >= 2 * self.k.max(1) {
            self.finish();
        }
    }

    /// Sort and keep the first `k`.
    fn finish(&mut self) {
        self.items.sort_by(self.cmp);
        self.items.truncate(self.k);
    }
}

/// Highest value first, then by segment id.
fn worst_first(a: &(f64, String), b: &(f64, String)) -> Ordering {
    b.0.total_cmp(&a.0).then(a.1.cmp(&b.1))
}

/// A segment of the least-certain table.
struct LeastCertain {
    id: String,
    material: &'static str,
    soil_type: String,
    speed: f64,
    std: f64,
    rel: f64,
    status: &'static str,
    flags: String,
}

/// A segment drawn on the map: its leak-band speed ± σ ([`speed_with_std`]) and status.
struct Drawn {
    speed: Option<(f64, Option<f64>)>,
    /// %Δv of the leak-band speed since the previous campaign, of a changed pipe.
    change_pct: Option<f64>,
    status: &'static str,
    trust: Trust,
}

/// A segment of the action list: flagged or failed, or carrying a flag.
struct Action {
    id: String,
    /// Its length, m (the inventory's, else its geometry's in a projected system).
    length_m: Option<f64>,
    material: &'static str,
    status: &'static str,
    flags: String,
    speed: Option<(f64, Option<f64>)>,
    todo: String,
}

/// What to do about a segment: the action part of each flag's advice (after its first colon),
/// once each, or why its fit failed.
fn todo_of(flags: &str, failed: Option<&str>) -> String {
    let mut out: Vec<String> = Vec::new();
    if let Some(msg) = failed {
        out.push(format!(
            "no fit ({msg}): check the inventory record and the measurements"
        ));
    }
    for code in codes(flags) {
        let a = advice(code);
        let action = a.split_once(": ").map_or(a, |(_, act)| act).to_string();
        if !out.contains(&action) {
            out.push(action);
        }
    }
    out.join("; ")
}

/// The length of a line in a projected system, in its units.
fn line_length(line: &LineString) -> f64 {
    line.points
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum()
}

/// A soil zone of the zone section: its newest estimate and its members' single fits.
pub(crate) struct ZoneTally {
    /// The estimate.
    pub zone: ZoneFitRow,
    /// The members' fitted E_m, Pa.
    pub e: Vec<f64>,
    /// The members' fitted ν_m.
    pub nu: Vec<f64>,
}

/// Everything the report shows, gathered in one pass over the records: counts, the values of
/// the distributions (a few numbers per segment), and the few segments each table lists.
struct Tally {
    segments: usize,
    with_geometry: usize,
    fitted: usize,
    status: BTreeMap<&'static str, usize>,
    flags: BTreeMap<String, usize>,
    notes: BTreeMap<String, usize>,
    run_ids: BTreeSet<i64>,
    /// Of the non-failed fits, sorted by [`Tally::finish`].
    misfits: Vec<f64>,
    /// Of the non-failed fits, sorted by [`Tally::finish`].
    chi2: Vec<f64>,
    /// Of every segment, sorted by [`Tally::finish`].
    speeds: Vec<f64>,
    any_non_failed: bool,
    all_chi2: bool,
    with_speed_error: usize,
    above_speed_error: usize,
    without_speed_error: usize,
    /// Segments whose speed is the soil field's prediction, of them not fitted, and with an
    /// error.
    predicted: usize,
    predicted_unfitted: usize,
    predicted_with_error: usize,
    least_certain: Top<LeastCertain>,
    soil: BTreeMap<String, SoilTally>,
    speed_points: Vec<SpeedPoint<'static>>,
    zones: BTreeMap<String, ZoneTally>,
    worst_chi2: Top<(f64, String)>,
    worst_misfit: Top<(f64, String)>,
    failed: usize,
    failed_listed: Vec<(String, String)>,
    common: CommonGeometry,
    bbox: [f64; 4],
    drawn: Vec<Drawn>,
    actions: Vec<Action>,
    changes: ChangeTally,
}

impl Tally {
    fn new(common: CommonGeometry) -> Self {
        Tally {
            segments: 0,
            with_geometry: 0,
            fitted: 0,
            status: BTreeMap::new(),
            flags: BTreeMap::new(),
            notes: BTreeMap::new(),
            run_ids: BTreeSet::new(),
            misfits: Vec::new(),
            chi2: Vec::new(),
            speeds: Vec::new(),
            any_non_failed: false,
            all_chi2: true,
            with_speed_error: 0,
            above_speed_error: 0,
            without_speed_error: 0,
            predicted: 0,
            predicted_unfitted: 0,
            predicted_with_error: 0,
            least_certain: Top::new(LEAST_CERTAIN_LISTED, |a, b| {
                b.rel.total_cmp(&a.rel).then(a.id.cmp(&b.id))
            }),
            soil: BTreeMap::new(),
            speed_points: Vec::new(),
            zones: BTreeMap::new(),
            worst_chi2: Top::new(WORST_FITS, worst_first),
            worst_misfit: Top::new(WORST_FITS, worst_first),
            failed: 0,
            failed_listed: Vec::new(),
            common,
            bbox: [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ],
            drawn: Vec::new(),
            actions: Vec::new(),
            changes: ChangeTally::new(),
        }
    }

    /// Count one record; `map_warnings` gets its geometry's, when it cannot go on the map.
    fn add(&mut self, r: &SegmentExport, map_warnings: &mut Vec<String>) {
        self.segments += 1;
        self.fitted += usize::from(r.fit.is_some());
        *self.status.entry(r.status()).or_default() += 1;
        count_codes(&mut self.flags, r.flags.as_deref());
        count_codes(&mut self.notes, r.fit.as_ref().map(|f| f.notes.as_str()));
        self.speeds
            .extend(r.leak_band_speed.filter(|v| v.is_finite()));
        let change_pct = self.changes.add(r);
        if let Some(line) =
            self.common
                .line(r.id(), r.geometry.as_ref(), r.segment.srid, map_warnings)
        {
            // Counted as drawn: a geometry the map cannot show has its warning instead.
            self.with_geometry += 1;
            for &(x, y) in &line.points {
                self.bbox = [
                    self.bbox[0].min(x),
                    self.bbox[1].max(x),
                    self.bbox[2].min(y),
                    self.bbox[3].max(y),
                ];
            }
            self.drawn.push(Drawn {
                speed: speed_with_std(r),
                change_pct,
                status: r.status(),
                // A segment without a fit of its own but with the soil field's speed is drawn
                // as a prediction (model §7.12), whatever its fit status says.
                trust: if r.speed_source == crate::export::record::SPEED_PREDICTED {
                    Trust::Predicted
                } else {
                    Trust::of_status(r.status())
                },
            });
        }
        let flags = r.flags.clone().unwrap_or_default();
        if matches!(r.status(), "flagged" | "failed") || codes(&flags).next().is_some() {
            let failed = r
                .fit
                .as_ref()
                .filter(|f| f.status == FitStatus::Failed)
                .map(|f| f.message.as_deref().unwrap_or("no reason stored"));
            let length_m = r.segment.length_m.filter(|l| l.is_finite()).or_else(|| {
                let srid = r.segment.srid?;
                (!crs::is_geographic(srid))
                    .then(|| r.geometry.as_ref().map(line_length))
                    .flatten()
                    .map(|l| l * crs::metres_per_unit(srid).unwrap_or(1.0))
            });
            self.actions.push(Action {
                id: r.id().to_string(),
                length_m,
                material: r.segment.material.code(),
                status: r.status(),
                todo: todo_of(&flags, failed),
                flags,
                speed: speed_with_std(r),
            });
        }
        if let Some((z, _)) = &r.zone {
            let t = self
                .zones
                .entry(z.soil_zone.clone())
                .or_insert_with(|| ZoneTally {
                    zone: z.clone(),
                    e: Vec::new(),
                    nu: Vec::new(),
                });
            if let Some(f) = &r.fit {
                t.e.extend(f.soil_youngs_modulus_pa);
                t.nu.extend(f.soil_poisson);
            }
        }
        let predicted = r.speed_source == crate::export::record::SPEED_PREDICTED;
        if predicted {
            self.predicted += 1;
            self.predicted_unfitted += usize::from(r.fit.is_none());
            if let Some((v, Some(e))) = speed_with_std(r) {
                self.predicted_with_error += 1;
                self.above_speed_error += usize::from(e / v > SPEED_RSTD_MAX);
                self.least_certain.push(LeastCertain {
                    id: r.id().to_string(),
                    material: r.segment.material.code(),
                    soil_type: r.segment.soil_type.clone().unwrap_or_default(),
                    speed: v,
                    std: e,
                    rel: e / v,
                    status: "predicted",
                    flags: r.flags.clone().unwrap_or_default(),
                });
            }
        }
        let Some(f) = &r.fit else { return };
        self.run_ids.insert(f.run_id);
        if f.status == FitStatus::Failed {
            self.failed += 1;
            if self.failed_listed.len() < FAILED_LISTED {
                self.failed_listed
                    .push((r.id().to_string(), f.message.clone().unwrap_or_default()));
            }
            return;
        }
        // A non-failed fit.
        self.any_non_failed = true;
        self.all_chi2 &= f.chi2_per_dof.is_some_and(f64::is_finite);
        self.misfits.extend(f.misfit.filter(|v| v.is_finite()));
        self.chi2.extend(f.chi2_per_dof.filter(|v| v.is_finite()));
        match speed_with_std(r).filter(|_| !predicted) {
            Some((v, Some(e))) => {
                self.with_speed_error += 1;
                self.above_speed_error += usize::from(e / v > SPEED_RSTD_MAX);
                self.least_certain.push(LeastCertain {
                    id: r.id().to_string(),
                    material: r.segment.material.code(),
                    soil_type: r.segment.soil_type.clone().unwrap_or_default(),
                    speed: v,
                    std: e,
                    rel: e / v,
                    status: r.status(),
                    flags: r.flags.clone().unwrap_or_default(),
                });
            }
            Some((_, None)) => self.without_speed_error += 1,
            None => {}
        }
        let soil_type = r
            .segment
            .soil_type
            .as_deref()
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .unwrap_or("(not recorded)");
        if !self.soil.contains_key(soil_type) {
            self.soil
                .insert(soil_type.to_string(), SoilTally::default());
        }
        if let Some(g) = self.soil.get_mut(soil_type) {
            g.fitted += 1;
            g.c_p.extend(determined(
                f.soil_p_wave_speed_m_per_s,
                f.soil_p_wave_speed_std_m_per_s,
            ));
            g.c_s.extend(determined(
                f.soil_s_wave_speed_m_per_s,
                f.soil_s_wave_speed_std_m_per_s,
            ));
        }
        if let Some(speed) = r.leak_band_speed {
            self.speed_points.push(SpeedPoint {
                material: r.segment.material.code(),
                diameter_mm: r.segment.outer_diameter_mm,
                speed,
            });
        }
        if !r.curve.is_empty() {
            let id = || r.id().to_string();
            if let Some(v) = f.chi2_per_dof.filter(|v| v.is_finite()) {
                self.worst_chi2.push((v, id()));
            }
            if let Some(v) = f.misfit.filter(|v| v.is_finite()) {
                self.worst_misfit.push((v, id()));
            }
        }
    }

    /// Sort what the sections read sorted.
    fn finish(&mut self) {
        for v in [&mut self.misfits, &mut self.chi2, &mut self.speeds] {
            v.sort_by(f64::total_cmp);
        }
        self.least_certain.finish();
        // Longest first: a wrong speed on a long main costs the most excavation; then by id.
        self.actions.sort_by(|a, b| {
            b.length_m
                .unwrap_or(-1.0)
                .total_cmp(&a.length_m.unwrap_or(-1.0))
                .then(a.id.cmp(&b.id))
        });
        self.worst_chi2.finish();
        self.worst_misfit.finish();
        self.changes.listed.finish();
    }

    /// The fit-quality figure the report ranks by: χ²/dof when every non-failed fit has it
    /// (comparable across segments), the misfit otherwise; its sorted values over the
    /// non-failed fits.
    fn quality(&self) -> (&'static str, &[f64]) {
        if self.any_non_failed && self.all_chi2 {
            ("χ²/dof", &self.chi2)
        } else {
            ("misfit", &self.misfits)
        }
    }

    /// The worst fits by [`Self::quality`]: its name, and the segments with their values.
    fn worst(&self) -> (&'static str, Vec<(String, f64)>) {
        let (name, _) = self.quality();
        let top = if self.any_non_failed && self.all_chi2 {
            &self.worst_chi2
        } else {
            &self.worst_misfit
        };
        (
            name,
            top.items.iter().map(|(v, id)| (id.clone(), *v)).collect(),
        )
    }
}

/// "v ± σ" rounded to σ (or "v" in whole units without σ, "–" without a value), with a word
/// when the error is so large that the value says little ([`error_comment`]).
fn pm_opt(v: Option<(f64, Option<f64>)>) -> String {
    match v {
        Some((v, Some(e))) if v.is_finite() && e.is_finite() && e > 0.0 => {
            // As the exports print it: the error to 2 significant digits, the value to the
            // same decimal place.
            let place = numbers::error_place(e);
            format!(
                "{} ± {}{}",
                numbers::fixed(v, place),
                numbers::fixed(e, place),
                error_comment(v, e)
            )
        }
        Some((v, _)) if v.is_finite() => format!("{v:.0}"),
        _ => "–".to_string(),
    }
}

/// A relative error above which a value is not determined at all (the error is larger than the
/// value itself: zero is within one sigma).
const UNDETERMINED_RSTD: f64 = 1.0;
/// A relative error above which a value is only a rough indication.
const ROUGH_RSTD: f64 = 0.3;

/// The reader's comment on a value ± error, in words (empty when the error is moderate).
pub fn error_comment(v: f64, e: f64) -> &'static str {
    let rel = e / v.abs();
    if !rel.is_finite() || rel > UNDETERMINED_RSTD {
        " (not determined: the error exceeds the value; do not use it)"
    } else if rel > ROUGH_RSTD {
        " (rough: the error is over 30 % of the value)"
    } else {
        ""
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".to_string(), |x| sig(x, digits))
}

/// The fitted segments of one soil type and their determined soil speeds.
#[derive(Debug, Clone, Default)]
struct SoilTally {
    fitted: usize,
    c_p: Vec<WithStd>,
    c_s: Vec<WithStd>,
}

mod changes;
mod sections;

use changes::ChangeTally;

pub use sections::weighted_mean;
use sections::*;
