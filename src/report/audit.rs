//! The network audit report (`pipewave audit`): one self-contained HTML page (inline CSS and
//! SVG, no script, nothing fetched), leading with what a water utility needs.
//!
//! Sections (each a `<section id=...>`), in order: `trust` (how many predictions are
//! trustworthy, status `ok`, and the flags that need action, each with its advice), `map`
//! (segments coloured by the leak-band wave speed, and a second map of its relative error),
//! `least-certain` (the segments whose leak-band speed is least certain), `soil-speeds` (the
//! soil's c_P and c_S by soil type, with errors), `notes` (what the data leave undetermined,
//! summarised), then fit quality: `summary` (misfit statistics, runs), `misfit`
//! (distribution), `speed-diameter` (wave speed against diameter by material), `worst-fits`
//! (the worst fits, each with its measured points over the fitted curves), `failed` (segments
//! without a fit).
//!
//! Everything aggregates, so the page reads the same for 200 or 20,000 segments: see
//! [`svg::MAP_TOOLTIP_LIMIT`], [`charts::SCATTER_LIMIT`], [`WORST_FITS`], [`FAILED_LISTED`],
//! [`LEAST_CERTAIN_LISTED`], [`SOIL_TYPES_SHOWN`].

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

use super::charts::{self, ChartError, SoilSpeeds, SpeedPoint, WithStd};
use super::svg::{self, escape, ColourScale, MapLine, MapStyle};
use super::{quantile, sorted_finite};
use crate::db::{self, Database, FitStatus, RunRow};
use crate::export::gpkg::common_geometries;
use crate::export::record::UNFITTED;
use crate::export::{
    check_out_path, crs, load_records, write_file_atomically, ExportError, ExportSummary,
    SegmentExport,
};
use crate::invert::flags::{SPEED_DETERMINED_RSTD, SPEED_RSTD_MAX};
use crate::invert::FlagCode;
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

const CSS: &str = "body{font-family:sans-serif;margin:24px auto;max-width:1100px;color:#222;\
line-height:1.4}h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:4px;\
margin-top:2em}table{border-collapse:collapse;margin:8px 0}td,th{padding:3px 10px;\
border-bottom:1px solid #eee;text-align:left;vertical-align:middle}td.n{text-align:right;\
font-variant-numeric:tabular-nums}.note{color:#555;font-size:.9em}.worst{display:flex;\
flex-wrap:wrap;gap:4px 16px}.worst figure{margin:8px 0;border:1px solid #ddd;padding:6px}\
figcaption{font-size:.85em;max-width:730px}svg{max-width:100%;height:auto}.warn{color:#a33}";

/// Write the audit report of the database to `out_path`.
pub fn write(db: &Database, out_path: &Path) -> Result<ExportSummary, ExportError> {
    check_out_path(db, out_path, "the audit report", "report.html")?;
    let mut warnings = Vec::new();
    let records = load_records(db, &mut warnings)?;
    let runs = load_runs(db, &records)?;
    let html = render(
        &db.path().display().to_string(),
        &records,
        &runs,
        &mut warnings,
    )
    .map_err(|e| ExportError::Encode {
        path: out_path.to_path_buf(),
        message: e.to_string(),
    })?;
    write_file_atomically(out_path, html.as_bytes())?;
    Ok(ExportSummary {
        segments: records.len(),
        with_geometry: records.iter().filter(|r| r.geometry.is_some()).count(),
        fitted: records.iter().filter(|r| r.fit.is_some()).count(),
        warnings,
    })
}

/// The runs that produced the segments' latest fits, by id.
fn load_runs(db: &Database, records: &[SegmentExport]) -> Result<Vec<RunRow>, ExportError> {
    let ids: BTreeSet<i64> = records
        .iter()
        .filter_map(|r| r.fit.as_ref())
        .map(|f| f.run_id)
        .collect();
    let mut runs = Vec::new();
    for id in ids {
        if let Some(r) = db::load_run(db.conn(), id).map_err(ExportError::db(db))? {
            runs.push(r);
        }
    }
    Ok(runs)
}

/// "v ± σ" (or "v" without σ, "–" without a value), m/s-like precision.
fn pm_opt(v: Option<(f64, Option<f64>)>) -> String {
    match v {
        Some((v, Some(e))) if v.is_finite() && e.is_finite() => format!("{v:.0} ± {}", sig(e, 2)),
        Some((v, _)) if v.is_finite() => format!("{v:.0}"),
        _ => "–".to_string(),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".to_string(), |x| sig(x, digits))
}

/// The fit-quality figure the report ranks by: χ²/dof when every non-failed fit has it
/// (comparable across segments), the misfit otherwise.
fn quality_key(records: &[SegmentExport]) -> (&'static str, fn(&SegmentExport) -> Option<f64>) {
    let fitted = records
        .iter()
        .filter_map(|r| r.fit.as_ref())
        .filter(|f| f.status != FitStatus::Failed);
    let mut any = false;
    let mut all_chi2 = true;
    for f in fitted {
        any = true;
        all_chi2 &= f.chi2_per_dof.is_some_and(f64::is_finite);
    }
    if any && all_chi2 {
        ("χ²/dof", |r| r.fit.as_ref().and_then(|f| f.chi2_per_dof))
    } else {
        ("misfit", |r| r.fit.as_ref().and_then(|f| f.misfit))
    }
}

/// The HTML page.
pub fn render(
    db_name: &str,
    records: &[SegmentExport],
    runs: &[RunRow],
    warnings: &mut Vec<String>,
) -> Result<String, ChartError> {
    let mut h = String::with_capacity(64 * 1024);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>pipewave audit: {db}</title><style>{CSS}</style></head><body>\
         <h1>Network audit</h1><p class=\"note\">Database {db}; pipewave {ver}. Each segment's \
         latest fit. Wave speeds are the mean phase speed over {lo:.0}–{hi:.0} Hz.</p>",
        db = escape(db_name),
        ver = env!("CARGO_PKG_VERSION"),
        lo = crate::physics::curves::LEAK_BAND_HZ.0,
        hi = crate::physics::curves::LEAK_BAND_HZ.1,
    );
    let non_failed: Vec<&SegmentExport> = records
        .iter()
        .filter(|r| {
            r.fit
                .as_ref()
                .is_some_and(|f| f.status != FitStatus::Failed)
        })
        .collect();
    trust(&mut h, records);
    map(&mut h, records, warnings);
    least_certain(&mut h, &non_failed);
    soil_speeds(&mut h, &non_failed)?;
    notes(&mut h, records);
    summary(&mut h, records, &non_failed, runs);
    misfit(&mut h, records, &non_failed)?;
    speed_diameter(&mut h, &non_failed)?;
    h.push_str(&super::zones::section(records));
    worst_fits(&mut h, records)?;
    failed(&mut h, records);
    if !warnings.is_empty() {
        h.push_str("<section id=\"warnings\"><h2>Warnings</h2><ul>");
        for w in warnings.iter() {
            let _ = write!(h, "<li class=\"warn\">{}</li>", escape(w));
        }
        h.push_str("</ul></section>");
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

fn summary(
    h: &mut String,
    records: &[SegmentExport],
    non_failed: &[&SegmentExport],
    runs: &[RunRow],
) {
    let misfits = sorted_finite(non_failed.iter().filter_map(|r| r.fit.as_ref()?.misfit));
    let chi2 = sorted_finite(
        non_failed
            .iter()
            .filter_map(|r| r.fit.as_ref()?.chi2_per_dof),
    );
    let speeds = sorted_finite(records.iter().filter_map(|r| r.leak_band_speed));
    let with_geom = records.iter().filter(|r| r.geometry.is_some()).count();
    let fitted = records.iter().filter(|r| r.fit.is_some()).count();
    let _ = write!(
        h,
        "<section id=\"summary\"><h2>Summary</h2><table>\
         <tr><th>segments</th><td class=\"n\">{}</td></tr>\
         <tr><th>with geometry</th><td class=\"n\">{with_geom}</td></tr>\
         <tr><th>fitted (any status)</th><td class=\"n\">{fitted}</td></tr>\
         <tr><th>misfit: median / 90th percentile</th><td class=\"n\">{} / {}</td></tr>\
         <tr><th>χ²/dof: median / 90th percentile ({} fits)</th><td class=\"n\">{} / {}</td></tr>\
         <tr><th>leak-band wave speed, m/s: 10th / median / 90th percentile</th>\
         <td class=\"n\">{} / {} / {}</td></tr></table>",
        records.len(),
        opt(quantile(&misfits, 0.5), 3),
        opt(quantile(&misfits, 0.9), 3),
        chi2.len(),
        opt(quantile(&chi2, 0.5), 3),
        opt(quantile(&chi2, 0.9), 3),
        opt(quantile(&speeds, 0.1), 4),
        opt(quantile(&speeds, 0.5), 4),
        opt(quantile(&speeds, 0.9), 4),
    );
    h.push_str(
        "<h3>Runs behind these fits</h3><table><tr><th>run</th><th>started</th><th>finished</th>\
         <th>status</th><th>model</th><th>method</th><th>effects</th><th>seed</th>\
         <th>segments</th><th>ok</th><th>flagged</th><th>failed</th><th>time (s)</th>\
         <th>version</th></tr>",
    );
    for r in runs {
        let s = &r.settings;
        let c = &r.counts;
        let _ =
            write!(
            h,
            "<tr><td class=\"n\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            r.id,
            escape(&r.started_at),
            escape(r.finished_at.as_deref().unwrap_or("–")),
            r.status.as_str(),
            s.model.as_str(),
            escape(&s.method),
            escape(if s.effects.is_empty() { "none" } else { &s.effects }),
            s.seed,
            s.n_segments,
            c.n_ok,
            c.n_flagged,
            c.n_failed,
            opt(c.elapsed_s, 3),
            escape(&s.program_version),
        );
    }
    if runs.is_empty() {
        h.push_str("<tr><td colspan=\"14\">no calibrate run yet</td></tr>");
    }
    h.push_str("</table></section>");
}

/// The codes of a comma-separated list (`fits.flags`, `fits.notes`).
fn codes(list: &str) -> impl Iterator<Item = &str> {
    list.split(',').map(str::trim).filter(|s| !s.is_empty())
}

/// What a flag or note code means and what to do ([`FlagCode::advice`], or
/// [`ZoneFlag::advice`] for a soil zone's verdict); codes an older pipewave stored are named
/// as such.
fn advice(code: &str) -> &'static str {
    FlagCode::ALL
        .iter()
        .find(|c| c.as_str() == code)
        .map(|c| c.advice())
        .or_else(|| ZoneFlag::from_code(code).map(ZoneFlag::advice))
        .unwrap_or("a code of an older pipewave version: `pipewave run` refits these fits")
}

/// Count each code over the records, most frequent first (then by code).
fn count_codes(
    records: &[SegmentExport],
    list: fn(&SegmentExport) -> Option<&str>,
) -> Vec<(&str, usize)> {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for l in records.iter().filter_map(list) {
        for c in codes(l) {
            *counts.entry(c).or_default() += 1;
        }
    }
    let mut v: Vec<(&str, usize)> = counts.into_iter().collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    v
}

/// The leak-band speed of a fitted record, m/s, with its one-sigma error when stored.
fn speed_with_std(r: &SegmentExport) -> Option<(f64, Option<f64>)> {
    let speed = r.leak_band_speed.filter(|v| v.is_finite() && *v > 0.0)?;
    let std = r
        .fit
        .as_ref()
        .and_then(|f| f.leak_band_speed_std_m_per_s)
        .filter(|s| s.is_finite() && *s >= 0.0);
    Some((speed, std))
}

fn percent(part: usize, whole: usize) -> String {
    if whole == 0 {
        "–".to_string()
    } else {
        format!("{:.0} %", 100.0 * part as f64 / whole as f64)
    }
}

fn trust(h: &mut String, records: &[SegmentExport]) {
    let mut status: BTreeMap<&str, usize> = BTreeMap::new();
    for r in records {
        *status.entry(r.status()).or_default() += 1;
    }
    let n = |s: &str| status.get(s).copied().unwrap_or(0);
    let _ = write!(
        h,
        "<section id=\"trust\"><h2>Trustworthy predictions</h2><p><b>{ok} of {all} segments \
         ({pct}) have a trustworthy wave speed</b> (status ok): the model explains their \
         measurements and their leak-band speed is known within {lim:.0} % (one sigma). \
         {flagged} are flagged for action, {failed} failed, {unfitted} are not fitted.</p><table>\
         <tr><th>status</th><th>segments</th><th></th></tr>",
        ok = n("ok"),
        all = records.len(),
        pct = percent(n("ok"), records.len()),
        lim = 100.0 * SPEED_RSTD_MAX,
        flagged = n("flagged"),
        failed = n("failed"),
        unfitted = n(UNFITTED),
    );
    for s in ["ok", "flagged", "failed", UNFITTED] {
        let colour = match s {
            "ok" => "#228833",
            "flagged" => "#ccbb44",
            "failed" => "#ee6677",
            _ => "#bbbbbb",
        };
        let _ = write!(
            h,
            "<tr><td>{s}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            n(s),
            svg::bar(n(s), records.len(), colour)
        );
    }
    h.push_str(
        "</table><h3 id=\"flags\">Flags that need action</h3><table><tr><th>flag</th>\
         <th>segments</th><th>what it means and what to do</th></tr>",
    );
    let flags = count_codes(records, |r| r.flags.as_deref());
    for (code, count) in &flags {
        let _ = write!(
            h,
            "<tr><td>{}</td><td class=\"n\">{count}</td><td>{}</td></tr>",
            escape(code),
            escape(advice(code))
        );
    }
    if flags.is_empty() {
        h.push_str("<tr><td colspan=\"3\">no flags raised</td></tr>");
    }
    h.push_str(
        "</table><p class=\"note\">A segment can carry several flags. Each fit's own reasons \
         are in the exports' <code>flag_reasons</code> column.</p></section>",
    );
}

/// Classes of the relative-error map, % (the last class starts at [`SPEED_RSTD_MAX`]).
fn error_scale() -> ColourScale {
    ColourScale {
        lo: 100.0 * SPEED_RSTD_MAX / 8.0,
        hi: 100.0 * SPEED_RSTD_MAX,
    }
}

fn map(h: &mut String, records: &[SegmentExport], warnings: &mut Vec<String>) {
    h.push_str("<section id=\"map\"><h2>Map: leak-band wave speed ± its error</h2>");
    let (srid, lines) = common_geometries(records, warnings);
    let drawn: Vec<(&SegmentExport, &crate::db::wkt::LineString)> = records
        .iter()
        .zip(&lines)
        .filter_map(|(r, l)| l.as_ref().map(|line| (r, line)))
        .collect();
    let Some(srid) = srid.filter(|_| !drawn.is_empty()) else {
        h.push_str("<p class=\"note\">No segment has a geometry.</p></section>");
        return;
    };
    let speeds: Vec<Option<(f64, Option<f64>)>> =
        drawn.iter().map(|(r, _)| speed_with_std(r)).collect();
    let speed_lines: Vec<MapLine<'_>> = drawn
        .iter()
        .zip(&speeds)
        .map(|((r, line), s)| MapLine {
            id: r.id(),
            line,
            value: s.map(|s| s.0),
            label: s.map(|(v, e)| match e {
                Some(e) => format!("{v:.0} ± {} m/s ({})", sig(e, 2), r.status()),
                None => format!("{v:.0} m/s, error unknown ({})", r.status()),
            }),
        })
        .collect();
    let error_lines: Vec<MapLine<'_>> = drawn
        .iter()
        .zip(&speeds)
        .map(|((r, line), s)| {
            let rel = s.and_then(|(v, e)| Some(100.0 * e? / v));
            MapLine {
                id: r.id(),
                line,
                value: rel,
                label: rel.map(|p| format!("{} % of the speed", sig(p, 2))),
            }
        })
        .collect();
    let name = crs::lookup(srid).map_or("unknown system", |d| d.name);
    let _ = write!(
        h,
        "<p class=\"note\">{} segments drawn in EPSG:{srid} ({}). First map: the speed to type \
         into a leak correlator, colour classes spanning the 2nd–98th percentiles. Second map: its \
         one-sigma error as a percentage of the speed; darker is less certain, the darkest class \
         is above the {:.0} % a trustworthy prediction allows. Grey: no value (not fitted, \
         failed, a curve that does not cover the band, or no error stored).{}</p>",
        drawn.len(),
        escape(name),
        100.0 * SPEED_RSTD_MAX,
        if drawn.len() <= svg::MAP_TOOLTIP_LIMIT {
            " Hover a segment for its id, speed and error."
        } else {
            ""
        }
    );
    let geographic = crs::is_geographic(srid);
    h.push_str(&svg::map(
        &speed_lines,
        geographic,
        &MapStyle {
            unit: "m/s",
            decimals: 0,
            scale: None,
            reversed: false,
            width: MAP_WIDTH_PX,
        },
    ));
    let _ = write!(
        h,
        "<h3>Relative error of the leak-band speed (%)</h3>{}</section>",
        svg::map(
            &error_lines,
            geographic,
            &MapStyle {
                unit: "%",
                decimals: 2,
                scale: Some(error_scale()),
                reversed: true,
                width: ERROR_MAP_WIDTH_PX,
            },
        )
    );
}

fn least_certain(h: &mut String, non_failed: &[&SegmentExport]) {
    let mut rows: Vec<(&SegmentExport, f64, f64, f64)> = Vec::new();
    let mut without_error = 0usize;
    for r in non_failed {
        match speed_with_std(r) {
            Some((v, Some(e))) => rows.push((r, v, e, e / v)),
            Some((_, None)) => without_error += 1,
            None => {}
        }
    }
    rows.sort_by(|a, b| b.3.total_cmp(&a.3).then(a.0.id().cmp(b.0.id())));
    let above = rows.iter().filter(|r| r.3 > SPEED_RSTD_MAX).count();
    let _ = write!(
        h,
        "<section id=\"least-certain\"><h2>The least certain wave speeds</h2><p>{} fitted \
         segments have a leak-band speed with an error; {above} of them are uncertain by more \
         than {:.0} % (one sigma). The {} with the largest relative error:</p>",
        rows.len(),
        100.0 * SPEED_RSTD_MAX,
        rows.len().min(LEAST_CERTAIN_LISTED),
    );
    if without_error > 0 {
        let _ = write!(
            h,
            "<p class=\"note\">{without_error} fitted segment(s) have a speed but no stored \
             error (fits made by an older pipewave: <code>pipewave run</code> refits them).</p>"
        );
    }
    h.push_str(
        "<table><tr><th>segment</th><th>material</th><th>soil type</th>\
         <th>leak-band speed (m/s)</th><th>relative error</th><th>status</th><th>flags</th></tr>",
    );
    for (r, v, e, rel) in rows.iter().take(LEAST_CERTAIN_LISTED) {
        let flags = r.flags.as_deref().unwrap_or("");
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"n\">{v:.0} ± {}</td>\
             <td class=\"n rel\">{:.2} %</td><td>{}</td><td>{}</td></tr>",
            escape(r.id()),
            r.segment.material.code(),
            escape(r.segment.soil_type.as_deref().unwrap_or("")),
            sig(*e, 2),
            100.0 * rel,
            r.status(),
            escape(if flags.is_empty() { "none" } else { flags }),
        );
    }
    if rows.is_empty() {
        h.push_str("<tr><td colspan=\"7\">no fitted segment with a speed error</td></tr>");
    }
    h.push_str("</table></section>");
}

/// A value ± σ when determined: finite, positive, relative σ ≤ [`SPEED_DETERMINED_RSTD`].
fn determined(value: Option<f64>, std: Option<f64>) -> Option<WithStd> {
    let (value, std) = (value?, std?);
    (value.is_finite() && value > 0.0 && std.is_finite() && std > 0.0)
        .then_some(WithStd { value, std })
        .filter(|w| w.std / w.value <= SPEED_DETERMINED_RSTD)
}

/// The inverse-variance weighted mean of values ± σ, with its error (1/√Σw), and the sample
/// standard deviation of the values (None below two values).
pub fn weighted_mean(values: &[WithStd]) -> Option<(WithStd, Option<f64>)> {
    if values.is_empty() {
        return None;
    }
    let (sw, swx) = values.iter().fold((0.0, 0.0), |(sw, swx), p| {
        let w = 1.0 / (p.std * p.std);
        (sw + w, swx + w * p.value)
    });
    let mean = WithStd {
        value: swx / sw,
        std: 1.0 / sw.sqrt(),
    };
    let n = values.len() as f64;
    let spread = (values.len() >= 2).then(|| {
        let m = values.iter().map(|p| p.value).sum::<f64>() / n;
        (values.iter().map(|p| (p.value - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    });
    Some((mean, spread))
}

/// The fitted segments of one soil type and their determined soil speeds.
#[derive(Default)]
struct SoilTally {
    fitted: usize,
    c_p: Vec<WithStd>,
    c_s: Vec<WithStd>,
}

fn soil_speeds(h: &mut String, non_failed: &[&SegmentExport]) -> Result<(), ChartError> {
    h.push_str(
        "<section id=\"soil-speeds\"><h2>The soil's wave speeds by soil type</h2><p>The data fix \
         the soil's compressional speed c_P (metal and plastic pipes) and, for plastic pipes, \
         also its shear speed c_S; geotechnical surveys report the same quantities (Vp, Vs). \
         Each segment counts where its speed is determined (one sigma within ",
    );
    let _ = write!(
        h,
        "{:.0} % of the value); the mean of a soil type weights each segment by 1/σ², and the \
         spread is the standard deviation of its segments' values: a spread much larger than \
         the error says that soil type is not one material.</p>",
        100.0 * SPEED_DETERMINED_RSTD
    );
    let mut by_type: BTreeMap<String, SoilTally> = BTreeMap::new();
    for r in non_failed {
        let Some(f) = r.fit.as_ref() else { continue };
        let t = r
            .segment
            .soil_type
            .as_deref()
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .unwrap_or("(not recorded)");
        let g = by_type.entry(t.to_string()).or_default();
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
    let mut groups: Vec<(String, SoilTally)> = by_type.into_iter().collect();
    groups.sort_by(|a, b| b.1.fitted.cmp(&a.1.fitted).then(a.0.cmp(&b.0)));
    if groups.len() > SOIL_TYPES_SHOWN {
        let mut rest = SoilTally::default();
        for (_, g) in groups.drain(SOIL_TYPES_SHOWN - 1..) {
            rest.fitted += g.fitted;
            rest.c_p.extend(g.c_p);
            rest.c_s.extend(g.c_s);
        }
        groups.push(("(other types)".to_string(), rest));
    }
    let mut rows: Vec<(SoilSpeeds, usize, Option<f64>, Option<f64>)> = groups
        .into_iter()
        .map(
            |(
                name,
                SoilTally {
                    fitted: n,
                    c_p,
                    c_s,
                },
            )| {
                let p = weighted_mean(&c_p);
                let s = weighted_mean(&c_s);
                (
                    SoilSpeeds {
                        name,
                        c_p_mean: p.map(|m| m.0),
                        c_s_mean: s.map(|m| m.0),
                        c_p,
                        c_s,
                    },
                    n,
                    p.and_then(|m| m.1),
                    s.and_then(|m| m.1),
                )
            },
        )
        .collect();
    // Softest soil first; types without a determined c_P last.
    rows.sort_by(|a, b| {
        let key = |g: &SoilSpeeds| g.c_p_mean.map_or(f64::INFINITY, |m| m.value);
        key(&a.0)
            .total_cmp(&key(&b.0))
            .then(a.0.name.cmp(&b.0.name))
    });
    h.push_str(
        "<table><tr><th>soil type</th><th>fitted segments</th><th>with c_P</th>\
         <th>c_P (m/s): mean ± error</th><th>spread</th><th>with c_S</th>\
         <th>c_S (m/s): mean ± error</th><th>spread</th></tr>",
    );
    let pm = |m: Option<WithStd>| {
        m.map_or_else(
            || "–".to_string(),
            |m| format!("{:.0} ± {}", m.value, sig(m.std, 2)),
        )
    };
    for (g, n, p_spread, s_spread) in &rows {
        let _ = write!(
            h,
            "<tr><td>{}</td><td class=\"n\">{n}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td></tr>",
            escape(&g.name),
            g.c_p.len(),
            pm(g.c_p_mean),
            p_spread.map_or_else(|| "–".to_string(), |v| format!("{v:.0}")),
            g.c_s.len(),
            pm(g.c_s_mean),
            s_spread.map_or_else(|| "–".to_string(), |v| format!("{v:.0}")),
        );
    }
    if rows.is_empty() {
        h.push_str("<tr><td colspan=\"8\">no fitted segment</td></tr></table>");
    } else {
        h.push_str("</table>");
        let groups: Vec<SoilSpeeds> = rows.into_iter().map(|r| r.0).collect();
        if groups
            .iter()
            .any(|g| !g.c_p.is_empty() || !g.c_s.is_empty())
        {
            let _ = write!(
                h,
                "<p class=\"note\">Dots: one segment each, ± one sigma (blue c_P, red c_S{}); \
                 black bars: each type's weighted mean ± its error.</p>",
                if groups
                    .iter()
                    .map(|g| g.c_p.len() + g.c_s.len())
                    .sum::<usize>()
                    > charts::SCATTER_LIMIT
                {
                    "; too many to draw, only the means are shown"
                } else {
                    ""
                }
            );
            h.push_str(&charts::soil_speeds(&groups)?);
        }
    }
    h.push_str("</section>");
    Ok(())
}

fn notes(h: &mut String, records: &[SegmentExport]) {
    let notes = count_codes(records, |r| r.fit.as_ref().map(|f| f.notes.as_str()));
    h.push_str(
        "<section id=\"notes\"><h2>Notes</h2><p class=\"note\">What the data leave undetermined. \
         These are facts about the soil and the measurements, not defects of the fit.</p>",
    );
    if notes.is_empty() {
        h.push_str("<p class=\"note\">No notes.</p>");
    } else {
        h.push_str("<table class=\"note\"><tr><th>note</th><th>segments</th><th>meaning</th></tr>");
        for (code, count) in &notes {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"n\">{count}</td><td>{}</td></tr>",
                escape(code),
                escape(advice(code))
            );
        }
        h.push_str("</table>");
    }
    h.push_str("</section>");
}

fn misfit(
    h: &mut String,
    records: &[SegmentExport],
    non_failed: &[&SegmentExport],
) -> Result<(), ChartError> {
    h.push_str("<section id=\"misfit\"><h2>Misfit distribution</h2>");
    let (name, key) = quality_key(records);
    let v = sorted_finite(non_failed.iter().filter_map(|r| key(r)));
    if v.iter().any(|x| *x > 0.0) {
        let _ = write!(
            h,
            "<p class=\"note\">{name} of the {} fitted (ok or flagged) segments, logarithmic axis.</p>",
            v.len()
        );
        let markers: Vec<(&str, f64)> = [
            ("median", quantile(&v, 0.5)),
            ("90th percentile", quantile(&v, 0.9)),
        ]
        .into_iter()
        .filter_map(|(l, q)| q.map(|q| (l, q)))
        .collect();
        h.push_str(&charts::log_histogram(
            "misfit distribution",
            &v,
            name,
            &markers,
        )?);
    } else {
        h.push_str("<p class=\"note\">No fitted segment.</p>");
    }
    h.push_str("</section>");
    Ok(())
}

fn speed_diameter(h: &mut String, non_failed: &[&SegmentExport]) -> Result<(), ChartError> {
    h.push_str("<section id=\"speed-diameter\"><h2>Wave speed against diameter, by material</h2>");
    let points: Vec<SpeedPoint<'_>> = non_failed
        .iter()
        .filter_map(|r| {
            Some(SpeedPoint {
                material: r.segment.material.code(),
                diameter_mm: r.segment.outer_diameter_mm,
                speed: r.leak_band_speed?,
            })
        })
        .collect();
    if points.is_empty() {
        h.push_str("<p class=\"note\">No fitted segment with a wave speed.</p>");
    } else {
        let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
        for p in &points {
            *counts.entry(p.material).or_default() += 1;
        }
        let mut materials: Vec<(&str, usize)> = counts.into_iter().collect();
        materials.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
        let names: Vec<&str> = materials.iter().map(|m| m.0).collect();
        let _ = write!(
            h,
            "<p class=\"note\">{} segments; lines: median speed of each material at each diameter. \
             {}</p>",
            points.len(),
            if points.len() > charts::SCATTER_LIMIT {
                "Grey cells: number of segments (2-D histogram, darker = more)."
            } else {
                "Dots: one segment each."
            }
        );
        h.push_str(&charts::speed_vs_diameter(&points, &names)?);
    }
    h.push_str("</section>");
    Ok(())
}

fn worst_fits(h: &mut String, records: &[SegmentExport]) -> Result<(), ChartError> {
    let (name, key) = quality_key(records);
    let mut cands: Vec<(&SegmentExport, f64)> = records
        .iter()
        .filter(|r| {
            r.fit
                .as_ref()
                .is_some_and(|f| f.status != FitStatus::Failed)
        })
        .filter(|r| !r.curve.is_empty())
        .filter_map(|r| key(r).filter(|v| v.is_finite()).map(|v| (r, v)))
        .collect();
    cands.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.id().cmp(b.0.id())));
    cands.truncate(WORST_FITS);
    let _ = write!(
        h,
        "<section id=\"worst-fits\"><h2>The worst fits</h2><p class=\"note\">The {} fitted \
         segments with the highest {name}: measured points (red) over the fitted curves \
         (blue).</p><div class=\"worst\">",
        cands.len()
    );
    for (r, v) in cands {
        let Some(fit) = r.fit.as_ref() else { continue };
        let speed: Vec<(f64, f64)> = r
            .curve
            .iter()
            .filter_map(|p| {
                Some((
                    p.frequency_hz,
                    p.phase_speed_m_per_s.filter(|v| v.is_finite())?,
                ))
            })
            .collect();
        let att: Vec<(f64, f64)> = r
            .curve
            .iter()
            .filter_map(|p| {
                Some((
                    p.frequency_hz,
                    p.attenuation_db_per_m.filter(|v| v.is_finite())?,
                ))
            })
            .collect();
        let ms = &r.segment.measurements;
        let m_speed: Vec<(f64, f64)> = ms
            .iter()
            .map(|m| (m.frequency_hz, m.omega_rad_s / m.k_re_rad_per_m))
            .collect();
        let m_att: Vec<(f64, f64)> = ms
            .iter()
            .map(|m| (m.frequency_hz, np_to_db(m.attenuation_np_per_m)))
            .collect();
        let _ =
            write!(
            h,
            "<figure id=\"worst-{}\"><figcaption><b>{}</b> — {} {}, {} mm; {name} {}; status {}; \
             flags {}; leak-band speed {} m/s; c_P {} m/s, c_S {} m/s; notes {}</figcaption>",
            escape(r.id()),
            escape(r.id()),
            r.segment.material.code(),
            escape(r.segment.soil_type.as_deref().unwrap_or("")),
            sig(r.segment.outer_diameter_mm, 4),
            sig(v, 3),
            fit.status.as_str(),
            escape(match r.flags.as_deref() {
                Some(f) if !f.is_empty() => f,
                _ => "none",
            }),
            pm_opt(speed_with_std(r)),
            pm_opt(fit.soil_p_wave_speed_m_per_s.map(|v| (v, fit.soil_p_wave_speed_std_m_per_s))),
            pm_opt(fit.soil_s_wave_speed_m_per_s.map(|v| (v, fit.soil_s_wave_speed_std_m_per_s))),
            escape(if fit.notes.is_empty() { "none" } else { &fit.notes }),
        );
        h.push_str(&charts::curve_with_points(
            "worst fit: speed",
            "phase speed",
            &speed,
            &m_speed,
            "m/s",
        )?);
        h.push_str(&charts::curve_with_points(
            "worst fit: attenuation",
            "attenuation",
            &att,
            &m_att,
            "dB/m",
        )?);
        h.push_str("</figure>");
    }
    h.push_str("</div></section>");
    Ok(())
}

fn failed(h: &mut String, records: &[SegmentExport]) {
    let failed: Vec<&SegmentExport> = records
        .iter()
        .filter(|r| {
            r.fit
                .as_ref()
                .is_some_and(|f| f.status == FitStatus::Failed)
        })
        .collect();
    let _ = write!(
        h,
        "<section id=\"failed\"><h2>Failed segments</h2><p class=\"note\">{} segment(s) have no \
         fit{}.</p>",
        failed.len(),
        if failed.len() > FAILED_LISTED {
            format!("; the first {FAILED_LISTED} by id")
        } else {
            String::new()
        }
    );
    if !failed.is_empty() {
        h.push_str("<table><tr><th>segment</th><th>reason</th></tr>");
        for r in failed.iter().take(FAILED_LISTED) {
            let msg = r
                .fit
                .as_ref()
                .and_then(|f| f.message.as_deref())
                .unwrap_or("");
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td></tr>",
                escape(r.id()),
                escape(msg)
            );
        }
        h.push_str("</table>");
    }
    h.push_str("</section>");
}
