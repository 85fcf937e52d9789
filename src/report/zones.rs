//! The audit report's soil-zone section (model §7.11): each zone's estimate of
//! E_m and ν_m with its 95 % interval against the median and range of its segments' single
//! fits, the scatter used, χ²/dof, flags and the segments that disagree with their zone.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::audit::ZoneTally;
use super::svg::escape;

fn sci(v: Option<f64>) -> String {
    v.filter(|x| x.is_finite())
        .map(|x| format!("{x:.3e}"))
        .unwrap_or_else(|| "–".into())
}

fn fixed(v: Option<f64>) -> String {
    v.filter(|x| x.is_finite())
        .map(|x| format!("{x:.3}"))
        .unwrap_or_else(|| "–".into())
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    crate::stats::quantile(&v, 0.5)
}

/// The `<section id="zones">` of the audit report, from each zone's estimate and its members'
/// single fits; empty when no zone has an estimate.
pub(crate) fn section(zones: &BTreeMap<String, ZoneTally>) -> String {
    if zones.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<section id=\"zones\"><h2>Soil zones: zone estimates against single-segment fits</h2>\
         <p class=\"note\">A zone's E<sub>m</sub> and ν<sub>m</sub> come from all its \
         segments together (metal pipes fix c<sub>P</sub>, plastic pipes c<sub>S</sub>); \
         intervals are 95 %. Single fits: median [min, max] over the zone's segments. \
         Outliers disagree with their zone and are left out of its estimate.</p><table>\
         <tr><th>zone</th><th>segments</th><th>E<sub>m</sub> zone (Pa)</th><th>95 %</th>\
         <th>E<sub>m</sub> single fits</th><th>ν<sub>m</sub> zone</th><th>95 %</th>\
         <th>ν<sub>m</sub> single fits</th><th>scatter (decade, ν)</th><th>χ²/dof</th>\
         <th>flags</th><th>outliers</th></tr>",
    );
    for (name, ZoneTally { zone: z, e, nu }) in zones {
        let range = |v: &[f64], f: fn(Option<f64>) -> String| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            format!(
                "{} [{}, {}]",
                f(median(v.to_vec())),
                f(Some(lo)),
                f(Some(hi))
            )
        };
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{} – {}</td><td>{}</td><td>{}</td>\
             <td>{} – {}</td><td>{}</td><td>{:.3}, {:.3} ({})</td><td>{}</td><td>{}</td>\
             <td>{}</td></tr>",
            escape(name),
            z.n_segments,
            sci(z.soil_youngs_modulus_pa),
            sci(z.soil_youngs_modulus_lo_pa),
            sci(z.soil_youngs_modulus_hi_pa),
            range(e, sci),
            fixed(z.soil_poisson),
            fixed(z.soil_poisson_lo),
            fixed(z.soil_poisson_hi),
            range(nu, fixed),
            z.scatter_youngs_modulus_decades,
            z.scatter_poisson,
            escape(&z.scatter_source),
            fixed(z.chi2_per_dof),
            escape(&z.flags),
            escape(&z.outliers),
        );
    }
    h.push_str("</table>");
    let reasons: Vec<&str> = zones
        .values()
        .flat_map(|t| t.zone.outlier_reasons.lines())
        .filter(|l| !l.trim().is_empty())
        .collect();
    if !reasons.is_empty() {
        h.push_str("<ul>");
        for r in reasons {
            let _ = write!(h, "<li>{}</li>", escape(r));
        }
        h.push_str("</ul>");
    }
    h.push_str("</section>");
    h
}
