//! The audit's section "What changed since the last campaign": the change test of model
//! §7.14 (P94–P96) over the network, as counts by finding and cause, the changed pipes with
//! what to do about each, largest speed change first, and a map of the speed changes.

use super::*;

/// Changed pipes listed by id (the rest are counted).
pub const CHANGES_LISTED: usize = 100;
/// Width of the speed-change map, px.
pub(super) const CHANGE_MAP_WIDTH_PX: f64 = 800.0;

/// A changed pipe of the list.
pub(super) struct ChangeEntry {
    id: String,
    since: String,
    campaign: String,
    /// %Δv of the leak-band speed and its one-sigma error (P94's companion, §7.14).
    pct: Option<f64>,
    pct_std: Option<f64>,
    p_value: Option<f64>,
    effect: String,
    ambiguous_with: String,
    speed_by_campaign: String,
}

/// The change findings of every record, tallied.
pub(super) struct ChangeTally {
    /// Segments whose latest fit was tested against an earlier campaign.
    pub tested: usize,
    pub changed: usize,
    pub unchanged: usize,
    /// Unchanged and fitted from both campaigns (P96).
    pub pooled: usize,
    /// Measured in two campaigns but not tested (the note says why).
    pub untested: usize,
    /// Changed pipes by cause (`unexplained` among them).
    pub by_effect: BTreeMap<String, usize>,
    /// The pairs of campaigns compared, with their counts.
    pub pairs: BTreeMap<(String, String), usize>,
    /// The changed pipes, largest |%Δv| first.
    pub listed: Top<ChangeEntry>,
    /// The levels the tests were judged at, as stored with each finding (`changes.alpha`).
    pub levels: BTreeSet<String>,
}

/// Largest speed change first (a change without a figure last), then by id.
fn largest_first(a: &ChangeEntry, b: &ChangeEntry) -> Ordering {
    let size = |e: &ChangeEntry| e.pct.map_or(-1.0, f64::abs);
    size(b).total_cmp(&size(a)).then(a.id.cmp(&b.id))
}

impl ChangeTally {
    pub fn new() -> Self {
        ChangeTally {
            tested: 0,
            changed: 0,
            unchanged: 0,
            pooled: 0,
            untested: 0,
            by_effect: BTreeMap::new(),
            pairs: BTreeMap::new(),
            listed: Top::new(CHANGES_LISTED, largest_first),
            levels: BTreeSet::new(),
        }
    }

    /// Count one record; the speed change to draw on the map (changed pipes only).
    pub fn add(&mut self, r: &SegmentExport) -> Option<f64> {
        let c = r.change.as_ref()?;
        match c.status.as_str() {
            "changed" | "unchanged" => {}
            "untested" => {
                self.untested += 1;
                return None;
            }
            _ => return None,
        }
        self.tested += 1;
        if let Some(a) = c.alpha {
            self.levels.insert(sig(a, 2));
        }
        if let Some(since) = &c.since_campaign {
            *self
                .pairs
                .entry((since.clone(), c.campaign.clone()))
                .or_default() += 1;
        }
        if c.status == "unchanged" {
            self.unchanged += 1;
            self.pooled += usize::from(c.pooled);
            return None;
        }
        self.changed += 1;
        let effect = c
            .effect
            .clone()
            .unwrap_or_else(|| "unexplained".to_string());
        *self.by_effect.entry(effect.clone()).or_default() += 1;
        self.listed.push(ChangeEntry {
            id: r.id().to_string(),
            since: c.since_campaign.clone().unwrap_or_default(),
            campaign: c.campaign.clone(),
            pct: c.leak_band_speed_pct.filter(|v| v.is_finite()),
            pct_std: c.leak_band_speed_pct_std.filter(|v| v.is_finite()),
            p_value: c.p_value,
            effect,
            ambiguous_with: c.ambiguous_with.clone(),
            speed_by_campaign: r.speed_by_campaign.clone().unwrap_or_default(),
        });
        c.leak_band_speed_pct.filter(|v| v.is_finite())
    }
}

/// A p-value as the list prints it: two digits, and below the double's resolution of a
/// χ² tail (1e-16 of 1) as a bound rather than a spurious 0.
fn p_value(p: f64) -> String {
    if p < P_SHOWN_MIN {
        format!("< {P_SHOWN_MIN:.0e}")
    } else {
        format!("{p:.1e}")
    }
}

/// The smallest p-value printed as a number.
const P_SHOWN_MIN: f64 = 1e-16;

/// What a crew does about a change of this cause (model §7.14, P95's causes).
pub fn advice(effect: &str) -> &'static str {
    match effect {
        "soil_change" => {
            "the soil around the pipe changed (drying, wetting, frost): use the current speed, \
             not last campaign's"
        }
        "air_in_water" => {
            "air in the main (E3): bleed it at the high points, then use the current speed or \
             measure again"
        }
        "wall_thinning" => "the wall is thinner (E4): inspect it for corrosion or leaching",
        "pipe_loss" => {
            "the wall's loss changed (E2): check for a repair, a liner or a replaced length"
        }
        _ => {
            "no single cause explains the change: check the records and the measurements of \
             both campaigns"
        }
    }
}

/// The diverging classes of the speed-change map, symmetric about zero: 8 classes whose middle
/// edge is 0 (a fall red, a rise blue), spanning the 98th percentile of |%Δv|.
fn change_scale(drawn: &[Drawn]) -> ColourScale {
    let sizes = sorted_finite(drawn.iter().filter_map(|d| d.change_pct.map(f64::abs)));
    let m = quantile(&sizes, 0.98).filter(|m| *m > 0.0).unwrap_or(1.0);
    // 8 classes: 2 open-ended and 6 between lo and hi, so the 4th of the 7 edges is 0.
    ColourScale { lo: -m, hi: m }
}

/// The map of the speed changes: changed pipes coloured by %Δv, the others grey. Drawn in the
/// same pass over the geometries as the other maps.
pub(super) fn change_canvas(
    t: &Tally,
    geographic: bool,
    metres_per_unit: Option<f64>,
) -> Option<MapCanvas<'static>> {
    if t.changes.changed == 0 {
        return None;
    }
    let scale = change_scale(&t.drawn);
    let values = sorted_finite(t.drawn.iter().filter_map(|d| d.change_pct));
    let style = MapStyle {
        unit: "%",
        decimals: 1,
        scale: Some(scale),
        palette: &svg::FALL_RED_RISE_BLUE_8,
        width: CHANGE_MAP_WIDTH_PX,
        metres_per_unit,
    };
    Some(MapCanvas::new(
        t.bbox,
        t.drawn.len(),
        &values,
        geographic,
        &style,
    ))
}

/// The section; `map` is the drawn speed-change map, if any segment changed and has a geometry.
pub(super) fn section(h: &mut String, t: &Tally, map: Option<String>) {
    let c = &t.changes;
    h.push_str("<section id=\"changes\"><h2>What changed since the last campaign</h2>");
    if c.tested == 0 && c.untested == 0 {
        h.push_str(
            "<p class=\"note\">No segment is measured in two campaigns. Import a second \
             campaign beside the first (a new <code>campaign</code> name in \
             <code>measurements.csv</code>) and the next run tests every re-measured pipe for a \
             change (README, \"A second campaign\").</p></section>",
        );
        return;
    }
    let pairs = c
        .pairs
        .iter()
        .map(|((a, b), n)| format!("{} → {} ({n})", escape(a), escape(b)))
        .collect::<Vec<_>>()
        .join(", ");
    let _ = write!(
        h,
        "<p><b>{changed} of {tested} re-measured segment{s} changed</b> since their previous \
         campaign ({pairs}); {unchanged} unchanged, {pooled} of them fitted from both campaigns \
         (a smaller error).{untested} A changed pipe's current speed is its latest campaign's: \
         give the correlator that, never last campaign's. Each change is tested at a false-alarm \
         rate of {alpha} per pipe (model §7.14, P94).</p>",
        changed = c.changed,
        tested = c.tested,
        s = if c.tested == 1 { "" } else { "s" },
        unchanged = c.unchanged,
        pooled = c.pooled,
        untested = if c.untested > 0 {
            format!(
                " {} more measured twice but not tested (see <code>change_note</code>).",
                c.untested
            )
        } else {
            String::new()
        },
        alpha = if c.levels.is_empty() {
            "–".to_string()
        } else {
            c.levels.iter().cloned().collect::<Vec<_>>().join(", ")
        },
    );
    if c.changed == 0 {
        h.push_str("</section>");
        return;
    }
    h.push_str(
        "<table class=\"change-causes\"><tr><th>cause</th><th>pipes</th><th>what to do</th></tr>",
    );
    let mut causes: Vec<(&String, &usize)> = c.by_effect.iter().collect();
    causes.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    for (effect, n) in causes {
        let _ = write!(
            h,
            "<tr><td><code>{}</code></td><td class=\"n\">{n}</td><td>{}</td></tr>",
            escape(effect),
            escape(advice(effect))
        );
    }
    h.push_str("</table>");
    let listed = &c.listed.items;
    let _ = write!(
        h,
        "<p class=\"note\">The changed pipes, largest change of the leak-band speed first{}. \
         The change is that of the two campaigns fitted each on its own, ± one sigma. A cause \
         \"ambiguous with\" others fits the data as well as they do (within 2 in AICc).</p>\
         <table class=\"changes\"><tr><th>segment</th><th>since</th><th>speed change (%)</th>\
         <th>p-value</th><th>cause</th><th>ambiguous with</th><th>speed by campaign (m/s)</th>\
         </tr>",
        if c.changed > listed.len() {
            format!(
                " ({} of {} listed; all are in the exports)",
                listed.len(),
                c.changed
            )
        } else {
            String::new()
        }
    );
    for e in listed {
        let pct = match (e.pct, e.pct_std) {
            (Some(v), Some(s)) => format!("{v:+.1} ± {s:.1}"),
            (Some(v), None) => format!("{v:+.1}"),
            _ => "–".to_string(),
        };
        let _ = write!(
            h,
            "<tr><td class=\"segment\">{}</td><td>{} → {}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td><code>{}</code></td><td>{}</td><td>{}</td></tr>",
            escape(&e.id),
            escape(&e.since),
            escape(&e.campaign),
            pct,
            e.p_value.map_or_else(|| "–".to_string(), p_value),
            escape(&e.effect),
            escape(if e.ambiguous_with.is_empty() {
                "–"
            } else {
                &e.ambiguous_with
            }),
            escape(if e.speed_by_campaign.is_empty() {
                "–"
            } else {
                &e.speed_by_campaign
            }),
        );
    }
    h.push_str("</table>");
    match map {
        Some(m) => {
            let _ = write!(
                h,
                "<h3>Change of the leak-band speed since the previous campaign (%)</h3>\
                 <p class=\"note\">Changed pipes only, red where the speed fell (air, a thinner \
                 wall, a softer soil), blue where it rose; grey: unchanged, not re-measured or \
                 without a geometry.</p>{m}"
            );
        }
        None => h.push_str("<p class=\"note\">No changed pipe has a geometry to map.</p>"),
    }
    h.push_str("</section>");
}
