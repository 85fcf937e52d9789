//! The diagnosis report: `diagnosis.csv` (docs/interface.md) and `diagnosis.html` (inline SVG).

use std::fmt::Write as _;
use std::path::Path;

use super::group::GroupTest;
use super::{effect_value, Diagnosis, Residuals};
use crate::physics::effects::Effect;
use crate::report::svg::escape as esc;
use crate::spreadsheet::{self, spreadsheet_safe};
use crate::units::sig;

/// Columns of `diagnosis.csv`: the interface's, then details.
pub const CSV_COLUMNS: [&str; 22] = [
    "segment_id",
    "named_effect",
    "effect_value",
    "effect_std",
    "chi2_per_dof_before",
    "chi2_per_dof_after",
    "evidence",
    "group",
    "structured",
    "pattern",
    "ambiguous_with",
    "lr_statistic",
    "p_value",
    "holdout_chi2_before",
    "holdout_chi2_after",
    "ambiguity",
    "group_effect",
    "group_chi2_per_dof_after",
    "candidates_chi2_per_dof",
    "record_to_check",
    "record_set",
    "record_set_separation",
];

/// Columns of `groups.csv` (docs/interface.md).
pub const GROUP_CSV_COLUMNS: [&str; 12] = [
    "group",
    "n_segments",
    "named_effect",
    "ambiguous_with",
    "statistic",
    "p_value",
    "n_refitted",
    "pooled_by_effect",
    "statistic_kind",
    "members_carrying",
    "members",
    "twin_comparison",
];

/// A segment's place in the pooled test: the key of its group when that group detected an
/// effect, the effect, and the segment's χ²/dof after its refit with it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GroupRow {
    /// The group's key (empty: in no detected group).
    pub key: String,
    /// The group's effect.
    pub effect: Option<Effect>,
    /// χ²/dof of the member refitted with it.
    pub chi2_per_dof_after: Option<f64>,
}

/// "The measured data fit … far better than the recorded …" for a named inventory error.
pub fn record_sentence(d: &Diagnosis) -> Option<String> {
    let (c, _) = d.record.as_ref()?;
    if d.named != Some(Effect::InventoryError) {
        return None;
    }
    let (od, wall) = super::inventory::recorded_size(&d.data);
    let mm = |v: f64| ((v * 10.0).round() / 10.0).to_string();
    let what = match d.record_set.split_first() {
        Some((first, rest)) if !rest.is_empty() => format!(
            "{} (or equally {}: {} records the data cannot tell apart, most likely first by the \
             inventory's materials, sizes and eras)",
            first.candidate.label(),
            rest.iter()
                .map(|m| m.candidate.label())
                .collect::<Vec<_>>()
                .join(" | "),
            d.record_set.len()
        ),
        _ => format!("{} ({})", c.label(), c.change.describe()),
    };
    let separate = if d.record_separation.is_empty() {
        String::new()
    } else {
        format!("; to tell them apart: {}", d.record_separation)
    };
    Some(format!(
        "measured data fit {what} far better than the recorded {} OD {} mm, wall {} mm: check the record{separate}",
        d.data.material.map(|m| m.code()).unwrap_or("pipe"),
        mm(od),
        mm(wall),
    ))
}

/// "attenuation recorded in dB/m, not Np/m: …" for a named unit mix-up, with what to do.
pub fn units_sentence(id: &str, d: &Diagnosis) -> Option<String> {
    let (u, _) = d.units.as_ref()?;
    if d.named != Some(Effect::MeasurementUnits) {
        return None;
    }
    Some(format!(
        "{}: the data fit with {} divided by {} (chi2/dof {} -> {}); the stored measurements are \
         unchanged: correct the file and re-import it, or confirm with \
         `pipewave diagnose --convert-units {id}={}`",
        u.describe(),
        u.column(),
        sig(u.factor(), 4),
        sig(d.chi2_per_dof_before(), 3),
        sig(d.chi2_per_dof_after(), 3),
        u.code()
    ))
}

/// The `record_set` column: filled when a record is named or tied with the named effect.
pub fn record_set_column(d: &Diagnosis) -> String {
    let in_play = d.named == Some(Effect::InventoryError)
        || d.ambiguous_with.contains(&Effect::InventoryError);
    if in_play {
        d.record_set_text()
    } else {
        String::new()
    }
}

/// A residual counts as off when it is beyond this many standard deviations.
pub const OFF_SIGMAS: f64 = 2.0;

/// Where the residuals are off, in words: runs of neighbouring frequencies at which the model is
/// above (or below) the data by more than [`OFF_SIGMAS`], for Re k and the attenuation, e.g.
/// `attenuation: model below the data by 9.1–14σ at 425–525 Hz; above by 5.2–15σ at 575–725 Hz`.
pub fn residual_runs(r: &Residuals) -> String {
    let part = |v: &[f64], name: &str| -> Option<String> {
        let mut order: Vec<usize> = (0..v.len()).collect();
        order.sort_by(|&a, &b| r.frequency_hz[a].total_cmp(&r.frequency_hz[b]));
        let mut runs: Vec<(f64, Vec<usize>)> = Vec::new();
        for i in order {
            let x = v[i];
            let sign = if x > OFF_SIGMAS {
                1.0
            } else if x < -OFF_SIGMAS {
                -1.0
            } else {
                0.0
            };
            match runs.last_mut() {
                Some((s, members)) if *s == sign => members.push(i),
                _ => runs.push((sign, vec![i])),
            }
        }
        let words: Vec<String> = runs
            .iter()
            .filter(|(s, _)| *s != 0.0)
            .map(|(s, members)| {
                let mags: Vec<f64> = members.iter().map(|&i| v[i].abs()).collect();
                let lo = mags.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = mags.iter().copied().fold(0.0, f64::max);
                let f0 = r.frequency_hz[members[0]];
                let f1 = r.frequency_hz[*members.last().unwrap_or(&members[0])];
                let by = if members.len() == 1 {
                    format!("{}σ at {f0:.0} Hz", sig(hi, 2))
                } else {
                    format!("{}–{}σ at {f0:.0}–{f1:.0} Hz", sig(lo, 2), sig(hi, 2))
                };
                format!("{} by {by}", if *s > 0.0 { "above" } else { "below" })
            })
            .collect();
        (!words.is_empty()).then(|| format!("{name}: model {}", words.join("; ")))
    };
    let parts: Vec<String> = [part(&r.re, "Re k"), part(&r.att, "attenuation")]
        .into_iter()
        .flatten()
        .collect();
    if parts.is_empty() {
        format!("no residual beyond {OFF_SIGMAS}σ")
    } else {
        parts.join("; ")
    }
}

/// A χ²/dof for the page: 3 significant digits, or "–" where it is not defined (no
/// measurement standard deviations, or no fit), never `NaN`.
pub fn chi(v: f64) -> String {
    if v.is_finite() {
        sig(v, 3)
    } else {
        "–".to_string()
    }
}

/// χ²/dof before and after each refitted candidate: `base 38.4; pipe_loss 38.1; …`.
pub fn candidates_chi2(d: &Diagnosis) -> String {
    let mut v = vec![format!("base {}", chi(d.chi2_per_dof_before()))];
    for c in &d.candidates {
        if let Some(r) = &c.refit {
            v.push(format!(
                "{} {}",
                c.effect.name(),
                chi(r.fit.chi2_per_dof.unwrap_or(f64::NAN))
            ));
        }
    }
    v.join("; ")
}

/// The level below which a χ² p-value is no longer "within the noise" in words: the usual 5 %
/// (the diagnosis itself acts only below [`super::STRUCTURE_P`]).
pub const NOISE_P: f64 = 0.05;

/// The ambiguity column: for each indistinguishable effect, why and what would separate it.
pub fn ambiguity_text(d: &Diagnosis) -> String {
    d.ambiguity
        .iter()
        .map(|a| format!("{}: {}; {}", a.effect.name(), a.quantity, a.separating))
        .collect::<Vec<_>>()
        .join(" | ")
}

/// The named effect's value for the CSV: its parameter, or the record to check.
fn value_and_std(d: &Diagnosis) -> (String, String) {
    if d.named == Some(Effect::InventoryError) {
        let first = d.record_set.first().map(|m| m.candidate);
        return (
            first
                .or(d.record.as_ref().map(|(c, _)| *c))
                .map(|c| c.label())
                .unwrap_or_default(),
            String::new(),
        );
    }
    if d.named == Some(Effect::MeasurementUnits) {
        return (
            d.units.as_ref().map(|(u, _)| u.label()).unwrap_or_default(),
            String::new(),
        );
    }
    d.named
        .and_then(|e| d.chosen().and_then(|r| effect_value(&r.fit, e)))
        .map(|(v, s)| with_error(v, s))
        .unwrap_or_default()
}

/// A value and its standard error by the export's rule: the error to 2 significant digits and
/// the value to the same decimal place; without a usable error, the value to 6 digits.
fn with_error(v: f64, s: Option<f64>) -> (String, String) {
    use crate::export::numbers::{error_place, fixed};
    match s.filter(|s| s.is_finite() && *s > 0.0) {
        Some(s) if v.is_finite() => {
            let place = error_place(s);
            (fixed(v, place), fixed(s, place))
        }
        _ => (num(v), s.map(num).unwrap_or_default()),
    }
}

/// Write `groups.csv`, one row per group tested; `ids[i]` is segment i's id (the members that
/// carry the detected effect best are listed by id, joined by `;`).
pub fn write_groups_csv(
    path: &Path,
    ids: &[String],
    groups: &[GroupTest],
) -> Result<(), csv::Error> {
    let mut w = spreadsheet::writer_from_path(path)?;
    w.write_record(GROUP_CSV_COLUMNS)?;
    for g in groups {
        w.write_record([
            spreadsheet_safe(&g.group).into_owned(),
            g.members.len().to_string(),
            g.effect.map(|e| e.name()).unwrap_or("none").to_string(),
            g.ambiguous_with
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(","),
            num(g.statistic()),
            p_num(g.p_value()),
            g.n_refitted.to_string(),
            g.pooled
                .iter()
                .map(|p| {
                    format!(
                        "{} {} (p {})",
                        p.effect.name(),
                        sig(p.statistic, 3),
                        sig(p.p_value, 2)
                    )
                })
                .collect::<Vec<_>>()
                .join("; "),
            super::group::STATISTIC_KIND.to_string(),
            g.carrying.len().to_string(),
            spreadsheet_safe(
                &g.carrying
                    .iter()
                    .map(|&i| ids[i].as_str())
                    .collect::<Vec<_>>()
                    .join(";"),
            )
            .into_owned(),
            g.twins.as_ref().map(twin_text).unwrap_or_default(),
        ])?;
    }
    spreadsheet::finish(w)
}

/// The `twin_comparison` column: the two detected twins' group-level evidence at one common
/// size (the likelihood ratio of a fraction of the compared members carrying it), the winner
/// first (empty when no twins were both detected).
pub fn twin_text(t: &super::group::TwinComparison) -> String {
    format!(
        "{} {} (fraction {}, deviation {}) over {} {} (fraction {}); {} members",
        t.first.name(),
        sig(t.first_gain, 4),
        sig(t.first_fraction, 2),
        sig(t.first_deviation, 3),
        t.second.name(),
        sig(t.second_gain, 4),
        sig(t.second_fraction, 2),
        t.members
    )
}

/// The evidence column: the statistic used and its value.
pub fn evidence(d: &Diagnosis) -> String {
    match d.chosen() {
        Some(r) => format!(
            "LR {} (p {}), dAICc {}, held-out chi2 {} -> {}",
            sig(r.lr, 4),
            sig(r.p_value, 2),
            sig(r.d_aicc, 3),
            holdout_text(r.holdout_base),
            holdout_text(r.holdout_ext)
        ),
        None if !d.structure.structured => {
            let p = d.structure.p_value;
            if !p.is_finite() {
                "chi2 p not defined (no misfit statistic)".to_string()
            } else if p >= NOISE_P {
                format!("chi2 p = {} (within the noise)", sig(p, 2))
            } else {
                format!(
                    "chi2 p = {} (some misfit, but not below the {} this diagnosis acts on)",
                    sig(p, 2),
                    sig(super::STRUCTURE_P, 1)
                )
            }
        }
        None => {
            let best = d
                .candidates
                .iter()
                .filter_map(|c| c.refit.as_ref().map(|r| (c.effect, r)))
                .min_by(|a, b| a.1.p_value.total_cmp(&b.1.p_value));
            match best {
                Some((e, r)) => format!(
                    "no candidate passed: best {e} LR {} (p {}), chi2/dof {} -> {}, held-out chi2 {} -> {}",
                    sig(r.lr, 4),
                    sig(r.p_value, 2),
                    chi(d.chi2_per_dof_before()),
                    chi(r.fit.chi2_per_dof.unwrap_or(f64::NAN)),
                    holdout_text(r.holdout_base),
                    holdout_text(r.holdout_ext)
                ),
                None => "no candidate could lower the misfit".to_string(),
            }
        }
    }
}

/// Write `diagnosis.csv`. `ids[i]` and `groups[i]` belong to `diags[i]`. Safe to open in a
/// spreadsheet: text quoted, a formula-like id or group prefixed with `'`
/// ([`spreadsheet`]).
pub fn write_csv(
    path: &Path,
    ids: &[String],
    diags: &[Diagnosis],
    groups: &[GroupRow],
) -> Result<(), csv::Error> {
    let mut w = spreadsheet::writer_from_path(path)?;
    w.write_record(CSV_COLUMNS)?;
    for ((id, d), g) in ids.iter().zip(diags).zip(groups) {
        let (val, std) = value_and_std(d);
        let r = d.chosen();
        w.write_record([
            spreadsheet_safe(id).as_ref(),
            d.named.map(|e| e.name()).unwrap_or("none"),
            spreadsheet_safe(&val).as_ref(),
            &std,
            &num(d.chi2_per_dof_before()),
            &num(d.chi2_per_dof_after()),
            &evidence(d),
            spreadsheet_safe(&g.key).as_ref(),
            if d.structure.structured { "1" } else { "0" },
            &d.structure.pattern,
            &d.ambiguous_with
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(","),
            &r.map(|r| num(r.lr)).unwrap_or_default(),
            &r.map(|r| p_num(r.p_value)).unwrap_or_default(),
            &r.map(|r| num(r.holdout_base)).unwrap_or_default(),
            &r.map(|r| num(r.holdout_ext)).unwrap_or_default(),
            &ambiguity_text(d),
            g.effect.map(|e| e.name()).unwrap_or(""),
            &g.chi2_per_dof_after.map(num).unwrap_or_default(),
            &candidates_chi2(d),
            &record_sentence(d)
                .or_else(|| units_sentence(id, d))
                .unwrap_or_default(),
            spreadsheet_safe(&record_set_column(d)).as_ref(),
            if record_set_column(d).is_empty() {
                ""
            } else {
                &d.record_separation
            },
        ])?;
    }
    spreadsheet::finish(w)
}

/// A number cell, by the export's rule for values without an error: 6 significant digits,
/// plain notation unless tiny or huge; empty when not finite.
fn num(v: f64) -> String {
    if v.is_finite() {
        crate::export::numbers::significant(v, 6)
    } else {
        String::new()
    }
}

/// A p-value cell: scientific notation with 3 significant digits (`1.23e-180`, `5.00e-1`),
/// however small; empty when not finite.
fn p_num(p: f64) -> String {
    if p.is_finite() {
        format!("{p:.2e}")
    } else {
        String::new()
    }
}

/// A held-out χ² for the evidence text: 3 significant digits, or why there is none (∞: the
/// model has no wave at a frequency once another is left out, or no base fit; NaN: fewer than
/// 3 measurements or no stated noise).
fn holdout_text(v: f64) -> String {
    if v.is_finite() {
        sig(v, 3)
    } else if v.is_infinite() {
        "not computable (the model loses its wave when a frequency is left out)".to_string()
    } else {
        "not computable (fewer than 3 measurements or no stated noise)".to_string()
    }
}

/// At most this many segments get a detailed section (plot and candidate table).
pub const MAX_DETAILED: usize = 200;

/// Round tick positions over `[lo, hi]`: steps of 1, 2 or 5 × 10^k, about `n` of them.
pub fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if hi <= lo || !lo.is_finite() || !hi.is_finite() {
        return vec![lo];
    }
    let raw = (hi - lo) / n.max(1) as f64;
    let k = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * k)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * k);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// The label of tick `v` of `ticks`: as many decimals as their step needs, `-0` as `0`.
fn tick_text(v: f64, ticks: &[f64]) -> String {
    let step = match ticks {
        [a, b, ..] => b - a,
        _ => 1.0,
    };
    let dec = (-step.log10().floor()).max(0.0) as usize;
    let t = format!("{v:.dec$}");
    if t.starts_with('-') && t[1..].bytes().all(|b| b == b'0' || b == b'.') {
        t[1..].to_string()
    } else {
        t
    }
}

/// An inline SVG of normalised residuals against frequency: Re k (circles) and attenuation
/// (squares), before (hollow) and after (filled), with the ±2σ band, both axes with ticks and
/// labels, and a legend.
pub fn residual_svg(before: &Residuals, after: Option<&Residuals>) -> String {
    let (w, h, ml, mr, mt, mb) = (560.0, 250.0, 56.0, 14.0, 30.0, 44.0);
    let all = before
        .re
        .iter()
        .chain(&before.att)
        .chain(after.iter().flat_map(|a| a.re.iter().chain(&a.att)))
        .copied()
        .filter(|v| v.is_finite());
    let lim = all.fold(3.0f64, |m, v| m.max(v.abs())) * 1.1;
    let fmin = before
        .frequency_hz
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let fmax = before
        .frequency_hz
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let (f0, f1) = if fmax > fmin {
        (fmin - 0.05 * (fmax - fmin), fmax + 0.05 * (fmax - fmin))
    } else {
        (fmin - 1.0, fmin + 1.0)
    };
    let x = |f: f64| ml + (f - f0) / (f1 - f0) * (w - ml - mr);
    let y = |v: f64| mt + (lim - v.clamp(-lim, lim)) / (2.0 * lim) * (h - mt - mb);
    let (bottom, right) = (h - mb, w - mr);
    let mut s = String::new();
    let _ = write!(
        s,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img" font-family="sans-serif"><rect x="{ml}" y="{:.1}" width="{}" height="{:.1}" fill="#eef3f8"/>"##,
        y(2.0),
        w - ml - mr,
        y(-2.0) - y(2.0)
    );
    // Axes: the zero line, the frame's left and bottom edges, ticks and their labels.
    let _ = write!(
        s,
        r##"<line x1="{ml}" x2="{right}" y1="{0:.1}" y2="{0:.1}" stroke="#888"/><path d="M{ml} {mt}V{bottom}H{right}" fill="none" stroke="#333"/>"##,
        y(0.0)
    );
    let y_ticks = ticks(-lim, lim, 6);
    for &v in &y_ticks {
        let _ = write!(
            s,
            r##"<line x1="{x0}" x2="{ml}" y1="{yv:.1}" y2="{yv:.1}" stroke="#333"/><text x="{xt}" y="{yt:.1}" font-size="10" text-anchor="end">{label}</text>"##,
            x0 = ml - 4.0,
            yv = y(v),
            xt = ml - 6.0,
            yt = y(v) + 3.5,
            label = tick_text(v, &y_ticks)
        );
    }
    let x_ticks = ticks(f0, f1, 6);
    for &f in &x_ticks {
        let _ = write!(
            s,
            r##"<line x1="{0:.1}" x2="{0:.1}" y1="{bottom}" y2="{1}" stroke="#333"/><text x="{0:.1}" y="{2}" font-size="10" text-anchor="middle">{3}</text>"##,
            x(f),
            bottom + 4.0,
            bottom + 15.0,
            tick_text(f, &x_ticks)
        );
    }
    let _ = write!(
        s,
        r##"<text x="{}" y="{}" font-size="11" text-anchor="middle">frequency (Hz)</text><text x="13" y="{2}" font-size="11" transform="rotate(-90 13 {2})" text-anchor="middle">residual / σ</text>"##,
        (ml + right) / 2.0,
        h - 6.0,
        (mt + bottom) / 2.0,
    );
    // Legend, above the plot: (circle or square, filled, label).
    let mut items = vec![
        (true, false, "Re k, before"),
        (false, false, "attenuation, before"),
    ];
    if after.is_some() {
        items.extend([
            (true, true, "Re k, after"),
            (false, true, "attenuation, after"),
        ]);
    }
    let mut lx = ml;
    for (circle, filled, label) in items {
        let cx = lx + 3.0;
        let shape = if circle {
            format!(
                r##"<circle cx="{cx:.1}" cy="12" r="4" fill="{}" stroke="#1f77b4"/>"##,
                if filled { "#1f77b4" } else { "none" }
            )
        } else {
            format!(
                r##"<rect x="{:.1}" y="8.5" width="7" height="7" fill="{}" stroke="#d62728"/>"##,
                cx - 3.5,
                if filled { "#d62728" } else { "none" }
            )
        };
        let _ = write!(
            s,
            r##"{shape}<text x="{:.1}" y="16" font-size="10">{label}</text>"##,
            lx + 10.0
        );
        lx += 14.0 + 5.6 * label.chars().count() as f64;
    }
    let _ = write!(
        s,
        r##"<rect x="{:.1}" y="8" width="12" height="8" fill="#eef3f8" stroke="#ccd"/><text x="{:.1}" y="16" font-size="10">±2σ</text>"##,
        lx,
        lx + 15.0
    );
    let mut dots = |r: &Residuals, filled: bool| {
        for ((f, a), b) in r.frequency_hz.iter().zip(&r.re).zip(&r.att) {
            let fill = if filled { "#1f77b4" } else { "none" };
            let fill2 = if filled { "#d62728" } else { "none" };
            let _ = write!(
                s,
                r##"<circle cx="{:.1}" cy="{:.1}" r="4" fill="{fill}" stroke="#1f77b4"/><rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{fill2}" stroke="#d62728"/>"##,
                x(*f),
                y(*a),
                x(*f) - 3.5,
                y(*b) - 3.5
            );
        }
    };
    dots(before, false);
    if let Some(a) = after {
        dots(a, true);
    }
    s.push_str("</svg>");
    s
}

/// The fragment id of a segment's details: `s-` and the id with every character outside
/// `[A-Za-z0-9.-]` written as its code point in hex between two `_`, so any segment id gives a
/// valid, unique id that needs no escaping in a link.
pub fn anchor(id: &str) -> String {
    let mut a = String::from("s-");
    for c in id.chars() {
        if c.is_ascii_alphanumeric() || matches!(c, '.' | '-') {
            a.push(c);
        } else {
            let _ = write!(a, "_{:x}_", u32::from(c));
        }
    }
    a
}

/// Write `diagnosis.html`.
pub fn write_html(
    path: &Path,
    ids: &[String],
    diags: &[Diagnosis],
    groups: &[GroupTest],
    notes: &[String],
) -> std::io::Result<()> {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>pipewave diagnosis</title><style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px}th{background:#f0f0f0}.seg{border-top:2px solid #ddd;margin-top:1.5em;padding-top:.5em}.ok{color:#2a7}.none{color:#888}</style></head><body>");
    let detailed: Vec<(&String, &Diagnosis)> = ids
        .iter()
        .zip(diags)
        .filter(|(_, d)| d.structure.structured || d.named.is_some() || diags.len() <= 50)
        .take(MAX_DETAILED)
        .collect();
    let has_detail = |id: &str| detailed.iter().any(|(i, _)| i.as_str() == id);
    let named = diags.iter().filter(|d| d.named.is_some()).count();
    let structured = diags.iter().filter(|d| d.structure.structured).count();
    h.push_str("<h1>Discrepancy diagnosis</h1>");
    let _ = write!(
        h,
        "<p><b>{} segments diagnosed; {structured} with a misfit far above the noise (χ² p \
         below {}); an effect named for {named}.</b></p>",
        diags.len(),
        sig(super::STRUCTURE_P, 1)
    );
    for n in notes {
        let _ = write!(h, "<p>{}</p>", esc(n));
    }
    // Findings first: the segments with something to act on, each linked to its details.
    let findings: Vec<(&String, &Diagnosis)> = ids
        .iter()
        .zip(diags)
        .filter(|(_, d)| d.structure.structured || d.named.is_some())
        .collect();
    let row = |h: &mut String, id: &String, d: &Diagnosis| {
        let val = match value_and_std(d) {
            (v, s) if s.is_empty() => v.parse::<f64>().map(|x| sig(x, 3)).unwrap_or(v),
            (v, s) => format!(
                "{} ± {}",
                sig(v.parse().unwrap_or(f64::NAN), 3),
                sig(s.parse().unwrap_or(f64::NAN), 2)
            ),
        };
        let name = if has_detail(id) {
            format!("<a href=\"#{}\">{}</a>", anchor(id), esc(id))
        } else {
            esc(id)
        };
        let _ = write!(
            h,
            "<tr><td>{name}</td><td>{}</td><td class=\"{}\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&d.structure.pattern),
            if d.named.is_some() { "ok" } else { "none" },
            d.named.map(|e| e.name()).unwrap_or("none"),
            val,
            chi(d.chi2_per_dof_before()),
            chi(d.chi2_per_dof_after()),
            esc(&evidence(d))
        );
    };
    const HEAD: &str = "<table><tr><th>segment</th><th>pattern</th><th>named effect</th><th>value ± 1σ</th><th>χ²/dof before</th><th>after</th><th>evidence</th></tr>";
    h.push_str("<h2 id=\"findings\">Findings</h2>");
    if findings.is_empty() {
        h.push_str("<p>No segment has a misfit far above the noise: nothing to explain.</p>");
    } else {
        h.push_str(HEAD);
        for (id, d) in &findings {
            row(&mut h, id, d);
        }
        h.push_str("</table>");
    }
    h.push_str("<p class=\"how\">How to read this page: for each segment, the residuals of its fit in standard deviations (hollow: before; filled: after adding the named effect; circles: Re k, squares: attenuation; shaded: ±2σ), the misfit before and after as χ² per degree of freedom (χ² divided by the measured numbers minus the fitted parameters: about 1 when the model explains the data within their noise; \"–\" where the measurements state no standard deviations), the named effect with its value and uncertainty, and the evidence: a likelihood-ratio test that allows for the parameter on its bound, ΔAICc, and the χ² of predicting each frequency held out of the fit. \"none\" means no effect of the library explains the misfit well enough, or there is no misfit to explain.</p>");
    if !groups.is_empty() {
        let _ = write!(
            h,
            "<h2>Pooled over groups</h2><p>The pooled test adds the members' likelihood-ratio gains (the χ² each member's refit with the effect removes; its one-sided score where the effect was not refitted) for each candidate effect; under \"no effect\" the sum of n members follows the mixture Σ C(n,k)2<sup>−n</sup>χ²<sub>k</sub>. A group detects an effect when its p-value is below {} divided by the number of effects tested and by the number of groups; its members are then refitted with the effect. Members with a misfit far above the noise that no physical effect explains (a wrong record, a unit or transcription error) are left out of the sum.</p><table><tr><th>group</th><th>segments</th><th>detected effect</th><th>ambiguous with</th><th>statistic</th><th>p</th><th>refitted</th><th>all effects</th></tr>",
            sig(super::group::GROUP_ALPHA, 2)
        );
        for g in groups {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&g.group),
                g.members.len(),
                g.effect.map(|e| e.name()).unwrap_or("none"),
                g.ambiguous_with.iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
                sig(g.statistic(), 4),
                sig(g.p_value(), 2),
                g.n_refitted,
                esc(&g
                    .pooled
                    .iter()
                    .map(|p| format!("{} {} (p {})", p.effect.name(), sig(p.statistic, 3), sig(p.p_value, 2)))
                    .collect::<Vec<_>>()
                    .join("; "))
            );
        }
        h.push_str("</table>");
    }
    // Every segment, findings first, folded away: the page leads with what to act on.
    let _ = write!(
        h,
        "<details><summary>All {} segments diagnosed</summary>{HEAD}",
        diags.len()
    );
    for (id, d) in &findings {
        row(&mut h, id, d);
    }
    for (id, d) in ids
        .iter()
        .zip(diags)
        .filter(|(_, d)| !(d.structure.structured || d.named.is_some()))
    {
        row(&mut h, id, d);
    }
    h.push_str("</table></details>");
    // Detail for the segments that have something to show, at most MAX_DETAILED of them, so
    // that the page stays readable for a whole network.
    let _ = write!(
        h,
        "<h2>Segments</h2><p>Residuals and candidates for {} segments{}.</p>",
        detailed.len(),
        if diags.len() > 50 {
            " with misfit far above the noise or a named effect"
        } else {
            ""
        }
    );
    for &(id, d) in &detailed {
        let _ = write!(
            h,
            "<div class=\"seg\" id=\"{}\"><h3>{}</h3>",
            anchor(id),
            esc(id)
        );
        if d.assumed_noise {
            h.push_str("<p><em>No measurement standard deviations were stated: 1 % on Re k and 10 % on the attenuation were assumed.</em></p>");
        }
        let _ = write!(
            h,
            "<p>Residual pattern: {}. Where: {}. χ²/dof before and after each candidate: {}.</p>",
            esc(&d.structure.pattern),
            esc(&residual_runs(&d.before)),
            esc(&candidates_chi2(d))
        );
        if let Some(t) = record_sentence(d).or_else(|| units_sentence(id, d)) {
            let _ = write!(h, "<p><strong>{}</strong></p>", esc(&t));
        }
        for a in &d.ambiguity {
            let _ = write!(
                h,
                "<p>Indistinguishable from {}: both change the {}. To separate them: {}.</p>",
                a.effect.name(),
                esc(a.quantity),
                esc(&a.separating)
            );
        }
        h.push_str(&residual_svg(&d.before, d.after.as_ref()));
        h.push_str("<table><tr><th>candidate</th><th>meaning</th><th>score</th><th>χ²/dof after</th><th>LR</th><th>p</th><th>ΔAICc</th><th>held-out χ² base → ext</th><th>accepted</th></tr>");
        for c in &d.candidates {
            let after = c
                .refit
                .as_ref()
                .map(|r| chi(r.fit.chi2_per_dof.unwrap_or(f64::NAN)))
                .unwrap_or_default();
            let (lr, p, da, ho, acc) = match &c.refit {
                Some(r) => (
                    sig(r.lr, 4),
                    sig(r.p_value, 2),
                    sig(r.d_aicc, 3),
                    format!("{} → {}", sig(r.holdout_base, 3), sig(r.holdout_ext, 3)),
                    if r.accepted { "yes" } else { "no" },
                ),
                None => (
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    "not refitted",
                ),
            };
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{after}</td><td>{lr}</td><td>{p}</td><td>{da}</td><td>{ho}</td><td>{acc}</td></tr>",
                c.effect.name(),
                esc(c.effect.meaning()),
                if c.score.is_nan() { "n/a".to_string() } else { sig(c.score, 3) }
            );
        }
        h.push_str("</table></div>");
    }
    h.push_str("</body></html>\n");
    crate::outfile::write_bytes(path, crate::outfile::Contents::Plain, h.as_bytes())
        .map_err(std::io::Error::other)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchors_are_plain_and_unique() {
        assert_eq!(anchor("WM10052"), "s-WM10052");
        assert_eq!(anchor("A&B <1>"), "s-A_26_B_20__3c_1_3e_");
        assert_ne!(anchor("a_b"), anchor("a b"));
        assert!(anchor("é#x")
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b)));
    }

    #[test]
    fn ticks_are_round_and_inside() {
        assert_eq!(
            ticks(95.0, 1050.0, 6),
            vec![200.0, 400.0, 600.0, 800.0, 1000.0]
        );
        assert_eq!(ticks(-4.4, 4.4, 6), vec![-4.0, -2.0, 0.0, 2.0, 4.0]);
        assert_eq!(chi(f64::NAN), "–");
    }

    #[test]
    fn residual_plots_have_ticks_axis_titles_and_a_legend() {
        let r = Residuals {
            frequency_hz: vec![100.0, 300.0, 500.0],
            re: vec![0.5, -3.0, 1.0],
            att: vec![2.5, 0.1, -0.4],
        };
        let svg = residual_svg(&r, Some(&r));
        for text in [
            "frequency (Hz)",
            "residual / σ",
            "Re k, before",
            "attenuation, after",
            "±2σ",
            ">300<",
            ">-2<",
        ] {
            assert!(svg.contains(text), "{text} missing: {svg}");
        }
    }

    #[test]
    fn residual_runs_name_where_and_by_how_much() {
        let r = Residuals {
            frequency_hz: vec![400.0, 100.0, 200.0, 300.0, 500.0],
            re: vec![0.5, -0.3, 1.0, 0.2, -1.9],
            att: vec![-14.0, 0.1, 3.0, -9.0, 15.0],
        };
        assert_eq!(
            residual_runs(&r),
            "attenuation: model above by 3.0σ at 200 Hz; below by 9.0–14σ at 300–400 Hz; above by 15σ at 500 Hz"
        );
        let quiet = Residuals {
            frequency_hz: vec![100.0, 200.0],
            re: vec![0.5, -1.0],
            att: vec![1.5, -2.0],
        };
        assert_eq!(residual_runs(&quiet), "no residual beyond 2σ");
    }

    #[test]
    fn groups_csv_names_the_statistic_and_the_members_carrying_the_effect() {
        // Members 1 and 3 carry thinning best (gains 9 and 6 above the others'); member 0's
        // largest gain is pipe_loss's, member 2's thinning gain is below the carrying cut.
        let g = |t: f64, l: f64| {
            vec![
                (Effect::WallThinning, t),
                (Effect::PipeLoss, l),
                (Effect::AirInWater, 0.0),
            ]
        };
        let mut scores = vec![g(5.0, 7.0), g(9.0, 0.0), g(2.0, 0.0), g(6.0, 1.0)];
        scores.extend((0..16).map(|_| g(4.0, 0.5)));
        let members: Vec<usize> = (0..4).collect();
        let t = super::super::group::pooled_score_test("CI 1925-1954", &members, &scores);
        assert_eq!(t.effect, Some(Effect::WallThinning));
        assert_eq!(t.carrying, vec![1, 3]);
        let ids: Vec<String> = (0..20).map(|i| format!("=S{i}")).collect();
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("groups.csv");
        write_groups_csv(&path, &ids, &[t]).expect("write");
        let mut r = csv::Reader::from_path(&path).expect("read");
        let head: Vec<String> = r
            .headers()
            .expect("header")
            .iter()
            .map(String::from)
            .collect();
        assert_eq!(head, GROUP_CSV_COLUMNS);
        let row = r.records().next().expect("row").expect("record");
        let col = |n: &str| row[head.iter().position(|h| h == n).expect(n)].to_string();
        assert_eq!(col("statistic_kind"), "lr_gain_sum");
        assert_eq!(col("members_carrying"), "2");
        // Formula-like ids are neutralised for spreadsheets; the list is joined by ';'.
        assert_eq!(col("members"), "'=S1;=S3");
        assert_eq!(col("named_effect"), "wall_thinning");
        assert_eq!(col("n_segments"), "4");
        // No twin pair detected: no comparison.
        assert_eq!(col("twin_comparison"), "");
        let c = super::super::group::TwinComparison {
            first: Effect::WallThinning,
            second: Effect::AirInWater,
            first_gain: 209.62,
            second_gain: 192.72,
            first_fraction: 0.75,
            second_fraction: 0.4167,
            first_deviation: 0.1234,
            members: 12,
        };
        assert_eq!(
            twin_text(&c),
            "wall_thinning 209.6 (fraction 0.75, deviation 0.123) over air_in_water 192.7 (fraction 0.42); 12 members"
        );
    }
}

#[cfg(test)]
mod number_cells {
    use super::{holdout_text, num, p_num, with_error};

    #[test]
    fn cells_follow_the_export_rounding_and_p_values_are_scientific() {
        assert_eq!(p_num(1.234_567e-180), "1.23e-180");
        assert_eq!(p_num(0.5), "5.00e-1");
        assert_eq!(p_num(f64::NAN), "");
        assert_eq!(num(38.425_612_345), "38.4256");
        assert_eq!(num(f64::INFINITY), "");
        assert_eq!(
            with_error(0.612_345_678, Some(0.013_579)),
            ("0.612".to_string(), "0.014".to_string())
        );
        assert!(!holdout_text(f64::INFINITY).contains("inf"));
        assert!(!holdout_text(f64::NAN).contains("NaN"));
        assert_eq!(holdout_text(12.345), "12.3");
    }
}
