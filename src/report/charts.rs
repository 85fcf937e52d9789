//! The XY charts of the reports, drawn with `plotters`' SVG backend into strings. Text uses
//! plotters' built-in size estimate (no system fonts), and the browser's sans-serif font.
//!
//! Every chart aggregates when the data are many: histograms, 2-D histograms above
//! [`SCATTER_LIMIT`] points, box plots per category.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::stats::quantile;
use crate::units::sig;

/// A chart that could not be drawn (plotters' message).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cannot draw the chart '{chart}': {message}")]
pub struct ChartError {
    /// Which chart.
    pub chart: &'static str,
    /// What plotters said.
    pub message: String,
}

/// A drawn chart, and how many of its values or error bars lie beyond its axes (drawn at the
/// edge with a mark, and said in the caption, never dropped silently).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Chart {
    /// The SVG.
    pub svg: String,
    /// Values (or error-bar ends) beyond the axes.
    pub off_axis: usize,
}

/// Above this many points a scatter plot becomes a 2-D histogram: 20,000 overlapping dots say
/// less than a density, and cost ~1.5 MB of SVG.
pub const SCATTER_LIMIT: usize = 3000;

/// Categorical colours (Paul Tol's "bright" scheme, colour-blind safe), then grey.
pub const CATEGORY_COLOURS: [RGBColor; 7] = [
    RGBColor(0x44, 0x77, 0xAA),
    RGBColor(0xEE, 0x66, 0x77),
    RGBColor(0x22, 0x88, 0x33),
    RGBColor(0xCC, 0xBB, 0x44),
    RGBColor(0x66, 0xCC, 0xEE),
    RGBColor(0xAA, 0x33, 0x77),
    RGBColor(0xBB, 0xBB, 0xBB),
];

const FONT: &str = "sans-serif";

fn render(
    chart: &'static str,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<String, ChartError> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
        let res = root
            .fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|()| draw(&root))
            .and_then(|()| root.present().map_err(|e| e.to_string()));
        res.map_err(|message| ChartError { chart, message })?;
    }
    Ok(buf)
}

fn e2s<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A range around the values with a margin of `frac` of the span (or ±1 when flat).
fn padded(lo: f64, hi: f64, frac: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * hi.abs().max(1.0) {
        let d = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        (lo - d, hi + d)
    } else {
        (lo - frac * span, hi + frac * span)
    }
}

/// The lowest value a log-axis histogram shows, as a fraction of the median: values far below
/// it (a fit that is exact to rounding, misfit 1e-15) would otherwise stretch the axis over
/// decades where nothing is. They are counted in the first bar, which the caption says.
pub const LOG_HISTOGRAM_FLOOR_OF_MEDIAN: f64 = 1e-3;

/// Histogram of log10 of positive values, with vertical markers (label, value). The axis
/// starts at the smallest value, or at [`LOG_HISTOGRAM_FLOOR_OF_MEDIAN`] × the median when
/// values lie below that; [`Chart::off_axis`] counts those, drawn in the first bar.
pub fn log_histogram(
    chart: &'static str,
    values: &[f64],
    x_desc: &str,
    markers: &[(&str, f64)],
) -> Result<Chart, ChartError> {
    const BINS: usize = 40;
    let logs: Vec<f64> = crate::stats::sorted_finite(
        values
            .iter()
            .filter(|v| v.is_finite() && **v > 0.0)
            .map(|v| v.log10()),
    );
    let floor = quantile(&logs, 0.5).map(|m| m + LOG_HISTOGRAM_FLOOR_OF_MEDIAN.log10());
    let lo = logs.first().copied().unwrap_or(f64::INFINITY);
    let lo = floor.map_or(lo, |f| lo.max(f));
    let hi = logs.last().copied().unwrap_or(f64::NEG_INFINITY);
    let (x0, x1) = padded(lo, hi, 0.02);
    let w = (x1 - x0) / BINS as f64;
    let mut counts = [0usize; BINS];
    let mut below = 0;
    for v in &logs {
        if *v < x0 {
            below += 1;
        }
        let i = ((((v - x0) / w).max(0.0)) as usize).min(BINS - 1);
        counts[i] += 1;
    }
    let ymax = counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.1;
    let svg = render(chart, (720, 300), |root| {
        let mut c = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, 0f64..ymax)
            .map_err(e2s)?;
        c.configure_mesh()
            .max_light_lines(0)
            .disable_x_mesh()
            .x_desc(x_desc)
            .y_desc("segments")
            .x_label_formatter(&|v| sig(10f64.powf(*v), 2))
            .y_labels(count_ticks(ymax))
            .y_label_formatter(&|v| count_label(*v))
            .label_style((FONT, 12))
            .draw()
            .map_err(e2s)?;
        c.draw_series(
            counts
                .iter()
                .enumerate()
                .filter(|(_, n)| **n > 0)
                .map(|(i, &n)| {
                    let a = x0 + i as f64 * w;
                    Rectangle::new([(a, 0.0), (a + w, n as f64)], CATEGORY_COLOURS[0].filled())
                }),
        )
        .map_err(e2s)?;
        for (k, (label, v)) in markers.iter().enumerate() {
            if !(v.is_finite() && *v > 0.0) || v.log10() < x0 || v.log10() > x1 {
                continue;
            }
            let colour = CATEGORY_COLOURS[(k + 1) % CATEGORY_COLOURS.len()];
            let x = v.log10();
            c.draw_series(std::iter::once(PathElement::new(
                vec![(x, 0.0), (x, ymax)],
                colour.stroke_width(2),
            )))
            .map_err(e2s)?
            .label(format!("{label} {}", sig(*v, 3)))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
            });
        }
        if !markers.is_empty() {
            c.configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK.mix(0.4))
                .label_font((FONT, 12))
                .draw()
                .map_err(e2s)?;
        }
        Ok(())
    })?;
    Ok(Chart {
        svg,
        off_axis: below,
    })
}

/// How many y ticks a count axis up to `ymax` asks for: one per whole count when they are few
/// (so that a small network's axis reads 0, 1, 2), at most 10.
fn count_ticks(ymax: f64) -> usize {
    (ymax.floor() as usize + 1).clamp(2, 10)
}

/// A count axis' tick label: the count where the tick is a whole number, nothing between (a
/// count of 0.4 segments printed as "0" would repeat the label).
pub fn count_label(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{:.0}", v.round())
    } else {
        String::new()
    }
}

/// One point of the speed–diameter chart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedPoint<'a> {
    /// Material code.
    pub material: &'a str,
    /// Outside diameter, mm.
    pub diameter_mm: f64,
    /// Wave speed, m/s.
    pub speed: f64,
}

/// Wave speed against diameter, by material: one dot per segment (or a 2-D histogram above
/// [`SCATTER_LIMIT`]) and, for each material, the median speed at each diameter.
pub fn speed_vs_diameter(
    points: &[SpeedPoint<'_>],
    materials: &[&str],
) -> Result<String, ChartError> {
    let fold = |f: fn(&SpeedPoint<'_>) -> f64| {
        points
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
    };
    let (x0, x1) = fold(|p| p.diameter_mm);
    let (y0, y1) = fold(|p| p.speed);
    let (x0, x1) = padded(x0, x1, 0.04);
    let (y0, y1) = padded(y0, y1, 0.06);
    let colour_of = |m: &str| {
        let i = materials
            .iter()
            .position(|x| *x == m)
            .unwrap_or(CATEGORY_COLOURS.len() - 1);
        CATEGORY_COLOURS[i.min(CATEGORY_COLOURS.len() - 1)]
    };
    render("speed against diameter", (720, 420), |root| {
        let mut c = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e2s)?;
        c.configure_mesh()
            .max_light_lines(0)
            .x_desc("outside diameter (mm)")
            .y_desc("leak-band wave speed (m/s)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((FONT, 12))
            .draw()
            .map_err(e2s)?;
        if points.len() <= SCATTER_LIMIT {
            c.draw_series(points.iter().map(|p| {
                Circle::new(
                    (p.diameter_mm, p.speed),
                    2,
                    colour_of(p.material).mix(0.5).filled(),
                )
            }))
            .map_err(e2s)?;
        } else {
            const NX: usize = 60;
            const NY: usize = 40;
            let mut grid = vec![0usize; NX * NY];
            let (wx, wy) = ((x1 - x0) / NX as f64, (y1 - y0) / NY as f64);
            for p in points {
                let i = (((p.diameter_mm - x0) / wx) as usize).min(NX - 1);
                let j = (((p.speed - y0) / wy) as usize).min(NY - 1);
                grid[j * NX + i] += 1;
            }
            let max = grid.iter().copied().max().unwrap_or(1).max(1) as f64;
            c.draw_series(
                grid.iter()
                    .enumerate()
                    .filter(|(_, n)| **n > 0)
                    .map(|(k, &n)| {
                        let (i, j) = (k % NX, k / NX);
                        // Grey level by log count, so single segments stay visible beside dense cells.
                        let t = 0.15 + 0.85 * ((n as f64).ln_1p() / max.ln_1p());
                        let g = (235.0 - 200.0 * t) as u8;
                        let a = (x0 + i as f64 * wx, y0 + j as f64 * wy);
                        Rectangle::new([a, (a.0 + wx, a.1 + wy)], RGBColor(g, g, g).filled())
                    }),
            )
            .map_err(e2s)?;
        }
        for m in materials {
            let mut by_d: std::collections::BTreeMap<i64, Vec<f64>> = Default::default();
            for p in points.iter().filter(|p| p.material == *m) {
                by_d.entry(p.diameter_mm.round() as i64)
                    .or_default()
                    .push(p.speed);
            }
            let line: Vec<(f64, f64)> = by_d
                .into_iter()
                .filter_map(|(d, mut v)| {
                    v.sort_by(f64::total_cmp);
                    quantile(&v, 0.5).map(|q| (d as f64, q))
                })
                .collect();
            let colour = colour_of(m);
            c.draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
                .map_err(e2s)?
                .label(format!("{m} (median per diameter)"))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
                });
            c.draw_series(line.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
                .map_err(e2s)?;
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK.mix(0.4))
            .label_font((FONT, 12))
            .draw()
            .map_err(e2s)?;
        Ok(())
    })
}

/// Horizontal box plots of log10 values per category (whiskers at 1.5 IQR, plotters'
/// [`Quartiles`]), labelled `name (n)`; `fmt` turns a log10 value into a tick label.
pub fn log_boxplots(
    chart: &'static str,
    groups: &[(String, Vec<f64>)],
    x_desc: &str,
    fmt: fn(f64) -> String,
) -> Result<String, ChartError> {
    let logs: Vec<(String, Vec<f32>)> = groups
        .iter()
        .map(|(name, v)| {
            let l: Vec<f32> = v
                .iter()
                .filter(|x| x.is_finite() && **x > 0.0)
                .map(|x| x.log10() as f32)
                .collect();
            (format!("{name} ({})", l.len()), l)
        })
        .filter(|(_, l)| !l.is_empty())
        .collect();
    let all = logs.iter().flat_map(|(_, l)| l.iter().copied());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(f64::from(v)), b.max(f64::from(v)))
    });
    let (x0, x1) = padded(lo, hi, 0.05);
    let n = logs.len().max(1);
    let height = (60 + 28 * n).clamp(160, 900) as u32;
    let names: Vec<String> = logs.iter().map(|(n, _)| n.clone()).collect();
    render(chart, (720, height), |root| {
        let mut c = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(170)
            .build_cartesian_2d(x0 as f32..x1 as f32, -1i32..n as i32)
            .map_err(e2s)?;
        c.configure_mesh()
            .max_light_lines(0)
            .disable_y_mesh()
            .x_desc(x_desc)
            .y_labels(n + 2)
            .y_label_formatter(&|i| {
                usize::try_from(*i)
                    .ok()
                    .and_then(|i| names.get(i))
                    .cloned()
                    .unwrap_or_default()
            })
            .x_label_formatter(&|v| fmt(f64::from(*v)))
            .label_style((FONT, 12))
            .draw()
            .map_err(e2s)?;
        c.draw_series(logs.iter().enumerate().map(|(i, (_, l))| {
            Boxplot::new_horizontal(i as i32, &Quartiles::new(l))
                .width(16)
                .style(CATEGORY_COLOURS[0])
        }))
        .map_err(e2s)?;
        Ok(())
    })
}

/// A speed with its one-sigma error, m/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WithStd {
    /// The value.
    pub value: f64,
    /// Its one-sigma error.
    pub std: f64,
}

/// One soil type of the soil-speed chart.
#[derive(Debug, Clone, PartialEq)]
pub struct SoilSpeeds {
    /// Soil type, as in the inventory (plotters escapes it in the SVG).
    pub name: String,
    /// Each segment's c_P ± σ.
    pub c_p: Vec<WithStd>,
    /// Each segment's c_S ± σ (only where determined).
    pub c_s: Vec<WithStd>,
    /// The inverse-variance weighted mean of `c_p` with its error.
    pub c_p_mean: Option<WithStd>,
    /// The same for `c_s`.
    pub c_s_mean: Option<WithStd>,
}

/// Which speeds of a soil type a series draws.
type Pick = fn(&SoilSpeeds) -> &[WithStd];

/// The soils' compressional (blue) and shear (red) speeds, one band per soil type: each
/// segment's value ± σ as a dot with an error bar (up to [`SCATTER_LIMIT`] segments in all),
/// and each type's weighted mean ± its error as a black bar. The axis spans the values' 1st to
/// 99th percentiles: a value beyond is drawn as a triangle at the edge, an error bar beyond
/// ends in one, and [`Chart::off_axis`] counts both.
pub fn soil_speeds(groups: &[SoilSpeeds]) -> Result<Chart, ChartError> {
    let all: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.c_p.iter().chain(&g.c_s))
        .map(|p| p.value)
        .filter(|v| v.is_finite())
        .collect();
    let sorted = crate::stats::sorted_finite(all.iter().copied());
    // The axis spans the values (1st–99th percentiles), not the error bars; what lies beyond
    // is drawn at the edge with a triangle and counted.
    let lo = quantile(&sorted, 0.01).unwrap_or(0.0);
    let hi = quantile(&sorted, 0.99).unwrap_or(1.0);
    let (x0, x1) = padded(lo.min(hi), hi, 0.08);
    let x0 = x0.max(0.0);
    let clip = |v: f64| v.clamp(x0, x1);
    let beyond = |v: f64| v < x0 || v > x1;
    let n = groups.len().max(1);
    let dots = all.len() <= SCATTER_LIMIT;
    let off_axis = std::cell::Cell::new(0usize);
    let height = (70 + 60 * n).clamp(180, 1400) as u32;
    let svg = render("soil speeds by soil type", (720, height), |root| {
        let mut c = ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(10)
            .build_cartesian_2d(x0..x1, -0.5f64..(n as f64 - 0.5))
            .map_err(e2s)?;
        c.configure_mesh()
            .max_light_lines(0)
            .disable_y_mesh()
            .y_labels(0)
            .x_desc("soil wave speed (m/s)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .label_style((FONT, 12))
            .draw()
            .map_err(e2s)?;
        // Band separators and names; band i holds group i, top to bottom.
        let y_of = |i: usize| (n - 1 - i) as f64;
        for i in 0..n {
            let y = y_of(i) + 0.5;
            c.draw_series(std::iter::once(PathElement::new(
                vec![(x0, y), (x1, y)],
                BLACK.mix(0.15),
            )))
            .map_err(e2s)?;
        }
        for (i, g) in groups.iter().enumerate() {
            let label = format!("{} (c_P: {}, c_S: {})", g.name, g.c_p.len(), g.c_s.len());
            c.draw_series(std::iter::once(Text::new(
                label,
                (x0 + 0.01 * (x1 - x0), y_of(i) + 0.42),
                (FONT, 12),
            )))
            .map_err(e2s)?;
        }
        let series: [(&str, usize, Pick, f64); 2] =
            [("c_P", 0, |g| &g.c_p, 0.02), ("c_S", 1, |g| &g.c_s, -0.3)];
        for (name, colour_i, get, base) in series {
            let colour = CATEGORY_COLOURS[colour_i];
            let mut bars = Vec::new();
            let mut edges: Vec<(f64, f64)> = Vec::new();
            if dots {
                for (i, g) in groups.iter().enumerate() {
                    let pts = get(g);
                    let k = pts.len().max(1) as f64;
                    for (j, p) in pts.iter().enumerate() {
                        // Spread the dots below the mean so their bars do not overlap.
                        let y = y_of(i) + base - 0.18 * (j as f64 + 0.5) / k;
                        off_axis.set(
                            off_axis.get()
                                + usize::from(
                                    beyond(p.value)
                                        || beyond(p.value - p.std)
                                        || beyond(p.value + p.std),
                                ),
                        );
                        for end in [p.value - p.std, p.value, p.value + p.std] {
                            if beyond(end) {
                                edges.push((clip(end), y));
                            }
                        }
                        bars.push((
                            clip(p.value),
                            clip(p.value - p.std),
                            clip(p.value + p.std),
                            y,
                        ));
                    }
                }
            }
            c.draw_series(bars.iter().map(|&(_, a, b, y)| {
                PathElement::new(vec![(a, y), (b, y)], colour.mix(0.6).stroke_width(1))
            }))
            .map_err(e2s)?;
            c.draw_series(
                bars.iter()
                    .map(|&(v, _, _, y)| Circle::new((v, y), 2, colour.mix(0.8).filled())),
            )
            .map_err(e2s)?
            .label(format!("{name} of a segment ± σ"))
            .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
            c.draw_series(
                edges
                    .iter()
                    .map(|&p| TriangleMarker::new(p, 5, BLACK.filled())),
            )
            .map_err(e2s)?;
            let means: Vec<(f64, WithStd)> = groups
                .iter()
                .enumerate()
                .filter_map(|(i, g)| {
                    let m = if colour_i == 0 {
                        g.c_p_mean
                    } else {
                        g.c_s_mean
                    };
                    Some((y_of(i) + base + 0.08, m?))
                })
                .collect();
            c.draw_series(means.iter().map(|&(y, m)| {
                Rectangle::new(
                    [
                        (clip(m.value - m.std), y - 0.04),
                        (clip(m.value + m.std), y + 0.04),
                    ],
                    BLACK.filled(),
                )
            }))
            .map_err(e2s)?;
            c.draw_series(
                means
                    .iter()
                    .map(|&(y, m)| Circle::new((clip(m.value), y), 4, colour.filled())),
            )
            .map_err(e2s)?;
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK.mix(0.4))
            .label_font((FONT, 12))
            .draw()
            .map_err(e2s)?;
        Ok(())
    })?;
    Ok(Chart {
        svg,
        off_axis: off_axis.get(),
    })
}

/// One measured point: frequency, value and its one-sigma error when stated.
pub type Measured = (f64, f64, Option<f64>);

/// A fitted curve (line) with the measured points (dots) over it, each with its ± σ error bar.
/// The axis spans the curve and the points, and the error bars up to one such span beyond
/// them; a bar longer than that ends at the axis in a triangle, counted in
/// [`Chart::off_axis`].
pub fn curve_with_points(
    chart: &'static str,
    title: &str,
    fitted: &[(f64, f64)],
    measured: &[Measured],
    y_desc: &str,
) -> Result<Chart, ChartError> {
    let xs = fitted
        .iter()
        .map(|p| p.0)
        .chain(measured.iter().map(|p| p.0));
    let ys = fitted
        .iter()
        .map(|p| p.1)
        .chain(measured.iter().map(|p| p.1));
    let x1 = xs.fold(f64::NEG_INFINITY, f64::max);
    let (ylo, yhi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let x1 = if x1.is_finite() && x1 > 0.0 {
        x1 * 1.03
    } else {
        1.0
    };
    let span = (yhi - ylo).max(0.05 * yhi.abs());
    let (blo, bhi) = measured
        .iter()
        .filter_map(|&(_, y, s)| s.filter(|s| s.is_finite()).map(|s| (y - s, y + s)))
        .fold((ylo, yhi), |(a, b), (l, h)| {
            (a.min(l.max(ylo - span)), b.max(h.min(yhi + span)))
        });
    let (y0, y1) = padded(blo, bhi, 0.08);
    let mut off_axis = 0;
    let mut bars = Vec::new();
    let mut edges = Vec::new();
    for &(x, y, s) in measured {
        let Some(s) = s.filter(|s| s.is_finite() && *s > 0.0) else {
            continue;
        };
        let (l, h) = (y - s, y + s);
        if l < y0 || h > y1 {
            off_axis += 1;
        }
        if l < y0 {
            edges.push((x, y0));
        }
        if h > y1 {
            edges.push((x, y1));
        }
        bars.push((x, l.max(y0), h.min(y1)));
    }
    let svg = render(chart, (360, 240), |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .caption(title, (FONT, 13))
            .x_label_area_size(32)
            .y_label_area_size(52)
            .build_cartesian_2d(0f64..x1, y0..y1)
            .map_err(e2s)?;
        c.configure_mesh()
            .max_light_lines(0)
            .x_desc("frequency (Hz)")
            .y_desc(y_desc)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| sig(*v, 3))
            .x_labels(5)
            .y_labels(5)
            .label_style((FONT, 11))
            .draw()
            .map_err(e2s)?;
        c.draw_series(LineSeries::new(
            fitted.iter().copied(),
            CATEGORY_COLOURS[0].stroke_width(2),
        ))
        .map_err(e2s)?;
        c.draw_series(bars.iter().map(|&(x, l, h)| {
            PathElement::new(vec![(x, l), (x, h)], CATEGORY_COLOURS[1].stroke_width(1))
        }))
        .map_err(e2s)?;
        c.draw_series(
            measured
                .iter()
                .map(|&(x, y, _)| Circle::new((x, y), 3, CATEGORY_COLOURS[1].filled())),
        )
        .map_err(e2s)?;
        c.draw_series(
            edges
                .iter()
                .map(|&p| TriangleMarker::new(p, 4, BLACK.filled())),
        )
        .map_err(e2s)?;
        Ok(())
    })?;
    Ok(Chart { svg, off_axis })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small network's histogram labels each whole count once: 0, 1 (never 0, 0, 1, 1).
    #[test]
    fn a_count_axis_labels_whole_counts_once() {
        let chart = log_histogram(
            "misfit distribution",
            &[0.3, 0.8, 1.1, 0.5],
            "chi2/dof",
            &[],
        )
        .unwrap();
        let labels: Vec<String> = chart
            .svg
            .split("<text")
            .skip(1)
            .filter_map(|t| {
                let t = &t[t.find('>')? + 1..];
                Some(t[..t.find('<')?].trim().to_string())
            })
            .filter(|t| !t.is_empty() && t.chars().all(|c| c.is_ascii_digit()))
            .collect();
        let mut unique = labels.clone();
        unique.dedup();
        assert_eq!(labels, unique, "repeated count labels");
        assert!(labels.contains(&"0".to_string()) && labels.contains(&"1".to_string()));
        assert_eq!(count_label(0.4), "");
        assert_eq!(count_label(2.0), "2");
    }

    fn points(n: usize) -> Vec<SpeedPoint<'static>> {
        (0..n)
            .map(|i| SpeedPoint {
                material: ["CI", "PVC", "DI"][i % 3],
                diameter_mm: [100.0, 150.0, 200.0][(i / 3) % 3],
                speed: 400.0 + (i % 800) as f64,
            })
            .collect()
    }

    #[test]
    fn scatter_above_the_limit_becomes_a_density() {
        let m = ["CI", "PVC", "DI"];
        let small = speed_vs_diameter(&points(300), &m).unwrap();
        // One dot per segment plus one marker per material and diameter (3 x 3).
        assert_eq!(small.matches("<circle").count(), 300 + 9);
        let large = speed_vs_diameter(&points(20_000), &m).unwrap();
        assert_eq!(large.matches("<circle").count(), 9);
        assert!(large.matches("<rect").count() <= 60 * 40 + 10);
        assert!(large.len() < 300_000, "{} bytes", large.len());
    }

    #[test]
    fn soil_speeds_draw_every_segment_and_name_every_type() {
        let w = |value, std| WithStd { value, std };
        let groups = vec![
            SoilSpeeds {
                name: "clay & <silt>".into(),
                c_p: vec![w(250.0, 10.0), w(270.0, 12.0)],
                c_s: vec![w(120.0, 5.0)],
                c_p_mean: Some(w(259.0, 7.7)),
                c_s_mean: Some(w(120.0, 5.0)),
            },
            SoilSpeeds {
                name: "sand".into(),
                c_p: vec![w(400.0, 20.0)],
                c_s: Vec::new(),
                c_p_mean: Some(w(400.0, 20.0)),
                c_s_mean: None,
            },
        ];
        let svg = soil_speeds(&groups).unwrap().svg;
        assert!(
            svg.contains("clay &amp; &lt;silt&gt; (c_P: 2, c_S: 1)"),
            "{svg}"
        );
        assert!(svg.contains("sand (c_P: 1, c_S: 0)"));
        // One dot per segment plus one per mean, plus the legend's two.
        assert_eq!(svg.matches("<circle").count(), 4 + 3 + 2);
    }

    #[test]
    fn measurements_carry_error_bars_and_long_ones_are_counted_off_axis() {
        let fitted: Vec<(f64, f64)> = (1..=8).map(|i| (100.0 * i as f64, 400.0)).collect();
        let measured = [
            (200.0, 410.0, Some(5.0)),
            (400.0, 395.0, Some(4.0)),
            (600.0, 400.0, Some(900.0)),
        ];
        let c = curve_with_points("c", "t", &fitted, &measured, "m/s").unwrap();
        // Three dots and three vertical bars; the long bar ends at both axis edges.
        assert_eq!(c.svg.matches("<circle").count(), 3);
        assert_eq!(c.off_axis, 1);
        assert_eq!(c.svg.matches("<polygon").count(), 2, "{}", c.svg);
    }

    #[test]
    fn a_log_histogram_does_not_stretch_to_exact_fits() {
        let mut v: Vec<f64> = (0..100).map(|i| 0.5 + 0.05 * f64::from(i)).collect();
        v.extend([1e-15, 3e-12]);
        let h = log_histogram("h", &v, "chi2/dof", &[("median", 2.9)]).unwrap();
        assert_eq!(h.off_axis, 2);
        // Tick labels stay within a few decades of the median, not 1e-15.
        assert!(
            !h.svg.contains("e-15") && !h.svg.contains("e-12"),
            "{}",
            h.svg
        );
    }

    #[test]
    fn charts_survive_degenerate_data() {
        assert!(log_histogram("h", &[], "x", &[]).is_ok());
        assert!(log_histogram("h", &[1.0, 1.0], "x", &[("median", 1.0)]).is_ok());
        assert!(log_histogram("h", &[f64::NAN, -1.0, 0.0], "x", &[("m", f64::NAN)]).is_ok());
        assert!(speed_vs_diameter(&points(1), &["CI"]).is_ok());
        assert!(log_boxplots("b", &[("a".into(), vec![5e7])], "E", |v| v.to_string()).is_ok());
        assert!(log_boxplots("b", &[], "E", |v| v.to_string()).is_ok());
        assert!(curve_with_points("c", "t", &[], &[], "m/s").is_ok());
        assert!(curve_with_points(
            "c",
            "t",
            &[(1.0, 1.0)],
            &[(1.0, 1.0, Some(f64::NAN))],
            "m/s"
        )
        .is_ok());
        assert!(soil_speeds(&[]).is_ok());
        let one = WithStd {
            value: 300.0,
            std: 1e9,
        };
        let g = SoilSpeeds {
            name: "clay".into(),
            c_p: vec![one],
            c_s: Vec::new(),
            c_p_mean: Some(one),
            c_s_mean: None,
        };
        assert!(soil_speeds(std::slice::from_ref(&g)).is_ok());
        assert!(curve_with_points("c", "t", &[(100.0, 1.0)], &[(100.0, 1.0, None)], "m/s").is_ok());
        assert_eq!(soil_speeds(&[g]).unwrap().off_axis, 1);
    }
}
