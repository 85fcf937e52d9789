//! The audit report's soil-field section (model §7.12): what the field rests on, the
//! leave-one-out check of every measured segment (P82: its fit against what its neighbours
//! predict, and the spread of z, which should be N(0, 1)), the worst segments, the labels the
//! neighbourhoods reject, and a map marking the measured segments by their z.

use std::fmt::Write as _;

use crate::db::field::{field_segments, latest_field_run, FieldSegmentRow};
use crate::db::wkt::LineString;
use crate::db::{self, Database};
use crate::export::ExportError;
use crate::field::FIELD_OUTLIER_Z;

use super::svg::{self, escape, MapLine, MapStyle};

/// Rows of the worst-segments table.
const WORST_SHOWN: usize = 12;
/// Rejected labels listed.
const LABELS_SHOWN: usize = 20;
/// Width of the plots, px.
const PLOT_W: f64 = 420.0;
/// Height of the plots, px.
const PLOT_H: f64 = 300.0;
/// Margin of the plots, px.
const MARGIN: f64 = 40.0;

/// Standard deviation and the robust one (1.4826 × the median absolute deviation) of `z`.
pub fn spread(z: &[f64]) -> (f64, f64) {
    let n = z.len() as f64;
    let m = z.iter().sum::<f64>() / n;
    let sd = (z.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
    let mut s: Vec<f64> = z.to_vec();
    s.sort_by(f64::total_cmp);
    let med = s[s.len() / 2];
    let mut dev: Vec<f64> = s.iter().map(|v| (v - med).abs()).collect();
    dev.sort_by(f64::total_cmp);
    (sd, 1.4826 * dev[dev.len() / 2])
}

/// The scatter of each measured segment's fitted leak-band speed (x) against the field's
/// leave-one-out prediction (y), with the line y = x.
fn loo_scatter(points: &[(f64, f64, bool)]) -> String {
    let lo = points
        .iter()
        .flat_map(|p| [p.0, p.1])
        .fold(f64::INFINITY, f64::min);
    let hi = points
        .iter()
        .flat_map(|p| [p.0, p.1])
        .fold(f64::NEG_INFINITY, f64::max);
    let span = (hi - lo).max(1.0);
    let px = |v: f64| MARGIN + (v - lo) / span * (PLOT_W - 2.0 * MARGIN);
    let py = |v: f64| PLOT_H - MARGIN - (v - lo) / span * (PLOT_H - 2.0 * MARGIN);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{PLOT_W}\" height=\"{PLOT_H}\" \
         viewBox=\"0 0 {PLOT_W} {PLOT_H}\"><line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" \
         y2=\"{:.1}\" stroke=\"#999\"/>",
        px(lo),
        py(lo),
        px(hi),
        py(hi)
    );
    for &(x, y, outlier) in points {
        let _ = write!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.5\" fill=\"{}\"/>",
            px(x),
            py(y),
            if outlier { "#c33" } else { "#36c" }
        );
    }
    let _ = write!(
        s,
        "<text x=\"{:.0}\" y=\"{:.0}\" font-size=\"11\" text-anchor=\"middle\">fitted \
         leak-band speed (m/s), {lo:.0}–{hi:.0}</text><text x=\"12\" y=\"{:.0}\" \
         font-size=\"11\" transform=\"rotate(-90 12 {:.0})\" text-anchor=\"middle\">predicted \
         from the others (m/s)</text></svg>",
        PLOT_W / 2.0,
        PLOT_H - 8.0,
        PLOT_H / 2.0,
        PLOT_H / 2.0
    );
    s
}

/// Histogram of z over [−5, 5] in half-unit bins (beyond: the end bins) with the N(0, 1)
/// density for comparison.
fn z_histogram(z: &[f64]) -> String {
    const BINS: usize = 20;
    let mut counts = [0usize; BINS];
    for &v in z {
        let b = ((v + 5.0) / 0.5).floor().clamp(0.0, (BINS - 1) as f64) as usize;
        counts[b] += 1;
    }
    let n = z.len().max(1) as f64;
    let peak = counts
        .iter()
        .map(|&c| c as f64 / n)
        .fold(0.5 * 0.398_942_28, f64::max);
    let bw = (PLOT_W - 2.0 * MARGIN) / BINS as f64;
    let hy = |f: f64| (PLOT_H - 2.0 * MARGIN) * f / peak;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{PLOT_W}\" height=\"{PLOT_H}\" \
         viewBox=\"0 0 {PLOT_W} {PLOT_H}\">"
    );
    for (i, &c) in counts.iter().enumerate() {
        let h = hy(c as f64 / n);
        let _ = write!(
            s,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{h:.1}\" fill=\"#9bd\"/>",
            MARGIN + i as f64 * bw,
            PLOT_H - MARGIN - h,
            bw - 1.0
        );
    }
    // N(0, 1): the probability of a half-unit bin ≈ 0.5 φ(centre).
    let mut path = String::new();
    for k in 0..=100 {
        let x = -5.0 + 0.1 * k as f64;
        let f = 0.5 * (-0.5 * x * x).exp() * 0.398_942_28;
        let _ = write!(
            path,
            "{}{:.1},{:.1}",
            if k == 0 { "M" } else { " L" },
            MARGIN + (x + 5.0) / 10.0 * (PLOT_W - 2.0 * MARGIN),
            PLOT_H - MARGIN - hy(f)
        );
    }
    let _ = write!(
        s,
        "<path d=\"{path}\" fill=\"none\" stroke=\"#333\"/><text x=\"{:.0}\" y=\"{:.0}\" \
         font-size=\"11\" text-anchor=\"middle\">leave-one-out z (−5 to 5); line: N(0, 1)\
         </text></svg>",
        PLOT_W / 2.0,
        PLOT_H - 8.0
    );
    s
}

/// The map of the measured segments coloured by z (the others grey), in the stored
/// coordinates of the network's first system.
fn z_map(db: &Database, rows: &[FieldSegmentRow]) -> Result<String, ExportError> {
    let z: std::collections::BTreeMap<&str, f64> = rows
        .iter()
        .filter_map(|r| r.loo_z.map(|z| (r.segment_id.as_str(), z)))
        .collect();
    let mut lines: Vec<(String, LineString, Option<f64>)> = Vec::new();
    let mut srid = None;
    db::pages::for_each_geometry(db.conn(), |g| {
        let Some(line) = g
            .geometry_wkt
            .as_deref()
            .and_then(|w| LineString::parse_wkt(w).ok())
        else {
            return Ok::<(), db::DbError>(());
        };
        if srid.is_none() {
            srid = g.srid;
        }
        if g.srid == srid {
            let v = z.get(g.segment_id.as_str()).copied();
            lines.push((g.segment_id, line, v));
        }
        Ok(())
    })
    .map_err(ExportError::db(db))?;
    if lines.is_empty() {
        return Ok(String::new());
    }
    let tooltips = lines.len() <= svg::MAP_TOOLTIP_LIMIT;
    let map_lines: Vec<MapLine<'_>> = lines
        .iter()
        .map(|(id, line, v)| MapLine {
            id,
            line,
            value: *v,
            label: v.filter(|_| tooltips).map(|z| format!("z = {z:.2}")),
            trust: crate::types::Trust::Trusted,
        })
        .collect();
    let style = MapStyle {
        unit: "",
        decimals: 1,
        scale: None,
        palette: &svg::VIRIDIS_9,
        width: 720.0,
        metres_per_unit: None,
    };
    let geographic = srid.is_some_and(crate::db::crs::is_geographic);
    Ok(svg::map(&map_lines, geographic, &style))
}

/// The `<section id="field">` of the audit report; empty when the database has no field.
pub(crate) fn section(db: &Database) -> Result<String, ExportError> {
    let err = ExportError::db(db);
    let Some(run) = latest_field_run(db.conn()).map_err(&err)? else {
        return Ok(String::new());
    };
    let rows = field_segments(db.conn()).map_err(&err)?;
    let mut h =
        String::from("<section id=\"field\"><h2>The soil field: a speed for every segment</h2>");
    let _ = write!(
        h,
        "<p>{} segments: {} measured ones teach the field, {} are predicted from it ({} from \
         their soil class alone, having no geometry), {} have no speed. {} soil class{}; \
         correlation length {}; hyper-parameters by {}.</p>",
        run.n_segments,
        run.n_measured,
        run.n_predicted,
        run.n_class_mean_only,
        run.n_without_speed,
        run.n_classes,
        if run.n_classes == 1 { "" } else { "es" },
        run.correlation_length_m
            .map_or_else(|| "–".to_string(), |l| format!("{l:.0} m")),
        escape(&run.hyper_source.replace('_', " ")),
    );
    let mut measured: Vec<&FieldSegmentRow> = rows.iter().filter(|r| r.loo_z.is_some()).collect();
    if measured.len() >= 2 {
        let z: Vec<f64> = measured.iter().filter_map(|r| r.loo_z).collect();
        let beyond2 = z.iter().filter(|v| v.abs() > 2.0).count();
        let outliers = measured.iter().filter(|r| r.field_outlier).count();
        // The spread is the stored figure, the one `calibrate` prints and the database holds:
        // one name, one figure.
        let spread_text = run
            .loo_z_std
            .map_or_else(|| "–".to_string(), |v| format!("{v:.2}"));
        let _ = write!(
            h,
            "<h3>Leave-one-out check</h3><p class=\"note\">Each measured segment is predicted \
             from the others and compared with its own fit: z = (field − fit) / √(σ²<sub>field\
             </sub> + σ²<sub>fit</sub>) should be N(0, 1). Leave-one-out z spread \
             <b>{spread_text}</b> (the standard deviation of z, the {outliers} \
             field outlier{} left out; near 1 when the predicted errors are honest, as \
             <code>calibrate</code> prints it); |z| &gt; 2 for {beyond2} of {} (about 5 % \
             expected). |z| &gt; {FIELD_OUTLIER_Z} is flagged <code>field_outlier</code>: a wrong \
             record, a changed soil or a leak.</p>",
            if outliers == 1 { "" } else { "s" },
            z.len()
        );
        let ids: Vec<String> = measured.iter().map(|r| r.segment_id.clone()).collect();
        let fitted: std::collections::BTreeMap<String, f64> =
            db::latest_fits(db.conn(), Some(&ids))
                .map_err(&err)?
                .into_iter()
                .filter_map(|f| f.leak_band_speed_m_per_s.map(|v| (f.segment_id, v)))
                .collect();
        let pts: Vec<(f64, f64, bool)> = measured
            .iter()
            .filter_map(|r| {
                Some((
                    *fitted.get(&r.segment_id)?,
                    r.field_leak_band_speed_m_per_s?,
                    r.field_outlier,
                ))
            })
            .collect();
        if !pts.is_empty() {
            h.push_str(&loo_scatter(&pts));
        }
        h.push_str(&z_histogram(&z));
        measured.sort_by(|a, b| {
            b.loo_z
                .unwrap_or(0.0)
                .abs()
                .total_cmp(&a.loo_z.unwrap_or(0.0).abs())
                .then(a.segment_id.cmp(&b.segment_id))
        });
        h.push_str(
            "<h3>The segments furthest from their neighbourhood</h3><table><tr><th>segment\
             </th><th>z</th><th>field speed (m/s)</th><th>class</th><th>outlier</th></tr>",
        );
        for r in measured.iter().take(WORST_SHOWN) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"n\">{:.2}</td><td class=\"n\">{} ± {}</td>\
                 <td>{}</td><td>{}</td></tr>",
                escape(&r.segment_id),
                r.loo_z.unwrap_or(f64::NAN),
                r.field_leak_band_speed_m_per_s
                    .map_or_else(|| "–".into(), |v| format!("{v:.1}")),
                r.field_leak_band_speed_std_m_per_s
                    .map_or_else(|| "–".into(), |v| format!("{v:.1}")),
                escape(r.soil_class.as_deref().unwrap_or("")),
                if r.field_outlier { "yes" } else { "" }
            );
        }
        h.push_str("</table>");
    }
    let rejected: Vec<&FieldSegmentRow> = rows.iter().filter(|r| r.label_rejected).collect();
    if !rejected.is_empty() {
        let _ = write!(
            h,
            "<h3>Labels the neighbourhood rejects</h3><p class=\"note\">{} segment{} carry a \
             soil label that most of their nearest neighbours do not; the field uses the \
             neighbourhood's class (a mapping error or imported backfill, or a true small \
             unit: check the record). Where the label is right, give it in the inventory's \
             column soil_class_override and import again: the field then uses it as it \
             is.</p><table><tr><th>segment</th><th>label</th><th>class \
             used</th></tr>",
            rejected.len(),
            if rejected.len() == 1 { "" } else { "s" }
        );
        for r in rejected.iter().take(LABELS_SHOWN) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(&r.segment_id),
                escape(r.label.as_deref().unwrap_or("")),
                escape(r.soil_class.as_deref().unwrap_or(""))
            );
        }
        h.push_str("</table>");
    }
    let overridden = rows.iter().filter(|r| r.class_overridden).count();
    if overridden > 0 {
        let _ = write!(
            h,
            "<p class=\"note\">{overridden} segment{} {} its class from the inventory's \
             soil_class_override (never rejected by its neighbourhood).</p>",
            if overridden == 1 { "" } else { "s" },
            if overridden == 1 { "takes" } else { "take" }
        );
    }
    let map = z_map(db, &rows)?;
    if !map.is_empty() {
        let _ = write!(
            h,
            "<h3>Measured segments by their leave-one-out z</h3><p class=\"note\">Coloured: \
             the measured segments; grey: the segments the field predicts. The speed and its \
             error for every segment are in the map above.</p>{map}"
        );
    }
    h.push_str("</section>");
    Ok(h)
}
