//! A small figure description (panels of line/point series) and its rendering with `plotters` to
//! SVG (text) and PNG (file). Every figure of the report goes through here, so the SVG and the PNG
//! of a figure always show the same thing.

use crate::ReportError;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// DejaVu Sans (Bitstream Vera licence, see `assets/DejaVuSans-LICENSE.txt`): the PNG backend
/// needs a font file and the machine may have none.
static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

/// Registers the embedded font under the names plotters asks for.
fn register_fonts() {
    REGISTER.call_once(|| {
        for name in ["sans-serif", "serif", "monospace"] {
            for style in [FontStyle::Normal, FontStyle::Bold, FontStyle::Italic] {
                // The bytes are a valid font (checked by a test); a failure would only mean
                // missing text in PNGs, never a crash.
                let _ = plotters::style::register_font(name, style, FONT);
            }
        }
    });
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    /// Solid line of the given width (px).
    Line(u32),
    /// Dashed line.
    Dashed(u32),
    /// Filled dots of the given radius (px).
    Points(u32),
}

/// One data series of a panel.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text (empty: not in the legend, e.g. the mirrored half of an envelope).
    pub name: String,
    /// Colour index into the palette.
    pub color: usize,
    /// How it is drawn (line or points).
    pub style: Style,
    /// Its points `(x, y)`, in data units.
    pub data: Vec<(f64, f64)>,
    /// Vertical error bars `(x, lo, hi)` drawn in the series colour.
    pub errors: Vec<(f64, f64, f64)>,
}

impl Series {
    /// A solid line of width 2 in palette colour `color`.
    pub fn line(name: impl Into<String>, color: usize, data: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            color,
            style: Style::Line(2),
            data,
            errors: Vec::new(),
        }
    }
    /// The same series drawn in another style.
    pub fn with_style(mut self, style: Style) -> Series {
        self.style = style;
        self
    }
}

/// A second pair of axes, a linear rescaling of the primary ones (e.g. SI units of a
/// dimensionless plot): `secondary = scale · primary`.
#[derive(Debug, Clone, PartialEq)]
pub struct Secondary {
    /// Label of the secondary x axis (none: no secondary x axis).
    pub x_label: Option<String>,
    /// Secondary x = `x_scale` · primary x.
    pub x_scale: f64,
    /// Label of the secondary y axis (none: no secondary y axis).
    pub y_label: Option<String>,
    /// Secondary y = `y_scale` · primary y.
    pub y_scale: f64,
}

/// One plotting area.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// The data series drawn.
    pub series: Vec<Series>,
    /// Horizontal dashed reference lines `(y, label)`: the first labelled one dark grey, later
    /// ones lighter; an empty label keeps the previous style and adds no legend entry.
    pub hlines: Vec<(f64, String)>,
    /// Shaded vertical span `(x0, x1, label)` (e.g. the samples the ECR classifier looked at).
    pub span: Option<(f64, f64, String)>,
    /// Secondary axes, if any.
    pub secondary: Option<Secondary>,
    /// Fixed ranges (else from the data, with a margin).
    pub x_range: Option<(f64, f64)>,
    /// The y range, as `x_range`.
    pub y_range: Option<(f64, f64)>,
    /// Where the legend goes.
    pub legend_pos: LegendPos,
}

/// Where the legend box goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegendPos {
    /// The corner with the fewest data points.
    Auto,
    /// Upper right corner.
    UpperRight,
    /// Upper left corner.
    UpperLeft,
    /// Lower right corner.
    LowerRight,
    /// Lower left corner.
    LowerLeft,
}

impl Panel {
    /// An empty panel with its title and axis labels, the legend upper right.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Panel {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            hlines: Vec::new(),
            span: None,
            secondary: None,
            x_range: None,
            y_range: None,
            legend_pos: LegendPos::UpperRight,
        }
    }
}

/// A figure: panels stacked vertically.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem (`motion` → `motion.svg`, `motion.png`).
    pub name: String,
    /// Heading in the HTML page.
    pub title: String,
    /// What to look at (one or two sentences, shown under the figure).
    pub caption: String,
    /// The panels, top to bottom.
    pub panels: Vec<Panel>,
    /// Pixel size.
    pub size: (u32, u32),
}

impl Figure {
    /// Number of data series over all panels.
    pub fn series_count(&self) -> usize {
        self.panels.iter().map(|p| p.series.len()).sum()
    }
}

/// Colour-blind-safe palette (Okabe–Ito), then greys.
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // green
    RGBColor(204, 121, 167), // purple
    RGBColor(230, 159, 0),   // orange
    RGBColor(86, 180, 233),  // sky
    RGBColor(0, 0, 0),       // black
    RGBColor(120, 120, 120), // grey
];

/// The palette's colour `i` (cycling; colour-blind safe, Okabe–Ito).
pub fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

fn plot_err(fig: &str, e: impl std::error::Error + Send + Sync + 'static) -> ReportError {
    ReportError::Plot {
        figure: fig.to_string(),
        source: Box::new(e),
    }
}

/// Renders a figure as an SVG document.
pub fn to_svg(fig: &Figure) -> Result<String, ReportError> {
    register_fonts();
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, fig.size).into_drawing_area();
        draw(&root, fig)?;
        root.present().map_err(|e| plot_err(&fig.name, e))?;
    }
    Ok(out)
}

/// Renders a figure as a PNG file.
pub fn to_png(fig: &Figure, path: &Path) -> Result<(), ReportError> {
    register_fonts();
    let root = BitMapBackend::new(path, fig.size).into_drawing_area();
    draw(&root, fig)?;
    root.present().map_err(|e| plot_err(&fig.name, e))
}

/// Tick label: up to 6 decimals without trailing zeros ("600", "0.15", "0.0205"), scientific
/// below 1e-4, and never "-0".
pub fn tick(v: f64) -> String {
    if v.abs() < 1e-12 {
        return "0".into();
    }
    if v.abs() < 1e-4 {
        return format!("{v:.2e}");
    }
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// Data range with a 4 % margin; a degenerate range is widened.
fn range_of(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    let span = hi - lo;
    let pad = if span > 0.0 {
        0.04 * span
    } else {
        0.5 * lo.abs().max(1e-12)
    };
    Some((lo - pad, hi + pad))
}

fn draw<DB: DrawingBackend<ErrorType: 'static>>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
) -> Result<(), ReportError> {
    let e = |err: DrawingAreaErrorKind<DB::ErrorType>| plot_err(&fig.name, err);
    root.fill(&WHITE).map_err(e)?;
    if fig.panels.is_empty() {
        return Err(ReportError::Empty {
            figure: fig.name.clone(),
            why: "no panel".into(),
        });
    }
    let areas = root.split_evenly((fig.panels.len(), 1));
    for (panel, area) in fig.panels.iter().zip(areas.iter()) {
        draw_panel(area, panel, &fig.name)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend<ErrorType: 'static>>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel,
    fig: &str,
) -> Result<(), ReportError> {
    let e = |err: DrawingAreaErrorKind<DB::ErrorType>| plot_err(fig, err);
    let xs = p.series.iter().flat_map(|s| {
        s.data
            .iter()
            .map(|d| d.0)
            .chain(s.errors.iter().map(|d| d.0))
    });
    let in_x = |x: f64| p.x_range.is_none_or(|(a, b)| x >= a && x <= b);
    let ys = p.series.iter().flat_map(|s| {
        s.data
            .iter()
            .filter(|d| in_x(d.0))
            .map(|d| d.1)
            .chain(s.errors.iter().flat_map(|d| [d.1, d.2]))
    });
    let no_data = || ReportError::Empty {
        figure: fig.to_string(),
        why: format!("panel {:?} has no finite data", p.title),
    };
    let (x0, x1) = p.x_range.or_else(|| range_of(xs)).ok_or_else(no_data)?;
    let (y0, y1) = p
        .y_range
        .or_else(|| range_of(ys.chain(p.hlines.iter().map(|h| h.0))))
        .ok_or_else(no_data)?;
    let sec = p.secondary.clone().unwrap_or(Secondary {
        x_label: None,
        x_scale: 1.0,
        y_label: None,
        y_scale: 1.0,
    });
    let top = if sec.x_label.is_some() { 45 } else { 10 };
    let right = if sec.y_label.is_some() { 80 } else { 20 };
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 20))
        .margin(8)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .top_x_label_area_size(top)
        .right_y_label_area_size(right)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?
        .set_secondary_coord(
            (x0 * sec.x_scale)..(x1 * sec.x_scale),
            (y0 * sec.y_scale)..(y1 * sec.y_scale),
        );
    chart
        .configure_mesh()
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(e)?;
    if sec.x_label.is_some() || sec.y_label.is_some() {
        chart
            .configure_secondary_axes()
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .x_desc(sec.x_label.clone().unwrap_or_default())
            .y_desc(sec.y_label.clone().unwrap_or_default())
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(e)?;
    }
    if let Some((s0, s1, label)) = &p.span {
        let shade = RGBColor(255, 235, 160).mix(0.45).filled();
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(*s0, y0), (*s1, y1)],
                shade,
            )))
            .map_err(e)?
            .label(label.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], shade));
    }
    let (mut grey, mut first) = (40, true);
    for (y, label) in &p.hlines {
        if !label.is_empty() {
            if !first {
                grey = 150;
            }
            first = false;
        }
        let st = RGBColor(grey, grey, grey).stroke_width(1);
        let anno = chart
            .draw_series(DashedLineSeries::new(vec![(x0, *y), (x1, *y)], 6, 4, st))
            .map_err(e)?;
        // An unlabelled line repeats the previous one's style (e.g. the other side of a band).
        if !label.is_empty() {
            anno.label(label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], st));
        }
    }
    let mut has_legend = p.span.is_some() || !p.hlines.is_empty();
    let inside = |d: &&(f64, f64)| p.x_range.is_none() || (d.0 >= x0 && d.0 <= x1);
    for s in &p.series {
        let c = color(s.color);
        let data: Vec<(f64, f64)> = s.data.iter().filter(inside).copied().collect();
        let anno = match s.style {
            Style::Line(w) => chart
                .draw_series(LineSeries::new(data, c.stroke_width(w)))
                .map_err(e)?,
            Style::Dashed(w) => chart
                .draw_series(DashedLineSeries::new(data, 10, 6, c.stroke_width(w)))
                .map_err(e)?,
            Style::Points(r) => chart
                .draw_series(
                    data.iter()
                        .map(|&(x, y)| Circle::new((x, y), r, c.filled())),
                )
                .map_err(e)?,
        };
        if !s.name.is_empty() {
            has_legend = true;
            match s.style {
                Style::Points(r) => anno
                    .label(s.name.as_str())
                    .legend(move |(x, y)| Circle::new((x + 10, y), r.max(3), c.filled())),
                Style::Line(w) | Style::Dashed(w) => {
                    anno.label(s.name.as_str()).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(w))
                    })
                }
            };
        }
        if !s.errors.is_empty() {
            chart
                .draw_series(s.errors.iter().map(|&(x, lo, hi)| {
                    PathElement::new(vec![(x, lo), (x, hi)], c.stroke_width(2))
                }))
                .map_err(e)?;
        }
    }
    if has_legend {
        let corner = if p.legend_pos == LegendPos::Auto {
            emptiest_corner(p, (x0, x1), (y0, y1))
        } else {
            p.legend_pos
        };
        let pos = match corner {
            LegendPos::Auto => SeriesLabelPosition::UpperRight,
            LegendPos::UpperRight => SeriesLabelPosition::UpperRight,
            LegendPos::UpperLeft => SeriesLabelPosition::UpperLeft,
            LegendPos::LowerRight => SeriesLabelPosition::LowerRight,
            LegendPos::LowerLeft => SeriesLabelPosition::LowerLeft,
        };
        chart
            .configure_series_labels()
            .position(pos)
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

/// The corner (legend box about 40 % wide, 30 % high) holding the fewest data points.
fn emptiest_corner(p: &Panel, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> LegendPos {
    let (w, h) = (x1 - x0, y1 - y0);
    let pts: Vec<(f64, f64)> = p
        .series
        .iter()
        .flat_map(|s| {
            s.data
                .iter()
                .copied()
                .chain(s.errors.iter().flat_map(|e| [(e.0, e.1), (e.0, e.2)]))
        })
        .collect();
    let count = |left: bool, top: bool| {
        pts.iter()
            .filter(|d| {
                let fx = (d.0 - x0) / w;
                let fy = (d.1 - y0) / h;
                let in_x = if left { fx < 0.4 } else { fx > 0.6 };
                let in_y = if top { fy > 0.7 } else { fy < 0.3 };
                in_x && in_y
            })
            .count()
    };
    [
        (LegendPos::UpperRight, count(false, true)),
        (LegendPos::UpperLeft, count(true, true)),
        (LegendPos::LowerRight, count(false, false)),
        (LegendPos::LowerLeft, count(true, false)),
    ]
    .into_iter()
    .min_by_key(|c| c.1)
    .map_or(LegendPos::UpperRight, |c| c.0)
}

/// Keeps at most about `2 · bins` points of a curve sampled in `x` order: the first and last point
/// and, in each of `bins` equal x-intervals, the minimum and maximum in their original order — so
/// the peaks a reader checks envelopes against survive.
pub fn decimate(data: &[(f64, f64)], bins: usize) -> Vec<(f64, f64)> {
    let n = data.len();
    if n <= 2 * bins.max(1) + 2 {
        return data.to_vec();
    }
    let per = n.div_ceil(bins.max(1));
    let mut out = Vec::with_capacity(2 * bins + 2);
    out.push(data[0]);
    for chunk in data[1..n - 1].chunks(per) {
        let (mut imin, mut imax) = (0, 0);
        for (i, d) in chunk.iter().enumerate() {
            if d.1 < chunk[imin].1 {
                imin = i;
            }
            if d.1 > chunk[imax].1 {
                imax = i;
            }
        }
        let (a, b) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out.push(data[n - 1]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_short_and_never_negative_zero() {
        assert_eq!(tick(600.0), "600");
        assert_eq!(tick(0.15), "0.15");
        assert_eq!(tick(0.0205), "0.0205");
        assert_eq!(tick(-1e-17), "0");
        assert_eq!(tick(-2.7e-17), "0");
        assert_eq!(tick(2.5e-5), "2.50e-5");
        assert_eq!(tick(-0.3), "-0.3");
    }

    #[test]
    fn decimation_keeps_extremes_and_order() {
        let data: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                (t, (t * 40.0).sin() * (-t / 3.0).exp())
            })
            .collect();
        let d = decimate(&data, 200);
        assert!(d.len() <= 2 * 200 + 2 && d.len() > 200);
        assert!(d.windows(2).all(|w| w[1].0 > w[0].0));
        let max = |v: &[(f64, f64)]| v.iter().fold(f64::MIN, |m, p| m.max(p.1));
        let min = |v: &[(f64, f64)]| v.iter().fold(f64::MAX, |m, p| m.min(p.1));
        assert_eq!(max(&d), max(&data));
        assert_eq!(min(&d), min(&data));
        assert_eq!(d[0], data[0]);
        assert_eq!(*d.last().unwrap(), *data.last().unwrap());
    }

    #[test]
    fn the_embedded_font_is_a_font() {
        assert!(ab_glyph_check(FONT));
    }

    fn ab_glyph_check(bytes: &'static [u8]) -> bool {
        plotters::style::register_font("test-font", FontStyle::Normal, bytes).is_ok()
    }
}
