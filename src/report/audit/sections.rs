//! The audit page's sections, each rendered from the tally of the parent module: the page
//! itself, the trust and action tables, the maps, the least certain speeds, the soil speeds,
//! the notes, the misfit and speed-diameter figures, the worst fits and the failures.

use super::*;

/// The HTML page: the tallied records `t`, the runs behind their fits, the map section, the
/// worst fits (the name of the figure they are ranked by, each record with its value), and the
/// warnings.
pub(super) fn render(
    db_name: &str,
    t: &Tally,
    runs: &[RunRow],
    map: &str,
    change_map: Option<String>,
    worst: (&str, &[(SegmentExport, f64)]),
    warnings: &[String],
) -> Result<String, ChartError> {
    let mut h = String::with_capacity(64 * 1024 + map.len());
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
    trust(&mut h, t);
    actions(&mut h, t);
    super::changes::section(&mut h, t, change_map);
    h.push_str(map);
    least_certain(&mut h, t);
    soil_speeds(&mut h, t)?;
    notes(&mut h, t);
    summary(&mut h, t, runs);
    misfit(&mut h, t)?;
    speed_diameter(&mut h, t)?;
    h.push_str(&super::super::zones::section(&t.zones));
    worst_fits(&mut h, worst.0, worst.1)?;
    failed(&mut h, t);
    if !warnings.is_empty() {
        h.push_str("<section id=\"warnings\"><h2>Warnings</h2><ul>");
        for w in warnings {
            let _ = write!(h, "<li class=\"warn\">{}</li>", escape(w));
        }
        h.push_str("</ul></section>");
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

pub(super) fn summary(h: &mut String, t: &Tally, runs: &[RunRow]) {
    let (misfits, chi2, speeds) = (&t.misfits, &t.chi2, &t.speeds);
    let (with_geom, fitted) = (t.with_geometry, t.fitted);
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
        t.segments,
        opt(quantile(misfits, 0.5), 3),
        opt(quantile(misfits, 0.9), 3),
        chi2.len(),
        opt(quantile(chi2, 0.5), 3),
        opt(quantile(chi2, 0.9), 3),
        opt(quantile(speeds, 0.1), 4),
        opt(quantile(speeds, 0.5), 4),
        opt(quantile(speeds, 0.9), 4),
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
pub(super) fn codes(list: &str) -> impl Iterator<Item = &str> {
    list.split(',').map(str::trim).filter(|s| !s.is_empty())
}

/// What a flag or note code means and what to do ([`FlagCode::advice`], or
/// [`ZoneFlag::advice`] for a soil zone's verdict); codes an older pipewave stored are named
/// as such.
pub(super) fn advice(code: &str) -> &'static str {
    FlagCode::ALL
        .iter()
        .find(|c| c.as_str() == code)
        .map(|c| c.advice())
        .or_else(|| ZoneFlag::from_code(code).map(ZoneFlag::advice))
        .unwrap_or("a code of an older pipewave version: `pipewave run` refits these fits")
}

/// Count each code of a comma-separated list into `counts`.
pub(super) fn count_codes(counts: &mut BTreeMap<String, usize>, list: Option<&str>) {
    for c in list.into_iter().flat_map(codes) {
        match counts.get_mut(c) {
            Some(n) => *n += 1,
            None => {
                counts.insert(c.to_string(), 1);
            }
        }
    }
}

/// The codes counted, most frequent first (then by code).
pub(super) fn by_frequency(counts: &BTreeMap<String, usize>) -> Vec<(&str, usize)> {
    let mut v: Vec<(&str, usize)> = counts.iter().map(|(c, n)| (c.as_str(), *n)).collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    v
}

/// The leak-band speed of a fitted record, m/s, with its one-sigma error when stored.
pub(super) fn speed_with_std(r: &SegmentExport) -> Option<(f64, Option<f64>)> {
    let speed = r.leak_band_speed.filter(|v| v.is_finite() && *v > 0.0)?;
    // The exports' error: the fit's, or the soil field's for a predicted speed.
    let std = r
        .leak_band_speed_std()
        .filter(|s| s.is_finite() && *s >= 0.0);
    Some((speed, std))
}

pub(super) fn percent(part: usize, whole: usize) -> String {
    if whole == 0 {
        "–".to_string()
    } else {
        format!("{:.0} %", 100.0 * part as f64 / whole as f64)
    }
}

pub(super) fn trust(h: &mut String, t: &Tally) {
    let n = |s: &str| t.status.get(s).copied().unwrap_or(0);
    let _ = write!(
        h,
        "<section id=\"trust\"><h2>Trustworthy predictions</h2><p><b>{ok} of {all} segments \
         ({pct}) have a trustworthy wave speed</b> (status ok): the model explains their \
         measurements and their leak-band speed is known within {lim:.0} % (one sigma). \
         {flagged} are flagged for action, {failed} failed, {unfitted} are not fitted. \
         <b>{predicted} have a speed predicted by the soil field</b> with its error \
         ({predicted_unfitted} of the {unfitted} not fitted).</p><table>\
         <tr><th>status</th><th>segments</th><th></th></tr>",
        ok = n("ok"),
        all = t.segments,
        pct = percent(n("ok"), t.segments),
        lim = 100.0 * SPEED_RSTD_MAX,
        flagged = n("flagged"),
        failed = n("failed"),
        unfitted = n(UNFITTED),
        predicted = t.predicted,
        predicted_unfitted = t.predicted_unfitted,
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
            svg::bar(n(s), t.segments, colour)
        );
    }
    h.push_str(
        "</table><h3 id=\"flags\">Flags that need action</h3><table><tr><th>flag</th>\
         <th>segments</th><th>what it means and what to do</th></tr>",
    );
    let flags = by_frequency(&t.flags);
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

/// The action list: every segment to distrust, longest first, with its flags, what to do and
/// its speed ± error.
pub(super) fn actions(h: &mut String, t: &Tally) {
    let n = t.actions.len();
    let _ = write!(
        h,
        "<section id=\"actions\"><h2>Action list: the pipes to distrust</h2><p><b>{n} \
         segment{} to act on</b> (flagged or failed), longest first: a wrong speed on a long pipe \
         costs the most digging. Until the action is done, do not give their speed to a leak \
         correlator as if it were known. The flags are explained <a href=\"#flags\">above</a>; \
         each fit's own reasons are in the exports' <code>flag_reasons</code> column.</p>",
        if n == 1 { "" } else { "s" }
    );
    if n == 0 {
        h.push_str("<p class=\"note\">No segment is flagged or failed.</p></section>");
        return;
    }
    h.push_str(
        "<table class=\"actions\"><tr><th>segment</th><th>length (m)</th><th>material</th>\
         <th>leak-band speed (m/s)</th><th>status</th><th>flags</th><th>what to do</th></tr>",
    );
    for a in &t.actions {
        let _ = write!(
            h,
            "<tr><td class=\"segment\">{}</td><td class=\"n\">{}</td><td>{}</td>\
             <td class=\"n\">{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&a.id),
            a.length_m
                .map_or_else(|| "–".to_string(), |l| format!("{l:.0}")),
            a.material,
            escape(&pm_opt(a.speed)),
            a.status,
            escape(if a.flags.is_empty() { "–" } else { &a.flags }),
            escape(&a.todo),
        );
    }
    h.push_str("</table></section>");
}

/// What the misfit and χ²/dof of a fit are, for the reader.
pub(super) const MISFIT_DEFINITION: &str =
    "<p class=\"note\" id=\"misfit-definition\"><b>misfit</b>: \
the number each fit makes as small as it can: over the measured frequencies, the differences \
between measured and modelled wavenumber (its real part and the attenuation), squared and \
summed; each difference is divided by the measurement's standard deviation when the \
measurements state one (then the misfit is χ²), or taken relative to the measured value \
otherwise. <b>χ²/dof</b>: χ² divided by the degrees of freedom (the measured numbers minus the \
fitted parameters). About 1 when the model explains the data within their stated noise; well \
above 1 (flag <code>high_misfit</code>) when it does not; not defined when the measurements \
carry no standard deviations.</p>";

/// Classes of the relative-error map, % (the last class starts at [`SPEED_RSTD_MAX`]).
pub(super) fn error_scale() -> ColourScale {
    ColourScale {
        lo: 100.0 * SPEED_RSTD_MAX / 8.0,
        hi: 100.0 * SPEED_RSTD_MAX,
    }
}

/// The relative error of a drawn segment's leak-band speed, %.
pub(super) fn relative_error(d: &Drawn) -> Option<f64> {
    d.speed.and_then(|(v, e)| Some(100.0 * e? / v))
}

/// The map section: the segments [`Tally::add`] put on the map, drawn from a second pass over
/// the geometries alone (in the same order, so the k-th line drawn is the k-th tallied); and,
/// from the same pass, the map of the speed changes since the previous campaign, when a
/// segment changed (for the section of [`super::changes`]).
pub(super) fn map_section(
    records: &Records<'_>,
    t: &mut Tally,
) -> Result<(String, Option<String>), ExportError> {
    let mut h = String::from("<section id=\"map\"><h2>Map: leak-band wave speed ± its error</h2>");
    let Some(srid) = t.common.srid().filter(|_| !t.drawn.is_empty()) else {
        h.push_str("<p class=\"note\">No segment has a geometry.</p></section>");
        return Ok((h, None));
    };
    let n = t.drawn.len();
    let name = crs::lookup(srid).map_or("unknown system", |d| d.name);
    let _ = write!(
        h,
        "<p class=\"note\">{} segments drawn in EPSG:{srid} ({}). First map: the speed to type \
         into a leak correlator, colour classes spanning the 2nd–98th percentiles. Second map: its \
         one-sigma error as a percentage of the speed, blue where small and red where large; the \
         darkest red is above the {:.0} % a trustworthy prediction allows. On both maps a \
         flagged or failed segment is dashed over a black casing: distrust its speed (see the \
         <a href=\"#actions\">action list</a>). Grey: no value (not fitted, failed, a curve \
         that does not cover the band, or no error stored).{}</p>",
        n,
        escape(name),
        100.0 * SPEED_RSTD_MAX,
        if n <= svg::MAP_TOOLTIP_LIMIT {
            " Hover a segment for its id, speed and error."
        } else {
            ""
        }
    );
    let geographic = crs::is_geographic(srid);
    let speed_values = sorted_finite(t.drawn.iter().filter_map(|d| d.speed.map(|s| s.0)));
    let error_values = sorted_finite(t.drawn.iter().filter_map(relative_error));
    // Metres of a coordinate unit, for the scale bar (a degree of latitude: 111.32 km).
    let scale_units = if geographic {
        Some(METRES_PER_DEGREE)
    } else {
        crs::metres_per_unit(srid)
    };
    let speed_style = MapStyle {
        unit: "m/s",
        decimals: 0,
        scale: None,
        palette: &svg::VIRIDIS_9,
        width: MAP_WIDTH_PX,
        metres_per_unit: scale_units,
    };
    let error_style = MapStyle {
        unit: "%",
        decimals: 2,
        scale: Some(error_scale()),
        palette: &svg::BAD_IS_RED_8,
        width: ERROR_MAP_WIDTH_PX,
        metres_per_unit: scale_units,
    };
    let mut speed_map = MapCanvas::new(t.bbox, n, &speed_values, geographic, &speed_style);
    let mut error_map = MapCanvas::new(t.bbox, n, &error_values, geographic, &error_style);
    let mut change_map = super::changes::change_canvas(t, geographic, scale_units);
    let tooltips = n <= svg::MAP_TOOLTIP_LIMIT;
    let (common, drawn) = (&mut t.common, &t.drawn);
    let mut k = 0;
    let mut seen = Vec::new();
    let changed = || db::DbError::BadStoredValue {
        what: "the segments' geometry changed while the audit report read it".to_string(),
    };
    db::pages::for_each_geometry(records.db().conn(), |g| {
        let geometry = g
            .geometry_wkt
            .as_deref()
            .and_then(|w| crs::usable_line(w, g.srid).ok());
        // Its warning, if any, was given by the first pass.
        seen.clear();
        let Some(line) = common.line(&g.segment_id, geometry.as_ref(), g.srid, &mut seen) else {
            return Ok(());
        };
        let d = drawn.get(k).ok_or_else(changed)?;
        k += 1;
        let rel = relative_error(d);
        speed_map.add(&MapLine {
            id: &g.segment_id,
            line: &line,
            trust: d.trust,
            value: d.speed.map(|s| s.0),
            label: d.speed.filter(|_| tooltips).map(|(v, e)| match e {
                Some(e) => format!("{v:.0} ± {} m/s ({})", sig(e, 2), d.status),
                None => format!("{v:.0} m/s, error unknown ({})", d.status),
            }),
        });
        error_map.add(&MapLine {
            id: &g.segment_id,
            line: &line,
            trust: d.trust,
            value: rel,
            label: rel
                .filter(|_| tooltips)
                .map(|p| format!("{} % of the speed", sig(p, 2))),
        });
        if let Some(m) = change_map.as_mut() {
            m.add(&MapLine {
                id: &g.segment_id,
                line: &line,
                trust: Trust::Trusted,
                value: d.change_pct,
                label: d
                    .change_pct
                    .filter(|_| tooltips)
                    .map(|p| format!("{p:+.1} % since the previous campaign")),
            });
        }
        Ok(())
    })
    .map_err(ExportError::db(records.db()))?;
    if k != drawn.len() {
        return Err(ExportError::db(records.db())(changed()));
    }
    h.push_str(&speed_map.finish());
    let _ = write!(
        h,
        "<h3>Relative error of the leak-band speed (%)</h3>{}</section>",
        error_map.finish()
    );
    Ok((h, change_map.map(MapCanvas::finish)))
}

pub(super) fn least_certain(h: &mut String, t: &Tally) {
    let rows = &t.least_certain.items;
    let (above, without_error) = (t.above_speed_error, t.without_speed_error);
    let _ = write!(
        h,
        "<section id=\"least-certain\"><h2>The least certain wave speeds</h2><p>{} \
         segments have a leak-band speed with an error ({} fitted, {} predicted by the soil \
         field); {above} of them are uncertain by more than {:.0} % (one sigma). The {} with \
         the largest relative error:</p>",
        t.with_speed_error + t.predicted_with_error,
        t.with_speed_error,
        t.predicted_with_error,
        100.0 * SPEED_RSTD_MAX,
        (t.with_speed_error + t.predicted_with_error).min(LEAST_CERTAIN_LISTED),
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
    for r in rows.iter().take(LEAST_CERTAIN_LISTED) {
        let flags = r.flags.as_str();
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"n\">{:.0} ± {}</td>\
             <td class=\"n rel\">{:.2} %</td><td>{}</td><td>{}</td></tr>",
            escape(&r.id),
            r.material,
            escape(&r.soil_type),
            r.speed,
            sig(r.std, 2),
            100.0 * r.rel,
            r.status,
            escape(if flags.is_empty() { "none" } else { flags }),
        );
    }
    if rows.is_empty() {
        h.push_str("<tr><td colspan=\"7\">no segment with a speed error</td></tr>");
    }
    h.push_str("</table></section>");
}

/// A value ± σ when determined: finite, positive, relative σ ≤ [`SPEED_DETERMINED_RSTD`].
pub(super) fn determined(value: Option<f64>, std: Option<f64>) -> Option<WithStd> {
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

pub(super) fn soil_speeds(h: &mut String, t: &Tally) -> Result<(), ChartError> {
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
    let mut groups: Vec<(String, SoilTally)> =
        t.soil.iter().map(|(k, g)| (k.clone(), g.clone())).collect();
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
            let chart = charts::soil_speeds(&groups)?;
            if chart.off_axis > 0 {
                let _ = write!(
                    h,
                    "<p class=\"note\">{} segment speed(s) or error bar(s) lie beyond the \
                     axis (it spans the 1st–99th percentiles of the values): drawn at its edge \
                     with a black triangle.</p>",
                    chart.off_axis
                );
            }
            h.push_str(&chart.svg);
        }
    }
    h.push_str("</section>");
    Ok(())
}

pub(super) fn notes(h: &mut String, t: &Tally) {
    let notes = by_frequency(&t.notes);
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

pub(super) fn misfit(h: &mut String, t: &Tally) -> Result<(), ChartError> {
    h.push_str("<section id=\"misfit\"><h2>Misfit distribution</h2>");
    h.push_str(MISFIT_DEFINITION);
    let (name, v) = t.quality();
    if v.iter().any(|x| *x > 0.0) {
        let _ = write!(
            h,
            "<p class=\"note\">{name} of the {} fitted (ok or flagged) segments, logarithmic axis.</p>",
            v.len()
        );
        let markers: Vec<(&str, f64)> = [
            ("median", quantile(v, 0.5)),
            ("90th percentile", quantile(v, 0.9)),
        ]
        .into_iter()
        .filter_map(|(l, q)| q.map(|q| (l, q)))
        .collect();
        let chart = charts::log_histogram("misfit distribution", v, name, &markers)?;
        if chart.off_axis > 0 {
            let _ = write!(
                h,
                "<p class=\"note\">{} fit(s) with a {name} below {} of the median (fits \
                 exact to rounding) are counted in the first bar, so the axis does not \
                 stretch over empty decades.</p>",
                chart.off_axis,
                charts::LOG_HISTOGRAM_FLOOR_OF_MEDIAN
            );
        }
        h.push_str(&chart.svg);
    } else {
        h.push_str("<p class=\"note\">No fitted segment.</p>");
    }
    h.push_str("</section>");
    Ok(())
}

pub(super) fn speed_diameter(h: &mut String, t: &Tally) -> Result<(), ChartError> {
    h.push_str("<section id=\"speed-diameter\"><h2>Wave speed against diameter, by material</h2>");
    let points = &t.speed_points;
    if points.is_empty() {
        h.push_str("<p class=\"note\">No fitted segment with a wave speed.</p>");
    } else {
        let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
        for p in points {
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
        h.push_str(&charts::speed_vs_diameter(points, &names)?);
    }
    h.push_str("</section>");
    Ok(())
}

pub(super) fn worst_fits(
    h: &mut String,
    name: &str,
    cands: &[(SegmentExport, f64)],
) -> Result<(), ChartError> {
    let _ = write!(
        h,
        "<section id=\"worst-fits\"><h2>The worst fits</h2><p class=\"note\">The {} fitted \
         segments with the highest {name} (<a href=\"#misfit-definition\">defined above</a>): \
         measured points (red) with their ± one-sigma error bars over the fitted curves \
         (blue).</p><div class=\"worst\">",
        cands.len()
    );
    for (r, v) in cands {
        let v = *v;
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
                    p.attenuation_db_per_m
                        .filter(|v| v.is_finite() && *v >= 0.0)?,
                ))
            })
            .collect();
        let ms = &r.segment.measurements;
        // Phase speed c = ω / k_re, so σ_c = c σ_k / k_re (first order).
        let m_speed: Vec<charts::Measured> = ms
            .iter()
            .map(|m| {
                let c = m.omega_rad_s / m.k_re_rad_per_m;
                (
                    m.frequency_hz,
                    c,
                    m.k_re_std.map(|s| c * s / m.k_re_rad_per_m),
                )
            })
            .collect();
        let m_att: Vec<charts::Measured> = ms
            .iter()
            .map(|m| {
                (
                    m.frequency_hz,
                    np_to_db(m.attenuation_np_per_m),
                    m.attenuation_std.map(np_to_db),
                )
            })
            .collect();
        let _ =
            write!(
            h,
            "<figure id=\"worst-{}\"><figcaption><b>{}</b> — {} {}, {} mm; {name} {}; status {}; \
             flags {}; leak-band speed {} m/s (curve: {}); c_P {} m/s, c_S {} m/s; notes {}</figcaption>",
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
            escape(&fit.curve_source),
            pm_opt(fit.soil_p_wave_speed_m_per_s.map(|v| (v, fit.soil_p_wave_speed_std_m_per_s))),
            pm_opt(fit.soil_s_wave_speed_m_per_s.map(|v| (v, fit.soil_s_wave_speed_std_m_per_s))),
            escape(if fit.notes.is_empty() { "none" } else { &fit.notes }),
        );
        let drawn = [
            charts::curve_with_points("worst fit: speed", "phase speed", &speed, &m_speed, "m/s")?,
            charts::curve_with_points(
                "worst fit: attenuation",
                "attenuation",
                &att,
                &m_att,
                "dB/m",
            )?,
        ];
        for c in &drawn {
            h.push_str(&c.svg);
        }
        // Where a corrected attenuation is not supported (far outside the measured band, or
        // not near any measured value) the curve leaves it out; say so, with the span shown.
        let unsupported = r
            .curve
            .iter()
            .filter(|p| {
                p.phase_speed_m_per_s.is_some() && !att.iter().any(|a| a.0 == p.frequency_hz)
            })
            .count();
        if unsupported > 0 {
            let span = match (att.first(), att.last()) {
                (Some(a), Some(b)) => format!("shown at {}–{} Hz", sig(a.0, 3), sig(b.0, 3)),
                _ => "shown nowhere".to_string(),
            };
            let _ = write!(
                h,
                "<p class=\"note unsupported\">attenuation {span}: at {unsupported} of {} \
                 frequencies the {} curve is not supported by the measurements and is left \
                 out (blank in the exports).</p>",
                r.curve.len(),
                escape(&fit.curve_source)
            );
        }
        let off: usize = drawn.iter().map(|c| c.off_axis).sum();
        if off > 0 {
            let _ = write!(
                h,
                "<p class=\"note\">{off} error bar(s) run beyond the axis (ending in a black \
                 triangle).</p>"
            );
        }
        h.push_str("</figure>");
    }
    h.push_str("</div></section>");
    Ok(())
}

pub(super) fn failed(h: &mut String, t: &Tally) {
    let _ = write!(
        h,
        "<section id=\"failed\"><h2>Failed segments</h2><p class=\"note\">{} segment(s) have no \
         fit{}.</p>",
        t.failed,
        if t.failed > FAILED_LISTED {
            format!("; the first {FAILED_LISTED} by id")
        } else {
            String::new()
        }
    );
    if t.failed > 0 {
        h.push_str("<table><tr><th>segment</th><th>reason</th></tr>");
        for (id, msg) in &t.failed_listed {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td></tr>",
                escape(id),
                escape(msg)
            );
        }
        h.push_str("</table>");
    }
    h.push_str("</section>");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The audit's advice for every code is that code's own, never the fallback for codes of
    /// an older version, and no two codes share one.
    #[test]
    fn every_code_gets_its_own_advice_in_the_audit() {
        let mut seen = std::collections::BTreeSet::new();
        for c in FlagCode::ALL {
            assert_eq!(advice(c.as_str()), c.advice(), "{c}");
            assert!(seen.insert(advice(c.as_str())), "{c} shares its advice");
        }
        for z in ZoneFlag::ALL {
            assert_eq!(advice(z.as_str()), z.advice(), "{}", z.as_str());
            assert!(
                seen.insert(advice(z.as_str())),
                "{} shares its advice",
                z.as_str()
            );
        }
        assert!(advice("field_outlier").contains("neighbours"));
    }
}
