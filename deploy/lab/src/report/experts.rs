//! A run with several experts, `RUN_DIR/experts.svg` and `experts.png`: each expert's estimated
//! quality after each of its answers (`experts.csv`) against the environment step, its 95%
//! interval shaded, one colour per expert.

use std::path::Path;

use crate::error::Context as _;
use plotters::prelude::*;

const WIDTH: u32 = 960;
const HEIGHT: u32 = 480;
/// One colour per expert.
use crate::sweep::plot::PALETTE as COLOURS;

/// One row of `experts.csv`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct QualityPoint {
    pub step: f64,
    pub expert: String,
    pub answers: u64,
    pub quality: f64,
    pub low: f64,
    pub high: f64,
}

/// The rows of `experts.csv` (`step,expert,answers,quality,low,high`).
pub(crate) fn parse(text: &str) -> crate::Result<Vec<QualityPoint>> {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    crate::error::ensure!(
        header == "step,expert,answers,quality,low,high",
        "experts.csv: unexpected header `{header}`"
    );
    lines
        .enumerate()
        .map(|(i, line)| {
            let f: Vec<&str> = line.split(',').collect();
            let num = |k: usize| -> crate::Result<f64> {
                f.get(k).and_then(|v| v.parse().ok()).ok_or_else(|| {
                    crate::error::msg!("experts.csv line {}: field {}", i + 2, k + 1)
                })
            };
            crate::error::ensure!(f.len() == 6, "experts.csv line {}: 6 fields", i + 2);
            Ok(QualityPoint {
                step: num(0)?,
                expert: f[1].to_owned(),
                answers: num(2)? as u64,
                quality: num(3)?,
                low: num(4)?,
                high: num(5)?,
            })
        })
        .collect()
}

/// Writes `dir/experts.svg` and, when a font is found, `dir/experts.png` from `dir/experts.csv`;
/// nothing when the run had one expert.
pub(crate) fn write(dir: &Path) -> crate::Result<()> {
    let path = dir.join("experts.csv");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    let points = parse(&text).with_context(|| format!("in {}", path.display()))?;
    let svg = svg(&points)?;
    crate::output::write(dir, "experts.svg", svg.as_bytes())?;
    if let Some(png) = crate::output::png_from_svg(&svg)? {
        crate::output::write(dir, "experts.png", &png)?;
    }
    Ok(())
}

/// The experts' names in the order they first answered.
fn names(points: &[QualityPoint]) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for p in points {
        if !out.contains(&p.expert.as_str()) {
            out.push(&p.expert);
        }
    }
    out
}

/// The picture as an SVG document.
pub(crate) fn svg(points: &[QualityPoint]) -> crate::Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, points).map_err(|e| crate::error::msg!("drawing experts.svg: {e}"))?;
        root.present()
            .map_err(|e| crate::error::msg!("drawing experts.svg: {e}"))?;
    }
    Ok(out)
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    points: &[QualityPoint],
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let x_max = points.iter().map(|p| p.step).fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(
            "each expert's estimated quality (95% interval)",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_max, 0.0..1.0)?;
    chart
        .configure_mesh()
        .x_desc("environment step")
        .y_desc("quality (agreement)")
        .axis_desc_style(("sans-serif", 15))
        .label_style(("sans-serif", 13))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()?;
    for (i, name) in names(points).into_iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let own: Vec<&QualityPoint> = points.iter().filter(|p| p.expert == name).collect();
        let band: Vec<(f64, f64)> = own
            .iter()
            .map(|p| (p.step, p.high))
            .chain(own.iter().rev().map(|p| (p.step, p.low)))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(band, colour.mix(0.15))))?;
        let line: Vec<(f64, f64)> = own.iter().map(|p| (p.step, p.quality)).collect();
        // One answer is a point: a line of one point is no line.
        let series = if line.len() > 1 {
            chart.draw_series(LineSeries::new(line, colour.stroke_width(2)))?
        } else {
            chart.draw_series(line.into_iter().map(|p| Circle::new(p, 3, colour.filled())))?
        };
        series
            .label(name.to_owned())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "step,expert,answers,quality,low,high\n\
                       7,good,1,1,0,1\n9,poor,1,0.5,0.1,0.9\n12,good,2,0.75,0.4,1\n";

    #[test]
    fn experts_csv_reads_back_and_draws_one_line_per_expert() {
        let points = parse(CSV).unwrap();
        assert_eq!(points.len(), 3);
        assert_eq!((points[2].step, points[2].answers), (12.0, 2));
        assert_eq!(names(&points), ["good", "poor"]);
        let svg = svg(&points).unwrap();
        assert!(
            svg.contains("\ngood\n") && svg.contains("\npoor\n"),
            "a legend entry each"
        );
        // `poor` answered once: a point, not a polyline of one point (which renderers skip).
        assert_eq!(svg.matches("<circle").count(), 1, "{svg}");
        let lines: Vec<&str> = svg.split("<polyline").skip(1).collect();
        for l in lines {
            let points = l
                .split("points=\"")
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap();
            assert!(points.split_whitespace().count() >= 2, "{l}");
        }
        assert!(parse("step,who\n")
            .unwrap_err()
            .to_string()
            .contains("header"));
        let short = format!("{CSV}3,good,1\n");
        assert!(parse(&short).unwrap_err().to_string().contains("line 5"));
    }
}
