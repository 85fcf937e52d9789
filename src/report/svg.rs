//! Hand-written SVG: escaping, the colour scale, the network map and inline bars.

use std::fmt::Write as _;

use crate::db::wkt::LineString;

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
/// readable by colour-blind readers, low speeds dark blue, high speeds yellow.
pub const VIRIDIS_9: [&str; 9] = [
    "#440154", "#472d7b", "#3b528b", "#2c728e", "#21918c", "#28ae80", "#5ec962", "#addc30",
    "#fde725",
];

/// Colour of segments without a value.
pub const NO_VALUE_COLOUR: &str = "#b0b0b0";

/// A classed colour scale: [`VIRIDIS_9`] over equal-width classes between `lo` and `hi` (the
/// first and last classes are open-ended).
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
        let lo = super::quantile(sorted, 0.02)?;
        let hi = super::quantile(sorted, 0.98)?;
        let (lo, hi) = if hi - lo > 1e-9 * hi.abs().max(1.0) {
            (lo, hi)
        } else {
            (lo - 1.0, hi + 1.0)
        };
        Some(ColourScale { lo, hi })
    }

    /// The class of a value, 0..9.
    pub fn class(&self, v: f64) -> usize {
        let n = VIRIDIS_9.len();
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

    /// The bounds of a class, for the legend (None: open end).
    pub fn bounds(&self, class: usize) -> (Option<f64>, Option<f64>) {
        let n = VIRIDIS_9.len();
        let inner = (n - 2) as f64;
        let edge = |k: usize| self.lo + (self.hi - self.lo) * (k as f64) / inner;
        match class {
            0 => (None, Some(self.lo)),
            c if c >= n - 1 => (Some(self.hi), None),
            c => (Some(edge(c - 1)), Some(edge(c))),
        }
    }
}

/// Above this many segments the map draws one path per colour class (no per-segment tooltip),
/// which keeps a 20,000-segment map to a few hundred kB and fast to render.
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
    /// Reverse the palette: high values dark (used where high values are the ones to see).
    pub reversed: bool,
    /// Width of the SVG, px.
    pub width: f64,
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
    let values = super::sorted_finite(lines.iter().filter_map(|l| l.value));
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
pub struct MapCanvas<'s> {
    style: MapStyle<'s>,
    scale: Option<ColourScale>,
    /// Tooltips: one path per segment; otherwise one path per colour class.
    tooltips: bool,
    bbox: [f64; 4],
    kx: f64,
    s: f64,
    ox: f64,
    height: f64,
    svg: String,
    by_colour: Vec<(&'static str, String)>,
}

const LEGEND_H: f64 = 40.0;
const PAD: f64 = 10.0;

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
            "<g fill=\"none\" stroke-width=\"1.5\" stroke-linecap=\"round\" stroke-linejoin=\"round\">"
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
            by_colour: Vec::new(),
        };
        if !canvas.tooltips {
            // Grey first, so coloured segments are drawn over it.
            canvas.by_colour = std::iter::once(NO_VALUE_COLOUR)
                .chain((0..VIRIDIS_9.len()).map(|c| canvas.palette(c)))
                .map(|c| (c, String::new()))
                .collect();
        }
        canvas
    }

    fn palette(&self, class: usize) -> &'static str {
        if self.style.reversed {
            VIRIDIS_9[VIRIDIS_9.len() - 1 - class]
        } else {
            VIRIDIS_9[class]
        }
    }

    fn colour(&self, v: Option<f64>) -> &'static str {
        match (v, self.scale) {
            (Some(v), Some(sc)) => self.palette(sc.class(v)),
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
        if self.tooltips {
            let mut d = String::new();
            self.path_d(l.line, &mut d);
            let dec = self.style.decimals;
            let v = match (&l.label, l.value) {
                (Some(t), _) => t.clone(),
                (None, Some(v)) => format!("{v:.dec$} {}", self.style.unit),
                (None, None) => "no value".to_string(),
            };
            let _ = write!(
                self.svg,
                "<path stroke=\"{c}\" d=\"{d}\"><title>{}: {}</title></path>",
                escape(l.id),
                escape(&v)
            );
        } else if let Some(k) = self.by_colour.iter().position(|(k, _)| *k == c) {
            let mut d = std::mem::take(&mut self.by_colour[k].1);
            self.path_d(l.line, &mut d);
            self.by_colour[k].1 = d;
        }
    }

    /// The SVG, with its legend.
    pub fn finish(mut self) -> String {
        for (c, d) in std::mem::take(&mut self.by_colour) {
            if !d.is_empty() {
                let _ = write!(self.svg, "<path stroke=\"{c}\" d=\"{d}\"/>");
            }
        }
        let mut svg = std::mem::take(&mut self.svg);
        svg.push_str("</g>");
        let (width, height, dec) = (self.style.width, self.height, self.style.decimals);
        // Legend.
        let ly = height - LEGEND_H + 8.0;
        let _ = write!(svg, "<g font-family=\"sans-serif\" font-size=\"11\">");
        if let Some(sc) = self.scale {
            let box_w = (width - 2.0 * PAD) / (VIRIDIS_9.len() + 1) as f64;
            for i in 0..VIRIDIS_9.len() {
                let c = self.palette(i);
                let x = PAD + i as f64 * box_w;
                let label = match sc.bounds(i) {
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
        let x = PAD + VIRIDIS_9.len() as f64 * ((width - 2.0 * PAD) / (VIRIDIS_9.len() + 1) as f64);
        let _ = write!(
            svg,
            "<rect x=\"{x:.1}\" y=\"{ly:.1}\" width=\"20\" height=\"10\" fill=\"{NO_VALUE_COLOUR}\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\">no value</text></g></svg>",
            x,
            ly + 24.0
        );
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
            reversed: false,
            width,
        }
    }

    #[test]
    fn fixed_reversed_scales_put_high_values_dark() {
        let ls = lines(2);
        let ml: Vec<MapLine<'_>> = ls
            .iter()
            .zip([0.1, 3.0])
            .map(|(l, v)| MapLine {
                id: "x",
                line: l,
                value: Some(v),
                label: Some(format!("{v} %")),
            })
            .collect();
        let st = MapStyle {
            unit: "%",
            decimals: 2,
            scale: Some(ColourScale { lo: 0.25, hi: 2.0 }),
            reversed: true,
            width: 400.0,
        };
        let svg = map(&ml, false, &st);
        assert!(svg.contains(&format!("<path stroke=\"{}\"", VIRIDIS_9[8])));
        assert!(svg.contains(&format!("<path stroke=\"{}\"", VIRIDIS_9[0])));
        let yellow = svg.find(&format!("stroke=\"{}\"", VIRIDIS_9[8])).unwrap();
        assert!(svg[yellow..].starts_with(&format!("stroke=\"{}\" d=", VIRIDIS_9[8])));
        assert!(svg[yellow..].contains("<title>x: 0.1 %</title>"));
        assert!(svg.contains(">≥ 2.00<") && svg.contains(">&lt; 0.25<"));
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
            })
            .collect();
        let svg = map(&ml, false, &style(800.0));
        assert_eq!(count(&svg, "path"), 50);
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
            })
            .collect();
        let svg = map(&ml, false, &style(1000.0));
        // Nine colour classes and grey, no per-segment element.
        assert_eq!(count(&svg, "path"), 10);
        assert_eq!(count(&svg, "title"), 0);
        // Every segment is still drawn: one move-to per segment.
        assert_eq!(svg.matches('M').count(), 20_000);
        assert!(svg.len() < 1_200_000, "{} bytes", svg.len());
    }

    #[test]
    fn colour_classes_cover_the_range_in_order() {
        let sc = ColourScale {
            lo: 100.0,
            hi: 800.0,
        };
        assert_eq!(sc.class(50.0), 0);
        assert_eq!(sc.class(100.0), 1);
        assert_eq!(sc.class(799.9), 7);
        assert_eq!(sc.class(800.0), 8);
        assert_eq!(sc.class(f64::INFINITY), 8);
        let mut last = 0;
        for i in 0..=1000 {
            let c = sc.class(i as f64);
            assert!(c >= last && c < 9);
            last = c;
        }
        assert_eq!(sc.bounds(0), (None, Some(100.0)));
        assert_eq!(sc.bounds(1), (Some(100.0), Some(200.0)));
        assert_eq!(sc.bounds(8), (Some(800.0), None));
    }
}
