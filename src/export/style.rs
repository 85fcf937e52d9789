//! The default QGIS style of the exports: each segment coloured by its leak-band speed
//! ([`STYLE_FIELD`]), with a legend in m/s and class breaks taken from the data, and drawn as
//! the audit's maps draw it by how far it can be trusted ([`Trust`]: a flagged or failed
//! segment dashed over a dark casing, a prediction dotted).
//!
//! The same QML document goes into the GeoPackage's `layer_styles` table (QGIS's own layout, see
//! [`LAYER_STYLES_SQL`]) and, for a GeoJSON or CSV export, into a `.qml` file beside it (QGIS
//! loads `NAME.qml` as the default style of `NAME.geojson`).

use std::path::{Path, PathBuf};

use crate::types::Trust;

/// The field the style colours by (a property of [`super::PROPERTIES`]).
pub const STYLE_FIELD: &str = "leak_band_speed_m_per_s";

/// The style's name in `layer_styles`.
pub const STYLE_NAME: &str = "pipewave leak-band speed";

/// Number of classes: five, the usual choice for a sequential map (ColorBrewer offers 3–11;
/// five colours stay distinguishable on a line layer).
pub const N_CLASSES: usize = 5;

/// The class colours, slow to fast: ColorBrewer "Spectral" with 5 classes (Brewer, Harrower &
/// Penn State, colorbrewer2.org), also QGIS's default "Spectral" ramp. Slow segments (plastic
/// pipes, soft soil) are red, fast ones blue.
pub const CLASS_COLOURS: [(u8, u8, u8); N_CLASSES] = [
    (215, 25, 28),
    (253, 174, 97),
    (255, 255, 191),
    (171, 221, 164),
    (43, 131, 186),
];

/// Class breaks are rounded to this many m/s, so the legend reads 1040 – 1120 m/s, not
/// 1043.27 – 1118.9 (a leak correlator takes whole m/s; the fits' own errors are larger).
pub const BREAK_ROUNDING_M_PER_S: f64 = 10.0;

/// Breaks used when no segment has a leak-band speed yet (nothing fitted): 0 – 1500 m/s in equal
/// classes, spanning every buried water pipe (the free-water sound speed is about 1480 m/s and
/// the pipe-fluid wave is always slower).
pub const FALLBACK_RANGE_M_PER_S: (f64, f64) = (0.0, 1500.0);

/// The QGIS table that stores layer styles in a GeoPackage, as QGIS's OGR provider creates it
/// (`QgsOgrProviderMetadata::saveStyle`: GDAL layer `layer_styles` with FID `id` and these
/// fields: strings of width 256/30, `useAsDefault` an integer of subtype boolean, `update_time`
/// a date-time defaulting to the current time), in the SQL GDAL's GeoPackage driver writes for it.
pub const LAYER_STYLES_SQL: &str = "CREATE TABLE \"layer_styles\" (\
\"id\" INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
\"f_table_catalog\" TEXT(256), \
\"f_table_schema\" TEXT(256), \
\"f_table_name\" TEXT(256), \
\"f_geometry_column\" TEXT(256), \
\"styleName\" TEXT(30), \
\"styleQML\" TEXT, \
\"styleSLD\" TEXT, \
\"useAsDefault\" BOOLEAN, \
\"description\" TEXT, \
\"owner\" TEXT(30), \
\"ui\" TEXT(30), \
\"update_time\" DATETIME DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')))";

/// The style file beside an export: `FILE` with the extension `.qml` (QGIS loads `net.qml` as
/// the default style of `net.geojson` or `net.csv`). An export itself named `*.qml` gets
/// `*.qml.qml`, so the style never replaces it.
pub fn qml_path(out: &Path) -> PathBuf {
    let is_qml = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("qml"));
    if is_qml {
        let mut name = out.as_os_str().to_owned();
        name.push(".qml");
        PathBuf::from(name)
    } else {
        out.with_extension("qml")
    }
}

/// The class breaks (N + 1 increasing values, m/s) for the segments' leak-band speeds:
/// quantiles of the finite speeds, rounded outward to [`BREAK_ROUNDING_M_PER_S`], repeated
/// breaks merged (so fewer classes when the speeds are few or equal). The first break is at or
/// below the slowest speed and the last at or above the fastest, so every speed is in a class.
pub fn class_breaks(speeds: impl IntoIterator<Item = f64>) -> Vec<f64> {
    let mut speeds: Vec<f64> = speeds.into_iter().filter(|v| v.is_finite()).collect();
    speeds.sort_by(f64::total_cmp);
    let r = BREAK_ROUNDING_M_PER_S;
    let (Some(&lo), Some(&hi)) = (speeds.first(), speeds.last()) else {
        let (a, b) = FALLBACK_RANGE_M_PER_S;
        return (0..=N_CLASSES)
            .map(|i| a + (b - a) * i as f64 / N_CLASSES as f64)
            .collect();
    };
    let mut breaks = vec![(lo / r).floor() * r];
    for i in 1..N_CLASSES {
        // Type-7 quantile position i/N (linear between order statistics).
        let h = (speeds.len() - 1) as f64 * i as f64 / N_CLASSES as f64;
        let (k, frac) = (h.floor() as usize, h - h.floor());
        let next = speeds[(k + 1).min(speeds.len() - 1)];
        let q = speeds[k] + frac * (next - speeds[k]);
        breaks.push((q / r).round() * r);
    }
    breaks.push((hi / r).ceil() * r);
    if breaks[N_CLASSES] <= breaks[0] {
        // All speeds equal and on a rounding step: one class one step wide.
        breaks[N_CLASSES] = breaks[0] + r;
    }
    breaks.dedup_by(|b, a| *b <= *a);
    breaks
}

/// A colour as QGIS writes it: `r,g,b,a`.
fn rgba((r, g, b): (u8, u8, u8)) -> String {
    format!("{r},{g},{b},255")
}

/// One QGIS `<Option>` of a map.
fn opt(name: &str, value: &str) -> String {
    format!("<Option type=\"QString\" name=\"{name}\" value=\"{value}\"/>")
}

/// Width of a segment's line, mm.
const LINE_WIDTH_MM: &str = "0.8";
/// Width of the dark casing under a distrusted segment, mm (its dashes are drawn over it).
const CASING_WIDTH_MM: &str = "1.6";
/// The casing's colour.
const CASING_COLOUR: (u8, u8, u8) = (17, 17, 17);
/// Colour of segments without a leak-band speed.
const NO_VALUE_COLOUR: (u8, u8, u8) = (176, 176, 176);

/// One QGIS 3 `SimpleLine` symbol layer.
fn simple_line(colour: (u8, u8, u8), style: &str, width_mm: &str) -> String {
    let options = [
        opt("capstyle", "round"),
        opt("joinstyle", "round"),
        opt("line_color", &rgba(colour)),
        opt("line_style", style),
        opt("line_width", width_mm),
        opt("line_width_unit", "MM"),
        opt("offset", "0"),
        opt("offset_unit", "MM"),
    ]
    .concat();
    format!(
        "<layer class=\"SimpleLine\" enabled=\"1\" locked=\"0\" pass=\"0\"><Option type=\"Map\">{options}</Option></layer>"
    )
}

/// The line symbol of a class colour for one kind of segment ([`Trust`], as the audit's maps
/// draw it): solid; dotted for a prediction; dashed over a dark casing when distrusted.
fn line_symbol(name: &str, colour: (u8, u8, u8), trust: Trust) -> String {
    let layers = match trust {
        Trust::Trusted => simple_line(colour, "solid", LINE_WIDTH_MM),
        Trust::Predicted => simple_line(colour, "dot", LINE_WIDTH_MM),
        Trust::Distrusted => [
            simple_line(CASING_COLOUR, "solid", CASING_WIDTH_MM),
            simple_line(colour, "dash", LINE_WIDTH_MM),
        ]
        .concat(),
    };
    format!(
        "<symbol type=\"line\" name=\"{name}\" alpha=\"1\" clip_to_extent=\"1\" force_rhr=\"0\">{layers}</symbol>"
    )
}

/// A class break as written in the legend: whole m/s (breaks are rounded to 10 m/s).
fn speed(v: f64) -> String {
    format!("{v:.0}")
}

/// The kinds of segment the style tells apart, with the filter on the exported `status` that
/// selects each and its legend label.
const KINDS: [(Trust, &str, &str); 3] = [
    (
        Trust::Trusted,
        "&quot;status&quot; NOT IN ('flagged', 'failed', 'predicted')",
        "trusted",
    ),
    (
        Trust::Predicted,
        "&quot;status&quot; = 'predicted'",
        "predicted, not measured (dotted)",
    ),
    (
        Trust::Distrusted,
        "&quot;status&quot; IN ('flagged', 'failed')",
        "flagged or failed: distrust (dashed, outlined)",
    ),
];

/// The QML document (QGIS 3.28 LTR and later): a rule-based renderer with one rule per kind of
/// segment (`KINDS`: trusted, predicted, distrusted), each holding one rule per class of
/// [`STYLE_FIELD`] ([`class_breaks`], labelled `LOW – HIGH m/s`, coloured by [`CLASS_COLOURS`],
/// interpolated down to fewer colours when there are fewer classes) and one for segments
/// without a speed (grey). A flagged segment keeps its class colour, dashed over a dark casing,
/// so it reads as distrusted at any speed. `speeds`: the segments' leak-band speeds, m/s.
pub fn qml(speeds: impl IntoIterator<Item = f64>) -> String {
    let breaks = class_breaks(speeds);
    let n = breaks.len().saturating_sub(1);
    let colour = |i: usize| {
        // Spread n classes over the 5 colours, ends kept.
        let j = if n <= 1 {
            N_CLASSES / 2
        } else {
            (i * (N_CLASSES - 1) + (n - 1) / 2) / (n - 1)
        };
        CLASS_COLOURS[j.min(N_CLASSES - 1)]
    };
    let field = format!("&quot;{STYLE_FIELD}&quot;");
    let mut rules = String::new();
    let mut symbols = String::new();
    let mut k = 0;
    for (trust, filter, label) in KINDS {
        rules.push_str(&format!(
            "<rule key=\"{}\" filter=\"{filter}\" label=\"{label}\">",
            trust_key(trust)
        ));
        for i in 0..n {
            let (lo, hi) = (breaks[i], breaks[i + 1]);
            // The last class is closed above, so the fastest segment is in it.
            let upper = if i + 1 == n { "&lt;=" } else { "&lt;" };
            rules.push_str(&format!(
                "<rule key=\"{}-{i}\" symbol=\"{k}\" filter=\"{field} &gt;= {lo} AND {field} {upper} {hi}\" \
                 label=\"{} – {} m/s\"/>",
                trust_key(trust),
                speed(lo),
                speed(hi)
            ));
            symbols.push_str(&line_symbol(&k.to_string(), colour(i), trust));
            k += 1;
        }
        rules.push_str(&format!(
            "<rule key=\"{}-none\" symbol=\"{k}\" filter=\"{field} IS NULL\" label=\"no speed\"/></rule>",
            trust_key(trust)
        ));
        symbols.push_str(&line_symbol(&k.to_string(), NO_VALUE_COLOUR, trust));
        k += 1;
    }
    format!(
        "<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>\n\
<qgis version=\"3.28.0-Firenze\" styleCategories=\"Symbology\">\n\
<renderer-v2 type=\"RuleRenderer\" symbollevels=\"0\" enableorderby=\"0\" forceraster=\"0\" \
referencescale=\"-1\">\n\
<rules key=\"{{pipewave-root}}\">{rules}</rules>\n\
<symbols>{symbols}</symbols>\n\
</renderer-v2>\n\
<legend type=\"default-vector\" showLabelLegend=\"0\"/>\n\
<layerGeometryType>1</layerGeometryType>\n\
</qgis>\n"
    )
}

/// The key of a kind's rule.
fn trust_key(t: Trust) -> &'static str {
    match t {
        Trust::Trusted => "trusted",
        Trust::Predicted => "predicted",
        Trust::Distrusted => "distrusted",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 101 speeds 400, 410, ..., 1400.
    fn speeds() -> Vec<f64> {
        (0..=100).map(|i| 400.0 + 10.0 * f64::from(i)).collect()
    }

    #[test]
    fn breaks_are_rounded_quantiles_covering_every_speed() {
        // 101 speeds 400, 410, ..., 1400: quantiles at 600, 800, 1000, 1200.
        assert_eq!(
            class_breaks(speeds()),
            [400.0, 600.0, 800.0, 1000.0, 1200.0, 1400.0]
        );
        // Ends rounded outward: 433 -> 430, 1417 -> 1420.
        let b = class_breaks([433.0, 1417.0, f64::NAN]);
        assert_eq!((b[0], *b.last().unwrap()), (430.0, 1420.0));
        assert!(b.windows(2).all(|w| w[0] < w[1]), "{b:?}");
    }

    #[test]
    fn equal_or_missing_speeds_still_give_increasing_breaks() {
        let b = class_breaks([1000.0, 1000.0]);
        assert_eq!(b, [1000.0, 1010.0]);
        let b = class_breaks([]);
        assert_eq!(b, [0.0, 300.0, 600.0, 900.0, 1200.0, 1500.0]);
    }

    #[test]
    fn the_style_file_is_beside_the_export() {
        assert_eq!(
            qml_path(Path::new("out/net.geojson")),
            Path::new("out/net.qml")
        );
        assert_eq!(qml_path(Path::new("net.csv")), Path::new("net.qml"));
        assert_eq!(qml_path(Path::new("net")), Path::new("net.qml"));
        assert_eq!(qml_path(Path::new("a.QML")), Path::new("a.QML.qml"));
    }

    #[test]
    fn qml_names_the_field_and_labels_in_m_per_s() {
        let q = qml(speeds());
        assert!(q.contains("type=\"RuleRenderer\""));
        assert!(
            q.contains(
                "filter=\"&quot;leak_band_speed_m_per_s&quot; &gt;= 400 AND \
             &quot;leak_band_speed_m_per_s&quot; &lt; 600\" label=\"400 – 600 m/s\""
            ),
            "{q}"
        );
        assert!(q.contains("&lt;= 1400\" label=\"1200 – 1400 m/s\""));
        // Five classes and "no speed" for each of the three kinds.
        assert_eq!(q.matches("<symbol ").count(), 18);
        assert!(q.contains("215,25,28,255") && q.contains("43,131,186,255"));
    }

    #[test]
    fn flagged_segments_are_dashed_over_a_casing_in_their_class_colour() {
        let q = qml(speeds());
        let distrusted = &q[q.find("<rule key=\"distrusted\"").unwrap()..];
        assert!(distrusted.starts_with(
            "<rule key=\"distrusted\" filter=\"&quot;status&quot; IN ('flagged', 'failed')\""
        ));
        // Its first class rule's symbol: a dark solid casing, then the class colour dashed.
        let k: usize = distrusted[distrusted.find("symbol=\"").unwrap() + 8..]
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let sym = &q[q
            .find(&format!("<symbol type=\"line\" name=\"{k}\""))
            .unwrap()..];
        let sym = &sym[..sym.find("</symbol>").unwrap()];
        let casing = sym.find("17,17,17,255").unwrap();
        let dash = sym.find("\"line_style\" value=\"dash\"").unwrap();
        assert!(casing < dash && sym.contains("215,25,28,255"), "{sym}");
        // Trusted segments are solid and never match a flagged status.
        let trusted = &q[q.find("<rule key=\"trusted\"").unwrap()..];
        assert!(trusted.contains("NOT IN ('flagged', 'failed', 'predicted')"));
    }
}
