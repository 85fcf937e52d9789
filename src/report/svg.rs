//! Hand-written SVG: escaping, the colour scale, the network map and inline bars.

use std::fmt::Write as _;

use crate::db::wkt::LineString;
use crate::types::Trust;

/// Escape text for HTML and XML content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            // Control characters are not allowed in XML 1.0.
            c if c.is_control() && c != '\n' && c != '\t' => out.push('\u{FFFD}'),
            c => out.push(c),
        }
    }
    out
}

/// Viridis, 9 classes (matplotlib's colour map sampled evenly): perceptually uniform and
/// readable by colour-blind readers, low speeds dark blue, high speeds yellow. For values that
/// are neither good nor bad (a wave speed).
pub const VIRIDIS_9: [&str; 9] = [
    "#440154", "#472d7b", "#3b528b", "#2c728e", "#21918c", "#28ae80", "#5ec962", "#addc30",
    "#fde725",
];

/// Small to large error, for values where large is bad: ColorBrewer "RdBu" with 10 classes
/// (Brewer, colorbrewer2.org; colour-blind safe), reversed, without its two darkest blues, so
/// the good end is a calm mid blue, the middle pale, and the bad end a saturated dark red: the
/// eye goes to the segments that need action.
pub const BAD_IS_RED_8: [&str; 8] = [
    "#4393c3", "#92c5de", "#d1e5f0", "#fddbc7", "#f4a582", "#d6604d", "#b2182b", "#67001f",
];

/// A fall to a rise, for a signed change with no good end (a wave speed's change between
/// campaigns): ColorBrewer "RdBu" with 8 classes (colour-blind safe), red for a fall, blue for
/// a rise, pale about zero.
pub const FALL_RED_RISE_BLUE_8: [&str; 8] = [
    "#b2182b", "#d6604d", "#f4a582", "#fddbc7", "#d1e5f0", "#92c5de", "#4393c3", "#2166ac",
];

/// Colour of segments without a value.
pub const NO_VALUE_COLOUR: &str = "#b0b0b0";

/// Line width of a segment, px: wide enough to tell colours apart on a network map.
pub const LINE_WIDTH_PX: f64 = 2.5;
/// Line width of a distrusted segment's dashes, px, drawn over a dark casing of
/// [`CASING_WIDTH_PX`], so a flagged pipe reads as a dashed, outlined line at any colour.
pub const DISTRUSTED_WIDTH_PX: f64 = 3.0;
/// Width of the casing under a distrusted segment, px.
pub const CASING_WIDTH_PX: f64 = 6.5;
/// Colour of that casing.
pub const CASING_COLOUR: &str = "#111111";

impl Trust {
    /// SVG stroke attributes of its line (colour `c`).
    fn stroke(self, c: &str) -> String {
        match self {
            Trust::Trusted => format!("stroke=\"{c}\""),
            Trust::Predicted => format!("stroke=\"{c}\" stroke-dasharray=\"1 5\""),
            Trust::Distrusted => format!(
                "stroke=\"{c}\" stroke-width=\"{DISTRUSTED_WIDTH_PX}\" stroke-dasharray=\"8 5\""
            ),
        }
    }
}

/// A classed colour scale: the palette's colours over equal-width classes between `lo` and
/// `hi` (the first and last classes are open-ended).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourScale {
    /// Upper edge of the first class.
    pub lo: f64,
    /// Lower edge of the last class.
    pub hi: f64,
}

impl ColourScale {
    /// Classes spanning the 2nd–98th percentiles of `sorted` values (so one outlier does not
    /// squeeze every other segment into one colour). `None` without values.
    pub fn from_sorted(sorted: &[f64]) -> Option<ColourScale> {
        let lo = crate::stats::quantile(sorted, 0.02)?;
        let hi = crate::stats::quantile(sorted, 0.98)?;
        let (lo, hi) = if hi - lo > 1e-9 * hi.abs().max(1.0) {
            (lo, hi)
        } else {
            (lo - 1.0, hi + 1.0)
        };
        Some(ColourScale { lo, hi })
    }

    /// The class of a value, 0..n for `n` classes (n ≥ 3).
    pub fn class(&self, v: f64, n: usize) -> usize {
        let inner = n - 2;
        if v < self.lo {
            0
        } else if v >= self.hi {
            n - 1
        } else {
            let t = (v - self.lo) / (self.hi - self.lo);
            1 + ((t * inner as f64) as usize).min(inner - 1)
        }
    }

    /// The bounds of a class of `n`, for the legend (None: open end).
    pub fn bounds(&self, class: usize, n: usize) -> (Option<f64>, Option<f64>) {
        let inner = (n - 2) as f64;
        let edge = |k: usize| self.lo + (self.hi - self.lo) * (k as f64) / inner;
        match class {
            0 => (None, Some(self.lo)),
            c if c >= n - 1 => (Some(self.hi), None),
            c => (Some(edge(c - 1)), Some(edge(c))),
        }
    }
}

/// Above this many segments the map draws one path per colour class and kind (no per-segment
/// tooltip), which keeps a 20,000-segment map to a few hundred kB and fast to render.
pub const MAP_TOOLTIP_LIMIT: usize = 2000;

/// One segment on the map.
#[derive(Debug, Clone)]
pub struct MapLine<'a> {
    /// Segment id (tooltip).
    pub id: &'a str,
    /// Geometry, in the map's coordinate system.
    pub line: &'a LineString,
    /// The value coloured (None: grey).
    pub value: Option<f64>,
    /// The tooltip's text after the id (None: the value with [`MapStyle::unit`]).
    pub label: Option<String>,
    /// How its line is drawn.
    pub trust: Trust,
}

/// How a map colours its values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapStyle<'a> {
    /// Unit of the values (tooltips).
    pub unit: &'a str,
    /// Decimals of the legend's class bounds and the default tooltip.
    pub decimals: usize,
    /// Fixed colour classes (None: the 2nd–98th percentiles of the values,
    /// [`ColourScale::from_sorted`]).
    pub scale: Option<ColourScale>,
    /// The class colours, first class first (at least 3).
    pub palette: &'static [&'static str],
    /// Width of the SVG, px.
    pub width: f64,
    /// Metres per unit of the map's coordinates, for the scale bar (None: no scale bar; for
    /// geographic coordinates give the metres of a degree of latitude).
    pub metres_per_unit: Option<f64>,
}

/// The network map: every segment as a polyline coloured by `value`, with a legend.
/// `geographic`: the coordinates are degrees (x scaled by cos(latitude) to keep shapes).
pub fn map(lines: &[MapLine<'_>], geographic: bool, style: &MapStyle<'_>) -> String {
    let mut bbox = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for l in lines {
        for &(x, y) in &l.line.points {
            bbox = [
                bbox[0].min(x),
                bbox[1].max(x),
                bbox[2].min(y),
                bbox[3].max(y),
            ];
        }
    }
    let values = crate::stats::sorted_finite(lines.iter().filter_map(|l| l.value));
    let mut canvas = MapCanvas::new(bbox, lines.len(), &values, geographic, style);
    for l in lines {
        canvas.add(l);
    }
    canvas.finish()
}

/// A [`map`] drawn one segment at a time, for networks too large to hold: made from what the
/// whole map needs first (the bounding box `[min x, max x, min y, max y]` of every line, the
/// number of lines, their sorted finite values), then given the lines in order
/// ([`Self::add`]), then closed ([`Self::finish`]). The SVG is that of [`map`] on the same lines.
/// Distrusted segments are drawn last, over the others, so none is hidden.
pub struct MapCanvas<'s> {
    style: MapStyle<'s>,
    scale: Option<ColourScale>,
    /// Tooltips: one path per segment; otherwise one path per colour class and kind.
    tooltips: bool,
    bbox: [f64; 4],
    kx: f64,
    s: f64,
    ox: f64,
    height: f64,
    svg: String,
    /// Per kind of line (in [`Trust`] order, drawn in that order): the casings and the paths
    /// of the segments drawn one by one (tooltips), or the path data by colour.
    layers: [Layer; 3],
    kinds_drawn: [bool; 3],
}

/// The paths of one [`Trust`] kind.
#[derive(Default)]
struct Layer {
    casing: String,
    paths: String,
    by_colour: Vec<(&'static str, String)>,
}

const LEGEND_H: f64 = 78.0;
const PAD: f64 = 10.0;

fn kind_index(t: Trust) -> usize {
    match t {
        Trust::Trusted => 0,
        Trust::Predicted => 1,
        Trust::Distrusted => 2,
    }
}

/// A round length for a scale bar at most `max_m` metres long: 1, 2 or 5 × 10^k.
pub fn scale_bar_length(max_m: f64) -> f64 {
    let k = 10f64.powf(max_m.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * k)
        .find(|&l| l <= max_m)
        .unwrap_or(k)
}

impl<'s> MapCanvas<'s> {
    /// A map of `n_lines` lines within `bbox`, coloured by the classes of `sorted_values` (or
    /// `style.scale`).
    pub fn new(
        bbox: [f64; 4],
        n_lines: usize,
        sorted_values: &[f64],
        geographic: bool,
        style: &MapStyle<'s>,
    ) -> Self {
        let width = style.width;
        let scale = style
            .scale
            .or_else(|| ColourScale::from_sorted(sorted_values));
        let kx = if geographic {
            ((bbox[2] + bbox[3]) / 2.0).to_radians().cos()
        } else {
            1.0
        };
        let dx = ((bbox[1] - bbox[0]) * kx).max(1e-9);
        let dy = (bbox[3] - bbox[2]).max(1e-9);
        let max_plot_h = 0.8 * width;
        let s = ((width - 2.0 * PAD) / dx).min(max_plot_h / dy);
        let plot_w = dx * s;
        let plot_h = dy * s;
        let height = plot_h + 2.0 * PAD + LEGEND_H;
        let ox = PAD + (width - 2.0 * PAD - plot_w) / 2.0;
        let mut svg = String::new();
        let _ = write!(
            svg,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" \
             viewBox=\"0 0 {width:.0} {height:.0}\" class=\"map\">\
             <rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>"
        );
        let _ = write!(
            svg,
            "<g fill=\"none\" stroke-width=\"{LINE_WIDTH_PX}\" stroke-linecap=\"round\" \
             stroke-linejoin=\"round\">"
        );
        let mut canvas = MapCanvas {
            style: *style,
            scale,
            tooltips: n_lines <= MAP_TOOLTIP_LIMIT,
            bbox,
            kx,
            s,
            ox,
            height,
            svg,
            layers: Default::default(),
            kinds_drawn: [false; 3],
        };
        if !canvas.tooltips {
            // Grey first, so coloured segments are drawn over it.
            let colours: Vec<&'static str> = std::iter::once(NO_VALUE_COLOUR)
                .chain(style.palette.iter().copied())
                .collect();
            for layer in &mut canvas.layers {
                layer.by_colour = colours.iter().map(|&c| (c, String::new())).collect();
            }
        }
        canvas
    }

    fn colour(&self, v: Option<f64>) -> &'static str {
        let p = self.style.palette;
        match (v, self.scale) {
            (Some(v), Some(sc)) => p[sc.class(v, p.len())],
            _ => NO_VALUE_COLOUR,
        }
    }

    /// The path data of a line, appended to `d`.
    fn path_d(&self, line: &LineString, d: &mut String) {
        let tx = |x: f64| self.ox + (x - self.bbox[0]) * self.kx * self.s;
        let ty = |y: f64| PAD + (self.bbox[3] - y) * self.s;
        let mut last: Option<(String, String)> = None;
        for (i, &(x, y)) in line.points.iter().enumerate() {
            let p = (format!("{:.1}", tx(x)), format!("{:.1}", ty(y)));
            if last.as_ref() == Some(&p) && i + 1 < line.points.len() {
                continue;
            }
            let _ = write!(d, "{}{} {}", if i == 0 { "M" } else { "L" }, p.0, p.1);
            last = Some(p);
        }
    }

    /// Draw the next segment.
    pub fn add(&mut self, l: &MapLine<'_>) {
        let c = self.colour(l.value);
        let k = kind_index(l.trust);
        self.kinds_drawn[k] = true;
        let mut d = String::new();
        self.path_d(l.line, &mut d);
        if l.trust == Trust::Distrusted {
            let layer = &mut self.layers[k];
            layer.casing.push_str(&d);
        }
        if self.tooltips {
            let dec = self.style.decimals;
            let v = match (&l.label, l.value) {
                (Some(t), _) => t.clone(),
                (None, Some(v)) => format!("{v:.dec$} {}", self.style.unit),
                (None, None) => "no value".to_string(),
            };
            let _ = write!(
                self.layers[k].paths,
                "<path {} d=\"{d}\"><title>{}: {}</title></path>",
                l.trust.stroke(c),
                escape(l.id),
                escape(&v)
            );
        } else if let Some(j) = self.layers[k].by_colour.iter().position(|(x, _)| *x == c) {
            self.layers[k].by_colour[j].1.push_str(&d);
        }
    }

    /// The SVG, with its legend and scale bar.
    pub fn finish(mut self) -> String {
        let mut svg = std::mem::take(&mut self.svg);
        for (k, layer) in self.layers.iter().enumerate() {
            let trust = [Trust::Trusted, Trust::Predicted, Trust::Distrusted][k];
            if !layer.casing.is_empty() {
                let _ = write!(
                    svg,
                    "<path class=\"casing\" stroke=\"{CASING_COLOUR}\" \
                     stroke-width=\"{CASING_WIDTH_PX}\" d=\"{}\"/>",
                    layer.casing
                );
            }
            svg.push_str(&layer.paths);
            for (c, d) in &layer.by_colour {
                if !d.is_empty() {
                    let _ = write!(svg, "<path {} d=\"{d}\"/>", trust.stroke(c));
                }
            }
        }
        svg.push_str("</g>");
        let (width, height, dec) = (self.style.width, self.height, self.style.decimals);
        let palette = self.style.palette;
        // Legend: the colour classes, then the kinds of line and the scale bar.
        let ly = height - LEGEND_H + 8.0;
        let _ = write!(svg, "<g font-family=\"sans-serif\" font-size=\"11\">");
        let box_w = (width - 2.0 * PAD) / (palette.len() + 1) as f64;
        if let Some(sc) = self.scale {
            for (i, c) in palette.iter().enumerate() {
                let x = PAD + i as f64 * box_w;
                let label = match sc.bounds(i, palette.len()) {
                    (None, Some(h)) => format!("< {h:.dec$}"),
                    (Some(l), None) => format!("≥ {l:.dec$}"),
                    (Some(l), Some(h)) => format!("{l:.dec$}–{h:.dec$}"),
                    (None, None) => String::new(),
                };
                let _ = write!(
                    svg,
                    "<rect x=\"{x:.1}\" y=\"{ly:.1}\" width=\"{:.1}\" height=\"10\" fill=\"{c}\"/>\
                     <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                    box_w - 2.0,
                    x + box_w / 2.0,
                    ly + 24.0,
                    escape(&label)
                );
            }
        }
        let x = PAD + palette.len() as f64 * box_w;
        let _ = write!(
            svg,
            "<rect x=\"{x:.1}\" y=\"{ly:.1}\" width=\"20\" height=\"10\" fill=\"{NO_VALUE_COLOUR}\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\">no value</text>",
            x,
            ly + 24.0
        );
        // The kinds of line drawn.
        let y2 = ly + 46.0;
        let mut lx = PAD;
        let sample = "#3b528b";
        for (k, (trust, label)) in [
            (Trust::Trusted, "trusted (status ok)"),
            (Trust::Predicted, "predicted, not measured"),
            (Trust::Distrusted, "flagged or failed: distrust"),
        ]
        .into_iter()
        .enumerate()
        {
            if !self.kinds_drawn[k] && trust != Trust::Distrusted {
                continue;
            }
            let d = format!("M{:.1} {y2:.1}L{:.1} {y2:.1}", lx, lx + 34.0);
            if trust == Trust::Distrusted {
                let _ = write!(
                    svg,
                    "<path fill=\"none\" stroke=\"{CASING_COLOUR}\" \
                     stroke-width=\"{CASING_WIDTH_PX}\" d=\"{d}\"/>"
                );
            }
            let _ = write!(
                svg,
                "<g fill=\"none\" stroke-width=\"{LINE_WIDTH_PX}\"><path {} d=\"{d}\"/></g>\
                 <text x=\"{:.1}\" y=\"{:.1}\">{label}</text>",
                trust.stroke(sample),
                lx + 40.0,
                y2 + 4.0
            );
            lx += 40.0 + 7.0 * label.len() as f64 + 24.0;
        }
        if let Some(m_per_unit) = self.style.metres_per_unit {
            // px per metre: the map's scale s is px per coordinate unit.
            let px_per_m = self.s / m_per_unit;
            let max_px = (width - 2.0 * PAD - lx).min(0.3 * width);
            if max_px > 40.0 && px_per_m.is_finite() && px_per_m > 0.0 {
                let len_m = scale_bar_length(max_px / px_per_m);
                let len_px = len_m * px_per_m;
                let x1 = width - PAD - len_px;
                let label = if len_m >= 1000.0 {
                    format!("{} km", len_m / 1000.0)
                } else {
                    format!("{len_m} m")
                };
                let _ = write!(
                    svg,
                    "<g class=\"scale-bar\"><path fill=\"none\" stroke=\"#222\" stroke-width=\"2\" \
                     d=\"M{x1:.1} {:.1}V{y2:.1}H{:.1}V{:.1}\"/><text x=\"{:.1}\" y=\"{:.1}\" \
                     text-anchor=\"middle\">{label}</text></g>",
                    y2 - 5.0,
                    x1 + len_px,
                    y2 - 5.0,
                    x1 + len_px / 2.0,
                    y2 + 16.0
                );
            }
        }
        svg.push_str("</g></svg>");
        svg
    }
}

/// A horizontal bar of `value` out of `max`, for table cells.
pub fn bar(value: usize, max: usize, colour: &str) -> String {
    const W: f64 = 200.0;
    let w = if max == 0 {
        0.0
    } else {
        W * value as f64 / max as f64
    };
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W:.0}\" height=\"12\" class=\"bar\">\
         <rect width=\"{w:.1}\" height=\"12\" fill=\"{colour}\"/></svg>"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_covers_markup_and_quotes() {
        assert_eq!(
            escape("<a href=\"x\">&'</a>"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;&lt;/a&gt;"
        );
        assert_eq!(escape("a\u{1}b"), "a\u{FFFD}b");
    }

    fn lines(n: usize) -> Vec<LineString> {
        (0..n)
            .map(|i| {
                let (x, y) = ((i % 150) as f64 * 100.0, (i / 150) as f64 * 100.0);
                LineString {
                    points: vec![(x, y), (x + 60.0, y + 30.0), (x + 90.0, y + 80.0)],
                }
            })
            .collect()
    }

    fn style(width: f64) -> MapStyle<'static> {
        MapStyle {
            unit: "m/s",
            decimals: 0,
            scale: None,
            palette: &VIRIDIS_9,
            width,
            metres_per_unit: Some(1.0),
        }
    }

    #[test]
    fn bad_values_are_red_and_distrusted_segments_dashed_over_a_casing() {
        let ls = lines(3);
        let ml: Vec<MapLine<'_>> = ls
            .iter()
            .zip([
                (0.1, Trust::Trusted),
                (3.0, Trust::Distrusted),
                (1.0, Trust::Predicted),
            ])
            .map(|(l, (v, trust))| MapLine {
                id: "x",
                line: l,
                value: Some(v),
                label: Some(format!("{v} %")),
                trust,
            })
            .collect();
        let st = MapStyle {
            unit: "%",
            decimals: 2,
            scale: Some(ColourScale { lo: 0.25, hi: 2.0 }),
            palette: &BAD_IS_RED_8,
            width: 400.0,
            metres_per_unit: None,
        };
        let svg = map(&ml, false, &st);
        // Small error: the calm blue, solid; large error: the dark red, dashed, drawn last over
        // its casing.
        let good = svg
            .find(&format!("<path stroke=\"{}\" d=", BAD_IS_RED_8[0]))
            .unwrap();
        assert!(svg[good..].contains("<title>x: 0.1 %</title>"));
        let bad = svg
            .find(&format!(
                "<path stroke=\"{}\" stroke-width=\"3\" stroke-dasharray",
                BAD_IS_RED_8[7]
            ))
            .unwrap();
        let casing = svg.find("class=\"casing\"").unwrap();
        let dotted = svg.find("stroke-dasharray=\"1 5\"").unwrap();
        assert!(good < casing && dotted < casing && casing < bad, "{svg}");
        assert!(svg.contains(">≥ 2.00<") && svg.contains(">&lt; 0.25<"));
        assert!(
            svg.contains("flagged or failed: distrust") && svg.contains("predicted, not measured")
        );
        assert!(!svg.contains("scale-bar"));
    }

    #[test]
    fn the_scale_bar_is_a_round_length_at_the_map_scale() {
        assert_eq!(scale_bar_length(730.0), 500.0);
        assert_eq!(scale_bar_length(199.0), 100.0);
        assert_eq!(scale_bar_length(2100.0), 2000.0);
        // 50 lines 100 m apart over 150 columns: 15 km wide on a 1000 px map.
        let ls = lines(50);
        let ml: Vec<MapLine<'_>> = ls
            .iter()
            .map(|l| MapLine {
                id: "x",
                line: l,
                value: Some(1.0),
                label: None,
                trust: Trust::Trusted,
            })
            .collect();
        let svg = map(&ml, false, &style(1000.0));
        let bar = &svg[svg.find("class=\"scale-bar\"").unwrap()..];
        let label: String = bar[bar.find("middle\">").unwrap() + 8..]
            .split('<')
            .next()
            .unwrap()
            .into();
        // The bar's path: M x1 y V y H x2: its length in px over px per metre is the label.
        let d = &bar[bar.find("d=\"M").unwrap() + 4..];
        let x1: f64 = d.split(' ').next().unwrap().parse().unwrap();
        let x2: f64 = d[d.find('H').unwrap() + 1..]
            .split('V')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let px_per_m = (1000.0 - 20.0) / (49.0 * 100.0 + 90.0);
        let metres = (x2 - x1) / px_per_m;
        let want: f64 = if let Some(km) = label.strip_suffix(" km") {
            km.parse::<f64>().unwrap() * 1000.0
        } else {
            label.strip_suffix(" m").unwrap().parse().unwrap()
        };
        assert!((metres - want).abs() < 0.01 * want, "{label}: {metres} m");
    }

    fn count(svg: &str, tag: &str) -> usize {
        svg.matches(&format!("<{tag} ")).count() + svg.matches(&format!("<{tag}>")).count()
    }

    #[test]
    fn small_maps_draw_each_segment_with_a_tooltip() {
        let ls = lines(50);
        let ids: Vec<String> = (0..50).map(|i| format!("S<{i}>")).collect();
        let ml: Vec<MapLine<'_>> = ls
            .iter()
            .zip(&ids)
            .enumerate()
            .map(|(i, (l, id))| MapLine {
                id,
                line: l,
                value: (i % 7 != 0).then_some(300.0 + i as f64),
                label: None,
                trust: Trust::Trusted,
            })
            .collect();
        let svg = map(&ml, false, &style(800.0));
        // One path per segment, and the legend's two line samples (the distrusted one over its
        // casing) and the scale bar.
        assert_eq!(count(&svg, "path"), 50 + 3 + 1);
        assert_eq!(count(&svg, "title"), 50);
        assert!(svg.contains("<title>S&lt;7&gt;: no value</title>"));
        assert!(svg.contains(NO_VALUE_COLOUR) && svg.contains(VIRIDIS_9[8]));
    }

    #[test]
    fn large_maps_draw_one_path_per_colour_class() {
        let ls = lines(20_000);
        let ml: Vec<MapLine<'_>> = ls
            .iter()
            .enumerate()
            .map(|(i, l)| MapLine {
                id: "x",
                line: l,
                value: (i % 11 != 0).then_some((i % 1000) as f64),
                label: None,
                trust: if i % 13 == 0 {
                    Trust::Distrusted
                } else {
                    Trust::Trusted
                },
            })
            .collect();
        let svg = map(&ml, false, &style(1000.0));
        // Nine colour classes and grey for each of the two kinds drawn, one casing, the
        // legend's samples and scale bar; no per-segment element.
        assert_eq!(count(&svg, "path"), 20 + 1 + 3 + 1);
        assert_eq!(count(&svg, "title"), 0);
        // Every segment is still drawn: one move-to per segment, and its casing for the
        // distrusted ones (and the legend's samples and scale bar).
        let distrusted = (0..20_000).filter(|i| i % 13 == 0).count();
        assert_eq!(svg.matches('M').count(), 20_000 + distrusted + 3 + 1);
        assert!(svg.len() < 1_200_000, "{} bytes", svg.len());
    }

    #[test]
    fn colour_classes_cover_the_range_in_order() {
        let sc = ColourScale {
            lo: 100.0,
            hi: 800.0,
        };
        assert_eq!(sc.class(50.0, 9), 0);
        assert_eq!(sc.class(100.0, 9), 1);
        assert_eq!(sc.class(799.9, 9), 7);
        assert_eq!(sc.class(800.0, 9), 8);
        assert_eq!(sc.class(f64::INFINITY, 9), 8);
        let mut last = 0;
        for i in 0..=1000 {
            let c = sc.class(i as f64, 9);
            assert!(c >= last && c < 9);
            last = c;
        }
        assert_eq!(sc.bounds(0, 9), (None, Some(100.0)));
        assert_eq!(sc.bounds(1, 9), (Some(100.0), Some(200.0)));
        assert_eq!(sc.bounds(8, 9), (Some(800.0), None));
        assert_eq!(sc.class(799.9, 8), 6);
        assert_eq!(sc.bounds(1, 8), (Some(100.0), Some(100.0 + 700.0 / 6.0)));
    }

    #[test]
    fn trust_follows_the_status() {
        assert_eq!(Trust::of_status("ok"), Trust::Trusted);
        assert_eq!(Trust::of_status("flagged"), Trust::Distrusted);
        assert_eq!(Trust::of_status("failed"), Trust::Distrusted);
        assert_eq!(Trust::of_status("predicted"), Trust::Predicted);
        assert_eq!(Trust::of_status("unfitted"), Trust::Trusted);
    }
}
