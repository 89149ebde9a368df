//! Plots of a sweep: one SVG drawn with plotters (text as SVG `<text>`, so no font is needed to
//! write it), rasterised to PNG by `crate::output::png_from_svg`.

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::experiment::LegendPosition;

/// One line of a plot with its band.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// The band's lower and upper edges (empty: no band; points where they are not finite are
    /// left out of it).
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct Plot<'a> {
    pub title: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    pub log_y: bool,
    /// The y range; fitted to the data when `None`.
    pub y_range: Option<(f64, f64)>,
    pub legend: LegendPosition,
    /// What the bands are, as the legend's last entry (say, "band: 95% bootstrap CI").
    pub band_desc: Option<&'a str>,
    pub series: &'a [Series],
}

const WIDTH: u32 = 960;
const HEIGHT: u32 = 600;

/// Line colours (the "tab10" palette).
pub(crate) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Series of at most this many points get a marker at each.
const MARKED_POINTS: usize = 12;

/// The plot as an SVG document.
pub fn svg(plot: &Plot) -> crate::Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (WIDTH, HEIGHT)).into_drawing_area();
        let (lo, hi) = plot.y_range.unwrap_or_else(|| fit_range(plot));
        if plot.log_y {
            draw(&root, plot, (lo..hi).log_scale(), lo, hi)?;
        } else {
            draw(&root, plot, lo..hi, lo, hi)?;
        }
        root.present().map_err(|e| crate::error::msg!("{e}"))?;
    }
    Ok(out)
}

/// The y range that holds every line and band (log scale: the positive part).
fn fit_range(plot: &Plot) -> (f64, f64) {
    let all = || {
        plot.series
            .iter()
            .flat_map(|s| s.y.iter().chain(&s.lo).chain(&s.hi).copied())
            .filter(|v| v.is_finite())
    };
    if plot.log_y {
        // From just below the lowest line (the bands may reach 0 or below) to above the highest.
        let lines = plot.series.iter().flat_map(|s| s.y.iter().copied());
        let lo = lines
            .filter(|v| *v > 0.0)
            .fold(f64::INFINITY, f64::min)
            .min(10.0);
        let lo = if lo.is_finite() { lo * 0.5 } else { 1.0 };
        let hi = all().fold(lo * 10.0, f64::max) * 1.3;
        (lo, hi)
    } else {
        let lo = all().fold(f64::INFINITY, f64::min);
        let hi = all().fold(f64::NEG_INFINITY, f64::max);
        if !(lo.is_finite() && hi.is_finite()) {
            return (0.0, 1.0);
        }
        let pad = ((hi - lo) * 0.05).max(1e-9);
        (lo - pad, hi + pad)
    }
}

fn draw<DB, Y>(
    root: &DrawingArea<DB, Shift>,
    plot: &Plot,
    y_spec: Y,
    y_lo: f64,
    y_hi: f64,
) -> crate::Result<()>
where
    DB: DrawingBackend,
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    root.fill(&WHITE).map_err(drawing_error)?;
    let x_max = plot
        .series
        .iter()
        .flat_map(|s| s.x.iter().copied())
        .fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(plot.title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(0.0..x_max, y_spec)
        .map_err(drawing_error)?;
    chart
        .configure_mesh()
        .x_desc(plot.x_desc)
        .y_desc(plot.y_desc)
        .axis_desc_style(("sans-serif", 16))
        .label_style(("sans-serif", 14))
        .x_label_formatter(&|v| format_number(*v))
        .y_label_formatter(&|v| format_number(*v))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(drawing_error)?;
    let clamp = |v: f64| v.clamp(y_lo, y_hi);
    for (i, s) in plot.series.iter().enumerate() {
        draw_band(&mut chart, s, PALETTE[i % PALETTE.len()], clamp)?;
    }
    for (i, s) in plot.series.iter().enumerate() {
        draw_line(&mut chart, s, PALETTE[i % PALETTE.len()], clamp)?;
    }
    draw_legend(&mut chart, plot)
}

/// A chart whose x axis is linear and whose y axis is `Y` (linear or log).
type Chart<'a, DB, Y> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>;

/// The error of a drawing step of the plot.
fn drawing_error<E: std::error::Error + Send + Sync>(
    e: DrawingAreaErrorKind<E>,
) -> crate::LabError {
    crate::error::msg!("drawing the plot: {e}")
}

/// The band of `s` in `color`, its edges brought into the y range by `clamp`.
fn draw_band<'a, DB, Y>(
    chart: &mut Chart<'a, DB, Y>,
    s: &Series,
    color: RGBColor,
    clamp: impl Fn(f64) -> f64,
) -> crate::Result<()>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64>,
{
    let edges: Vec<(f64, f64, f64)> =
        s.x.iter()
            .zip(&s.lo)
            .zip(&s.hi)
            .filter(|((_, l), h)| l.is_finite() && h.is_finite())
            .map(|((&x, &l), &h)| (x, clamp(l), clamp(h)))
            .collect();
    // A band needs two x values (one point has no area: nothing to draw).
    if edges.len() >= 2 {
        let band: Vec<(f64, f64)> = edges
            .iter()
            .map(|&(x, _, h)| (x, h))
            .chain(edges.iter().rev().map(|&(x, l, _)| (x, l)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                band,
                color.mix(0.10).filled(),
            )))
            .map_err(drawing_error)?;
    }
    Ok(())
}

/// The line of `s` in `color` (markers when it has few points), its values brought into the y
/// range by `clamp`, with its legend entry.
fn draw_line<'a, DB, Y>(
    chart: &mut Chart<'a, DB, Y>,
    s: &Series,
    color: RGBColor,
    clamp: impl Fn(f64) -> f64,
) -> crate::Result<()>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64>,
{
    let points: Vec<(f64, f64)> = s.x.iter().zip(&s.y).map(|(&x, &y)| (x, clamp(y))).collect();
    // Few points (a plot against B): each marked; one point: a marker alone, no line.
    if (2..=MARKED_POINTS).contains(&points.len()) {
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(drawing_error)?;
    }
    let drawn = if points.len() >= 2 {
        chart.draw_series(LineSeries::new(points, color.stroke_width(2)))
    } else {
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 4, color.filled())),
        )
    };
    drawn
        .map_err(drawing_error)?
        // The legend box is sized from an estimate of the text's width that runs short for
        // common fonts; trailing spaces (not rendered) widen it.
        .label(format!("{}{}", s.label, " ".repeat(2 + s.label.len() / 5)))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
    Ok(())
}

/// The legend: the lines' entries, then the bands' description when the plot has one.
fn draw_legend<'a, DB, Y>(chart: &mut Chart<'a, DB, Y>, plot: &Plot) -> crate::Result<()>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64>,
{
    if let Some(desc) = plot.band_desc {
        let grey = RGBColor(90, 90, 90);
        chart
            .draw_series(std::iter::empty::<Polygon<(f64, f64)>>())
            .map_err(drawing_error)?
            .label(format!("{desc}{}", " ".repeat(2 + desc.len() / 5)))
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 24, y + 5)], grey.mix(0.25).filled())
            });
    }
    chart
        .configure_series_labels()
        .position(match plot.legend {
            LegendPosition::UpperLeft => SeriesLabelPosition::UpperLeft,
            LegendPosition::UpperRight => SeriesLabelPosition::UpperRight,
            LegendPosition::LowerLeft => SeriesLabelPosition::LowerLeft,
            LegendPosition::LowerRight => SeriesLabelPosition::LowerRight,
        })
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(drawing_error)?;
    Ok(())
}

/// Axis labels: integers without a fraction, others with up to 3 significant decimals.
fn format_number(v: f64) -> String {
    if v == v.round() && v.abs() < 1e9 {
        format!("{}", v as i64)
    } else if v.abs() >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series() -> Vec<Series> {
        vec![Series {
            label: "method-a".into(),
            x: vec![0.0, 1.0, 2.0],
            y: vec![10.0, 20.0, 300.0],
            lo: vec![5.0, -3.0, 200.0],
            hi: vec![15.0, 40.0, 400.0],
        }]
    }

    #[test]
    fn svg_has_the_title_axes_and_legend() {
        for log_y in [false, true] {
            let s = series();
            let plot = Plot {
                title: "A title",
                x_desc: "episode",
                y_desc: "return",
                log_y,
                y_range: None,
                legend: LegendPosition::UpperLeft,
                band_desc: Some("band: 95% CI"),
                series: &s,
            };
            let svg = svg(&plot).unwrap();
            assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
            for text in ["A title", "episode", "return", "method-a", "band: 95% CI"] {
                assert!(svg.contains(text), "{text} missing");
            }
            assert!(svg.contains("<polygon") || svg.contains("<path"));
        }
    }

    #[test]
    fn log_range_starts_below_the_lowest_line() {
        let s = series();
        let plot = Plot {
            title: "t",
            x_desc: "x",
            y_desc: "y",
            log_y: true,
            y_range: None,
            legend: LegendPosition::UpperLeft,
            band_desc: None,
            series: &s,
        };
        let (lo, hi) = fit_range(&plot);
        assert_eq!(lo, 5.0);
        assert_eq!(hi, 400.0 * 1.3);
    }
}
