//! The network audit report (`pipewave audit`): one self-contained HTML page (inline CSS and
//! SVG, no script, nothing fetched) on fit quality across the network.
//!
//! Sections (each a `<section id=...>`): `summary` (counts, misfit statistics, runs),
//! `status-flags` (counts by status and flag code), `map` (segments coloured by the leak-band
//! wave speed), `misfit` (distribution), `speed-diameter` (wave speed against diameter by
//! material), `modulus-soil` (fitted E against soil type), `worst-fits` (the worst fits, each with
//! its measured points over the fitted curves), `failed` (segments without a fit).
//!
//! Everything aggregates, so the page reads the same for 200 or 20,000 segments: see
//! [`svg::MAP_TOOLTIP_LIMIT`], [`charts::SCATTER_LIMIT`], [`WORST_FITS`], [`FAILED_LISTED`].

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

use super::charts::{self, ChartError, SpeedPoint};
use super::svg::{self, escape, MapLine};
use super::{quantile, sorted_finite};
use crate::db::{self, Database, FitStatus, RunRow};
use crate::export::gpkg::common_geometries;
use crate::export::record::UNFITTED;
use crate::export::{
    check_out_path, crs, load_records, write_file_atomically, ExportError, ExportSummary,
    SegmentExport,
};
use crate::units::{np_to_db, sig};

/// The worst fits shown with their curves.
pub const WORST_FITS: usize = 12;
/// Failed segments listed by id (the rest are counted).
pub const FAILED_LISTED: usize = 25;
/// Soil types shown as their own box (the rest are pooled as "other").
pub const SOIL_TYPES_SHOWN: usize = 15;

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
    summary(&mut h, records, &non_failed, runs);
    status_flags(&mut h, records);
    map(&mut h, records, warnings);
    misfit(&mut h, records, &non_failed)?;
    speed_diameter(&mut h, &non_failed)?;
    modulus_soil(&mut h, &non_failed)?;
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

fn status_flags(h: &mut String, records: &[SegmentExport]) {
    let mut status: BTreeMap<&str, usize> = ["ok", "flagged", "failed", UNFITTED]
        .into_iter()
        .map(|s| (s, 0))
        .collect();
    let mut flags: BTreeMap<&str, usize> = BTreeMap::new();
    for r in records {
        *status.entry(r.status()).or_default() += 1;
        for f in r.flag_codes() {
            *flags.entry(f).or_default() += 1;
        }
    }
    let max = records.len();
    h.push_str(
        "<section id=\"status-flags\"><h2>Counts by status and flag</h2><table>\
                <tr><th>status</th><th>segments</th><th></th></tr>",
    );
    for s in ["ok", "flagged", "failed", UNFITTED] {
        let n = status.get(s).copied().unwrap_or(0);
        let colour = match s {
            "ok" => "#228833",
            "flagged" => "#ccbb44",
            "failed" => "#ee6677",
            _ => "#bbbbbb",
        };
        let _ = write!(
            h,
            "<tr><td>{s}</td><td class=\"n\">{n}</td><td>{}</td></tr>",
            svg::bar(n, max, colour)
        );
    }
    h.push_str("</table><table><tr><th>flag code</th><th>segments</th><th></th></tr>");
    let mut by_count: Vec<(&str, usize)> = flags.into_iter().collect();
    by_count.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    for (f, n) in &by_count {
        let _ = write!(
            h,
            "<tr><td>{}</td><td class=\"n\">{n}</td><td>{}</td></tr>",
            escape(f),
            svg::bar(*n, max, "#4477aa")
        );
    }
    if by_count.is_empty() {
        h.push_str("<tr><td colspan=\"3\">no flags raised</td></tr>");
    }
    h.push_str("</table></section>");
}

fn map(h: &mut String, records: &[SegmentExport], warnings: &mut Vec<String>) {
    h.push_str("<section id=\"map\"><h2>Map: leak-band wave speed</h2>");
    let (srid, lines) = common_geometries(records, warnings);
    let map_lines: Vec<MapLine<'_>> = records
        .iter()
        .zip(&lines)
        .filter_map(|(r, l)| {
            l.as_ref().map(|line| MapLine {
                id: r.id(),
                line,
                value: r.leak_band_speed,
            })
        })
        .collect();
    match srid {
        Some(srid) if !map_lines.is_empty() => {
            let name = crs::lookup(srid).map_or("unknown system", |d| d.name);
            let _ = write!(
                h,
                "<p class=\"note\">{} segments drawn in EPSG:{srid} ({}); colour classes span the \
                 2nd–98th percentiles, grey: no speed (not fitted, failed, or a curve that does \
                 not cover the band).{}</p>",
                map_lines.len(),
                escape(name),
                if map_lines.len() <= svg::MAP_TOOLTIP_LIMIT {
                    " Hover a segment for its id and speed."
                } else {
                    ""
                }
            );
            h.push_str(&svg::map(
                &map_lines,
                crs::is_geographic(srid),
                "m/s",
                1000.0,
            ));
        }
        _ => h.push_str("<p class=\"note\">No segment has a geometry.</p>"),
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

fn modulus_soil(h: &mut String, non_failed: &[&SegmentExport]) -> Result<(), ChartError> {
    h.push_str(
        "<section id=\"modulus-soil\"><h2>Fitted soil Young's modulus E against soil type</h2>",
    );
    let mut groups: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in non_failed {
        if let Some(e) = r.fit.as_ref().and_then(|f| f.soil_youngs_modulus_pa) {
            let t = r
                .segment
                .soil_type
                .as_deref()
                .map(str::trim)
                .filter(|s| !s.is_empty());
            groups
                .entry(t.unwrap_or("(not recorded)").to_string())
                .or_default()
                .push(e);
        }
    }
    let mut groups: Vec<(String, Vec<f64>)> = groups.into_iter().collect();
    groups.sort_by(|a, b| b.1.len().cmp(&a.1.len()).then(a.0.cmp(&b.0)));
    if groups.len() > SOIL_TYPES_SHOWN {
        let rest: Vec<f64> = groups
            .drain(SOIL_TYPES_SHOWN - 1..)
            .flat_map(|(_, v)| v)
            .collect();
        groups.push(("(other types)".to_string(), rest));
    }
    for g in &mut groups {
        g.1.sort_by(f64::total_cmp);
    }
    groups.sort_by(|a, b| {
        quantile(&a.1, 0.5)
            .unwrap_or(0.0)
            .total_cmp(&quantile(&b.1, 0.5).unwrap_or(0.0))
    });
    if groups.is_empty() {
        h.push_str("<p class=\"note\">No fitted modulus.</p>");
    } else {
        h.push_str(
            "<p class=\"note\">Box: quartiles and median; whiskers: 1.5 × interquartile range; \
             number of segments in brackets; logarithmic axis.</p>",
        );
        h.push_str(&charts::log_boxplots(
            "modulus by soil type",
            &groups,
            "soil Young's modulus E (MPa)",
            |l| sig(10f64.powf(l) / 1e6, 2),
        )?);
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
             flags {}; E {} Pa, ν {}, ξ {}</figcaption>",
            escape(r.id()),
            escape(r.id()),
            r.segment.material.code(),
            escape(r.segment.soil_type.as_deref().unwrap_or("")),
            sig(r.segment.outer_diameter_mm, 4),
            sig(v, 3),
            fit.status.as_str(),
            escape(if fit.flags.is_empty() { "none" } else { &fit.flags }),
            opt(fit.soil_youngs_modulus_pa, 3),
            opt(fit.soil_poisson, 3),
            opt(fit.contact, 3),
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
