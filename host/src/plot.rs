//! A small declarative layer over plotters' SVG backend: a figure is a stack of panels, each
//! with linear or logarithmic axes, line/dashed/point series, shaded x-bands and reference
//! lines. Rendering is deterministic (same data → same SVG text).
use crate::error::{Error, Result};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Colours (matplotlib's tab10, which print and read well).
pub mod colors {
    use plotters::style::RGBColor;
    /// Blue.
    pub const BLUE: RGBColor = RGBColor(31, 119, 180);
    /// Orange.
    pub const ORANGE: RGBColor = RGBColor(255, 127, 14);
    /// Green.
    pub const GREEN: RGBColor = RGBColor(44, 160, 44);
    /// Red.
    pub const RED: RGBColor = RGBColor(214, 39, 40);
    /// Purple.
    pub const PURPLE: RGBColor = RGBColor(148, 103, 189);
    /// Brown.
    pub const BROWN: RGBColor = RGBColor(140, 86, 75);
    /// Grey.
    pub const GREY: RGBColor = RGBColor(127, 127, 127);
    /// Light grey.
    pub const LIGHT_GREY: RGBColor = RGBColor(190, 190, 190);
    /// Olive.
    pub const OLIVE: RGBColor = RGBColor(188, 189, 34);
    /// Cyan.
    pub const CYAN: RGBColor = RGBColor(23, 190, 207);
    /// Shading of bands the coherence gate excluded.
    pub const EXCLUDED: RGBColor = RGBColor(253, 208, 162);
    /// Shading of a region of interest.
    pub const REGION: RGBColor = RGBColor(222, 235, 247);
    /// Cycle for several logs.
    pub const CYCLE: [RGBColor; 6] = [BLUE, GREEN, PURPLE, BROWN, OLIVE, CYAN];
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kind {
    /// Solid polyline of the given width (px).
    Line(u32),
    /// Dashed polyline of the given width (px).
    Dashed(u32),
    /// Filled circles of the given radius (px).
    Points(u32),
    /// Hollow circles of the given radius (px).
    Hollow(u32),
}

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label (None: not in the legend).
    pub label: Option<String>,
    /// (x, y) points; non-finite or (on log axes) non-positive points are skipped, and a
    /// line is broken there.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
    /// Drawing kind.
    pub kind: Kind,
}

impl Series {
    /// A labelled series.
    pub fn new(label: &str, points: Vec<(f64, f64)>, color: RGBColor, kind: Kind) -> Self {
        Self {
            label: (!label.is_empty()).then(|| label.to_string()),
            points,
            color,
            kind,
        }
    }
}

/// A horizontal or vertical reference line.
#[derive(Debug, Clone)]
pub struct RefLine {
    /// Position (data units).
    pub at: f64,
    /// Colour.
    pub color: RGBColor,
    /// Legend label (None: unlabelled).
    pub label: Option<String>,
}

/// A shaded x-interval spanning the panel's height.
#[derive(Debug, Clone, Copy)]
pub struct Band {
    /// Start (x units).
    pub x0: f64,
    /// End (x units).
    pub x1: f64,
    /// Fill colour.
    pub color: RGBColor,
}

/// Legend placement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegendAt {
    /// Upper right.
    UpperRight,
    /// Upper left.
    UpperLeft,
    /// Lower left.
    LowerLeft,
    /// Lower right.
    LowerRight,
    /// No legend.
    None,
}

/// One chart.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Title drawn above the chart ("" for none).
    pub title: String,
    /// x-axis description.
    pub x_desc: String,
    /// y-axis description.
    pub y_desc: String,
    /// Logarithmic x axis.
    pub x_log: bool,
    /// Logarithmic y axis.
    pub y_log: bool,
    /// x range (None: from the data).
    pub x_range: Option<(f64, f64)>,
    /// y range (None: from the data, with 5 % padding).
    pub y_range: Option<(f64, f64)>,
    /// Shaded bands (drawn first).
    pub bands: Vec<Band>,
    /// Label for the shaded bands in the legend (None: unlabelled).
    pub band_label: Option<String>,
    /// Horizontal reference lines (dashed).
    pub hlines: Vec<RefLine>,
    /// Vertical reference lines (dashed).
    pub vlines: Vec<RefLine>,
    /// Data series, drawn in order.
    pub series: Vec<Series>,
    /// Legend position.
    pub legend: LegendAt,
}

impl Panel {
    /// An empty panel with axis descriptions.
    pub fn new(title: &str, x_desc: &str, y_desc: &str, x_log: bool, y_log: bool) -> Self {
        Self {
            title: title.into(),
            x_desc: x_desc.into(),
            y_desc: y_desc.into(),
            x_log,
            y_log,
            x_range: None,
            y_range: None,
            bands: Vec::new(),
            band_label: None,
            hlines: Vec::new(),
            vlines: Vec::new(),
            series: Vec::new(),
            legend: LegendAt::UpperRight,
        }
    }

    fn usable(&self, x: f64, y: f64) -> bool {
        x.is_finite() && y.is_finite() && (!self.x_log || x > 0.0) && (!self.y_log || y > 0.0)
    }

    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
        let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(x, y) in &s.points {
                if self.usable(x, y) {
                    xs = (xs.0.min(x), xs.1.max(x));
                    ys = (ys.0.min(y), ys.1.max(y));
                }
            }
        }
        for h in &self.hlines {
            if h.at.is_finite() && (!self.y_log || h.at > 0.0) {
                ys = (ys.0.min(h.at), ys.1.max(h.at));
            }
        }
        let x = self.x_range.unwrap_or(xs);
        let y = self.y_range.unwrap_or_else(|| pad(ys, self.y_log));
        (fix_range(x, self.x_log), fix_range(y, self.y_log))
    }
}

fn pad(r: (f64, f64), log: bool) -> (f64, f64) {
    if !(r.0.is_finite() && r.1.is_finite()) {
        return r;
    }
    if log {
        let (a, b) = (r.0.ln(), r.1.ln());
        let p = 0.05 * (b - a).max(0.1);
        ((a - p).exp(), (b + p).exp())
    } else {
        let p = 0.05 * (r.1 - r.0).max(1e-12 * r.1.abs().max(1.0));
        (r.0 - p, r.1 + p)
    }
}

/// Most decades a log axis spans; a wider range keeps its upper end (plotters' log-axis key
/// points are generated decade by decade, and an axis from 4e-4 to 1e300 never finishes).
pub const MAX_LOG_DECADES: f64 = 30.0;

fn fix_range(r: (f64, f64), log: bool) -> (f64, f64) {
    let (mut a, mut b) = r;
    if !(a.is_finite() && b.is_finite()) || (log && !(a > 0.0 && b > 0.0)) {
        return if log { (0.1, 10.0) } else { (-1.0, 1.0) };
    }
    if log {
        // Normal, finite positive numbers whose ratio is representable.
        a = a.clamp(1e-290, 1e290);
        b = b.clamp(1e-290, 1e290);
    } else if !(b - a).is_finite() {
        // A linear span that overflows: keep the larger magnitude's half.
        let m = a.abs().max(b.abs());
        (a, b) = (-m / 2.0, m / 2.0);
    }
    if b <= a {
        if log {
            a /= 2.0;
            b = a * 4.0;
        } else {
            let d = a.abs().max(1.0) * 0.5;
            a -= d;
            b += d;
        }
    }
    if log && (b / a).log10() > MAX_LOG_DECADES {
        a = b / 10f64.powf(MAX_LOG_DECADES);
    }
    (a, b)
}

/// Tick label: up to 4 significant digits, no trailing zeros, scientific outside 1e-3..1e5.
pub fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        return s.replace(".0e", "e");
    }
    let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

fn err<E: std::fmt::Debug>(what: &str) -> impl Fn(E) -> Error + '_ {
    move |e| Error::Numerical(format!("rendering figure `{what}`: {e:?}"))
}

/// `s` without the characters XML forbids in text (control characters other than tab and
/// newline, e.g. a NUL in a unit string), each replaced by U+FFFD, so every figure is valid
/// SVG whatever the pipeline file says.
pub fn xml_text(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_control() && !matches!(c, '\n' | '\t') {
                '\u{FFFD}'
            } else {
                c
            }
        })
        .collect()
}

fn xml_safe(p: &Panel) -> Panel {
    let mut p = p.clone();
    p.title = xml_text(&p.title);
    p.x_desc = xml_text(&p.x_desc);
    p.y_desc = xml_text(&p.y_desc);
    p.band_label = p.band_label.as_deref().map(xml_text);
    for l in p.hlines.iter_mut().chain(p.vlines.iter_mut()) {
        l.label = l.label.as_deref().map(xml_text);
    }
    for s in &mut p.series {
        s.label = s.label.as_deref().map(xml_text);
    }
    p
}

/// Renders `panels` stacked vertically into an SVG of `width` × Σ heights pixels. Text is made
/// XML-safe first ([`xml_text`]).
pub fn render(name: &str, width: u32, panels: &[(Panel, u32)]) -> Result<String> {
    let panels: Vec<(Panel, u32)> = panels.iter().map(|(p, h)| (xml_safe(p), *h)).collect();
    let panels = panels.as_slice();
    let height: u32 = panels.iter().map(|p| p.1).sum();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err(name))?;
        let mut rest = root.clone();
        for (i, (p, h)) in panels.iter().enumerate() {
            let area = if i + 1 == panels.len() {
                rest.clone()
            } else {
                let (a, b) = rest.split_vertically(*h);
                rest = b;
                a
            };
            let ((x0, x1), (y0, y1)) = p.ranges();
            match (p.x_log, p.y_log) {
                (false, false) => draw_panel(name, &area, p, x0..x1, y0..y1)?,
                (true, false) => draw_panel(name, &area, p, (x0..x1).log_scale(), y0..y1)?,
                (false, true) => draw_panel(name, &area, p, x0..x1, (y0..y1).log_scale())?,
                (true, true) => {
                    draw_panel(name, &area, p, (x0..x1).log_scale(), (y0..y1).log_scale())?
                }
            }
        }
        root.present().map_err(err(name))?;
    }
    Ok(svg)
}

fn draw_panel<XR, YR>(
    name: &str,
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    p: &Panel,
    xr: XR,
    yr: YR,
) -> Result<()>
where
    XR: AsRangedCoord<Value = f64>,
    YR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: ValueFormatter<f64>,
    YR::CoordDescType: ValueFormatter<f64>,
{
    let e = err(name);
    let mut builder = ChartBuilder::on(area);
    builder
        .margin_top(8)
        .margin_bottom(4)
        .margin_left(8)
        .margin_right(24)
        .x_label_area_size(46)
        .y_label_area_size(72);
    if !p.title.is_empty() {
        builder.caption(&p.title, ("sans-serif", 17).into_font());
    }
    let mut chart = builder.build_cartesian_2d(xr, yr).map_err(&e)?;
    let (xs, ys) = (p.ranges().0, p.ranges().1);
    let (xspan, yspan) = ((xs.1 - xs.0).abs(), (ys.1 - ys.0).abs());
    let fx = move |v: &f64| tick(if v.abs() < 1e-9 * xspan { 0.0 } else { *v });
    let fy = move |v: &f64| tick(if v.abs() < 1e-9 * yspan { 0.0 } else { *v });
    chart
        .configure_mesh()
        .x_desc(p.x_desc.as_str())
        .y_desc(p.y_desc.as_str())
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .x_labels(10)
        .y_labels(8)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(&e)?;
    let (xrange, yrange) = (chart.x_range(), chart.y_range());
    let b = Bounds {
        x: (xrange.start, xrange.end),
        y: (yrange.start, yrange.end),
    };
    draw_bands(name, &mut chart, p, b)?;
    draw_rules(name, &mut chart, p, b)?;
    for s in &p.series {
        draw_series(name, &mut chart, p, s, b)?;
    }
    draw_legend(name, &mut chart, p)
}

/// A panel's chart: SVG backend, two f64 axes (linear or logarithmic).
type Chart<'a, 'b, X, Y> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<X, Y>>;

/// The drawn axis ranges `(lo, hi)` of a panel.
#[derive(Clone, Copy)]
struct Bounds {
    x: (f64, f64),
    y: (f64, f64),
}

/// Shaded x-bands, clipped to the x range; the first one carries the band label.
fn draw_bands<X, Y>(name: &str, chart: &mut Chart<'_, '_, X, Y>, p: &Panel, b: Bounds) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let e = err(name);
    let mut first_band = true;
    for band in &p.bands {
        let (a, c) = (band.x0.max(b.x.0), band.x1.min(b.x.1));
        if a.is_nan() || c.is_nan() || a > c {
            continue;
        }
        let anno = chart
            .draw_series(std::iter::once(Rectangle::new(
                [(a, b.y.0), (c, b.y.1)],
                band.color.mix(0.55).filled(),
            )))
            .map_err(&e)?;
        if first_band {
            if let Some(l) = &p.band_label {
                let col = band.color;
                anno.label(l.as_str()).legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 20, y + 6)], col.mix(0.55).filled())
                });
            }
            first_band = false;
        }
    }
    Ok(())
}

/// Dashed horizontal and vertical reference lines inside the ranges, with their labels.
fn draw_rules<X, Y>(name: &str, chart: &mut Chart<'_, '_, X, Y>, p: &Panel, b: Bounds) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let e = err(name);
    let horizontal = p
        .hlines
        .iter()
        .filter(|h| h.at.is_finite() && h.at > b.y.0 && h.at < b.y.1)
        .map(|h| (h, [(b.x.0, h.at), (b.x.1, h.at)]));
    let vertical = p
        .vlines
        .iter()
        .filter(|v| v.at.is_finite() && v.at > b.x.0 && v.at < b.x.1)
        .map(|v| (v, [(v.at, b.y.0), (v.at, b.y.1)]));
    for (rule, ends) in horizontal.chain(vertical) {
        let col = rule.color;
        let anno = chart
            .draw_series(DashedLineSeries::new(ends, 6, 4, col.stroke_width(1)))
            .map_err(&e)?;
        if let Some(l) = &rule.label {
            anno.label(l.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col));
        }
    }
    Ok(())
}

/// The runs of a series' points that can be drawn: points outside the ranges (or unusable
/// on a log axis) are not drawn and break lines (no clamping: a clamped line would draw data
/// that is not there).
fn drawable_pieces(p: &Panel, s: &Series, b: Bounds) -> Vec<Vec<(f64, f64)>> {
    let tol = 1e-9 * (b.y.1 - b.y.0).abs();
    let xtol = 1e-9 * (b.x.1 - b.x.0).abs();
    let inside = |x: f64, y: f64| {
        p.usable(x, y)
            && y >= b.y.0 - tol
            && y <= b.y.1 + tol
            && x >= b.x.0 - xtol
            && x <= b.x.1 + xtol
    };
    let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for &(x, y) in &s.points {
        if inside(x, y) {
            if let Some(last) = pieces.last_mut() {
                last.push((x, y));
            }
        } else if pieces.last().is_some_and(|l| !l.is_empty()) {
            pieces.push(Vec::new());
        }
    }
    pieces.retain(|pc| !pc.is_empty());
    pieces
}

/// One series, piece by piece; its label goes on the first piece drawn.
fn draw_series<X, Y>(
    name: &str,
    chart: &mut Chart<'_, '_, X, Y>,
    p: &Panel,
    s: &Series,
    b: Bounds,
) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let e = err(name);
    let col = s.color;
    for (i, piece) in drawable_pieces(p, s, b).iter().enumerate() {
        let anno = match s.kind {
            Kind::Line(w) => chart
                .draw_series(LineSeries::new(piece.iter().copied(), col.stroke_width(w)))
                .map_err(&e)?,
            Kind::Dashed(w) => chart
                .draw_series(DashedLineSeries::new(
                    piece.iter().copied(),
                    7,
                    4,
                    col.stroke_width(w),
                ))
                .map_err(&e)?,
            Kind::Points(r) => chart
                .draw_series(piece.iter().map(|&pt| Circle::new(pt, r, col.filled())))
                .map_err(&e)?,
            Kind::Hollow(r) => chart
                .draw_series(
                    piece
                        .iter()
                        .map(|&pt| Circle::new(pt, r, col.stroke_width(1))),
                )
                .map_err(&e)?,
        };
        let Some(l) = s.label.as_ref().filter(|_| i == 0) else {
            continue;
        };
        match s.kind {
            Kind::Line(w) | Kind::Dashed(w) => {
                anno.label(l.as_str()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(w))
                });
            }
            Kind::Points(r) => {
                anno.label(l.as_str())
                    .legend(move |(x, y)| Circle::new((x + 10, y), r.max(3), col.filled()));
            }
            Kind::Hollow(r) => {
                anno.label(l.as_str())
                    .legend(move |(x, y)| Circle::new((x + 10, y), r.max(3), col.stroke_width(1)));
            }
        }
    }
    Ok(())
}

/// The legend box, when the panel asks for one and anything carries a label.
fn draw_legend<'a, 'b: 'a, X, Y>(
    name: &str,
    chart: &mut Chart<'a, 'b, X, Y>,
    p: &Panel,
) -> Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let pos = match p.legend {
        LegendAt::UpperRight => SeriesLabelPosition::UpperRight,
        LegendAt::UpperLeft => SeriesLabelPosition::UpperLeft,
        LegendAt::LowerLeft => SeriesLabelPosition::LowerLeft,
        LegendAt::LowerRight => SeriesLabelPosition::LowerRight,
        LegendAt::None => return Ok(()),
    };
    let any_label = p.series.iter().any(|s| s.label.is_some())
        || p.hlines.iter().any(|h| h.label.is_some())
        || p.vlines.iter().any(|h| h.label.is_some())
        || (p.band_label.is_some() && !p.bands.is_empty());
    if any_label {
        chart
            .configure_series_labels()
            .position(pos)
            .margin(8)
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(160, 160, 160))
            .draw()
            .map_err(err(name))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_log_ranges_render_in_bounded_work() {
        // Before: a log axis from 4e-4 Hz to 1e300 Hz never finished (plotters walks decades).
        for (lo, hi) in [
            (4e-4, 1e300),
            (1e-310, 1.0),
            (0.0, 10.0),
            (1.0, f64::INFINITY),
        ] {
            let (a, b) = fix_range((lo, hi), true);
            assert!(
                a > 0.0 && b > a && (b / a).log10() <= MAX_LOG_DECADES + 1e-9,
                "{a} {b}"
            );
        }
        let mut p = Panel::new("t\0itle", "f", "unit \u{1}x", true, false);
        p.x_range = Some((4e-4, 1e300));
        p.series.push(Series::new(
            "s\0",
            vec![(1.0, 1.0), (10.0, 2.0)],
            RGBColor(0, 0, 0),
            Kind::Line(1),
        ));
        let svg = render("t", 400, &[(p, 300)]).unwrap();
        assert!(!svg
            .chars()
            .any(|c| c.is_control() && c != '\n' && c != '\t'));
    }

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(10.0), "10");
        assert_eq!(tick(0.5), "0.5");
        assert_eq!(tick(1234.0), "1234");
        assert_eq!(tick(2e-5), "2e-5");
        assert_eq!(tick(-3.25), "-3.25");
    }
}
