//! A run's learning curve, `RUN_DIR/curve.svg` (plotters; text as SVG `<text>`, no font needed)
//! and `RUN_DIR/curve.png` (rasterised with resvg by `crate::output::png_from_svg`, written only
//! when a font is found). Top panel: the return of each episode (thin), its 20-episode moving
//! average (thick), the greedy evaluations (dots), the expert's measured return (dashed), and
//! the shaping window (shaded: episodes with shaped steps). Bottom panel: demonstrations used,
//! and the budget B (dashed).

use std::path::Path;

use crate::error::Context as _;
use alfd_common::config::ExperimentConfig;
use alfd_common::record::EpisodeRecord;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::ExpertReference;

const WIDTH: u32 = 960;
const HEIGHT: u32 = 720;
/// Episodes in the moving average.
const SMOOTH: usize = 20;

const RETURN: RGBColor = RGBColor(31, 119, 180);
const EVAL: RGBColor = RGBColor(214, 39, 40);
const EXPERT: RGBColor = RGBColor(44, 160, 44);
const SHADE: RGBColor = RGBColor(255, 127, 14);
const DEMOS: RGBColor = RGBColor(148, 103, 189);
const GREY: RGBColor = RGBColor(90, 90, 90);

/// What the picture shows.
#[derive(Debug)]
pub(crate) struct Curve<'a> {
    pub title: String,
    /// In episode order.
    pub records: &'a [EpisodeRecord],
    /// The expert's name and measured mean return, when it is on the run's scale.
    pub expert: Option<(String, f64)>,
    pub budget: u32,
}

/// Writes `dir/curve.svg` and, when a font is found, `dir/curve.png` (else removes a stale one).
pub(crate) fn write(
    dir: &Path,
    cfg: &ExperimentConfig,
    expert: &ExpertReference,
    records: &[EpisodeRecord],
) -> crate::Result<()> {
    let mut records = records.to_vec();
    records.sort_by_key(|r| r.episode);
    let name = dir
        .canonicalize()
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| dir.display().to_string());
    let curve = Curve {
        title: format!(
            "{}, {} (seed {}): {name}",
            cfg.env.name,
            super::agent_name(cfg),
            cfg.seed
        ),
        records: &records,
        expert: expert.comparable_mean().map(|m| (expert.name.clone(), m)),
        budget: cfg.budget(),
    };
    let svg = svg(&curve)?;
    crate::output::write(dir, "curve.svg", svg.as_bytes())?;
    match crate::output::png_from_svg(&svg)? {
        Some(png) => crate::output::write(dir, "curve.png", &png)?,
        None => match std::fs::remove_file(dir.join("curve.png")) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).context("cannot remove the stale curve.png")
            }
            _ => {}
        },
    }
    Ok(())
}

/// The picture as an SVG document.
pub(crate) fn svg(curve: &Curve) -> crate::Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, curve)?;
        root.present()
            .map_err(|e| crate::error::msg!("drawing the learning curve: {e}"))?;
    }
    Ok(out)
}

/// Consecutive episodes (first, last) whose reward was shaped.
fn shaping_windows(records: &[EpisodeRecord]) -> Vec<(u32, u32)> {
    let mut windows: Vec<(u32, u32)> = Vec::new();
    for r in records.iter().filter(|r| r.shaped_steps > 0) {
        match windows.last_mut() {
            Some((_, last)) if r.episode <= *last + 1 => *last = r.episode,
            _ => windows.push((r.episode, r.episode)),
        }
    }
    windows
}

/// The trailing mean of up to `n` values ending at each one.
fn moving_average(values: &[f64], n: usize) -> Vec<f64> {
    let mut sum = 0.0;
    (0..values.len())
        .map(|i| {
            sum += values[i];
            if i >= n {
                sum -= values[i - n];
            }
            sum / (i + 1).min(n) as f64
        })
        .collect()
}

/// A legend entry; trailing spaces widen plotters' legend box, which runs short for common fonts.
fn label(s: &str) -> String {
    format!("{s}{}", " ".repeat(2 + s.len() / 5))
}

/// `lo..hi` padded by 5%, or around the value when they are equal.
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(0.5);
    (lo - pad, hi + pad)
}

fn format_number(v: f64) -> String {
    if v == v.round() && v.abs() < 1e9 {
        format!("{}", v as i64)
    } else {
        format!("{v:.1}")
    }
}

/// One panel of the picture: episodes on x, `y_desc` on y over `y`, the grid drawn.
fn panel<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    x_max: f64,
    y: (f64, f64),
    y_desc: &str,
) -> crate::Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| {
        crate::error::msg!("drawing the learning curve: {e}")
    };
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..x_max, y.0..y.1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("episode")
        .y_desc(y_desc)
        .axis_desc_style(("sans-serif", 15))
        .label_style(("sans-serif", 13))
        .x_label_formatter(&|v| format_number(*v))
        .y_label_formatter(&|v| format_number(*v))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(210, 210, 210))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// A panel's legend, upper left.
fn legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> crate::Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(|e| crate::error::msg!("drawing the learning curve: {e}"))
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &Curve) -> crate::Result<()> {
    root.fill(&WHITE).map_err(drawing_error)?;
    let root = root
        .titled(&c.title, ("sans-serif", 22))
        .map_err(drawing_error)?;
    let (_, h) = root.dim_in_pixel();
    let (top, bottom) = root.split_vertically(h as i32 * 64 / 100);
    let x_max = c.records.last().map_or(1.0, |r| f64::from(r.episode + 1));
    draw_returns(&top, c, x_max)?;
    draw_demos(&bottom, c, x_max)
}

/// A panel of the picture.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The error of a drawing step of the picture.
fn drawing_error<E: std::error::Error + Send + Sync>(
    e: DrawingAreaErrorKind<E>,
) -> crate::LabError {
    crate::error::msg!("drawing the learning curve: {e}")
}

/// The x of an episode's record.
fn episode_x(r: &EpisodeRecord) -> f64 {
    f64::from(r.episode)
}

/// The top panel: returns, their moving average, greedy evaluations, the expert's return and the
/// shaping windows, over episodes `0..x_max`.
fn draw_returns<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: &Curve,
    x_max: f64,
) -> crate::Result<()> {
    let returns: Vec<f64> = c.records.iter().map(|r| r.ret).collect();
    let evals: Vec<(f64, f64)> = c
        .records
        .iter()
        .filter(|r| r.eval_return.is_finite())
        .map(|r| (episode_x(r), r.eval_return))
        .collect();
    let all = returns
        .iter()
        .copied()
        .chain(evals.iter().map(|e| e.1))
        .chain(c.expert.as_ref().map(|e| e.1));
    let (lo, hi) = padded(
        all.clone().fold(f64::INFINITY, f64::min),
        all.fold(f64::NEG_INFINITY, f64::max),
    );
    // Room above the data for the legend.
    let hi = hi + (hi - lo) * 0.35;

    let mut chart = panel(area, x_max, (lo, hi), "return")?;
    draw_shaping(&mut chart, c.records, x_max, (lo, hi))?;
    let points = c.records.iter().map(|r| (episode_x(r), r.ret));
    chart
        .draw_series(LineSeries::new(points, RETURN.mix(0.45).stroke_width(1)))
        .map_err(drawing_error)?
        .label(label("return of each episode"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], RETURN.mix(0.45)));
    let smooth = moving_average(&returns, SMOOTH);
    let points = c.records.iter().zip(smooth).map(|(r, m)| (episode_x(r), m));
    chart
        .draw_series(LineSeries::new(points, RETURN.stroke_width(3)))
        .map_err(drawing_error)?
        .label(label(&format!("{SMOOTH}-episode moving average")))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], RETURN.stroke_width(3)));
    if !evals.is_empty() {
        chart
            .draw_series(evals.iter().map(|&p| Circle::new(p, 4, EVAL.filled())))
            .map_err(drawing_error)?
            .label(label("greedy evaluation"))
            .legend(|(x, y)| Circle::new((x + 12, y), 4, EVAL.filled()));
    }
    if let Some((name, mean)) = &c.expert {
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, *mean), (x_max, *mean)],
                10,
                6,
                EXPERT.stroke_width(2),
            ))
            .map_err(drawing_error)?
            .label(label(&format!("expert {name}: {mean:.1} (measured)")))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], EXPERT.stroke_width(2)));
    }
    legend(&mut chart)
}

/// The shaping windows of `records`, shaded over the panel's y range `(lo, hi)`.
fn draw_shaping<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    records: &[EpisodeRecord],
    x_max: f64,
    (lo, hi): (f64, f64),
) -> crate::Result<()> {
    let windows = shaping_windows(records);
    if !windows.is_empty() {
        chart
            .draw_series(windows.iter().map(|&(a, b)| {
                Rectangle::new(
                    [
                        ((f64::from(a) - 0.5).max(0.0), lo),
                        ((f64::from(b) + 0.5).min(x_max), hi),
                    ],
                    SHADE.mix(0.15).filled(),
                )
            }))
            .map_err(drawing_error)?
            .label(label("shaping window (episodes with shaped rewards)"))
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 6), (x + 24, y + 6)], SHADE.mix(0.3).filled())
            });
    }
    Ok(())
}

/// The bottom panel: demonstrations used and the budget B, over episodes `0..x_max`.
fn draw_demos<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: &Curve,
    x_max: f64,
) -> crate::Result<()> {
    let most = c.records.iter().map(|r| r.demos_used).max().unwrap_or(0);
    // Room above the budget's line for the legend.
    let y_max = (f64::from(most.max(c.budget)) * 1.5).max(1.0);
    let mut chart = panel(area, x_max, (0.0, y_max), "demonstrations")?;
    let points = c
        .records
        .iter()
        .map(|r| (episode_x(r), f64::from(r.demos_used)));
    chart
        .draw_series(LineSeries::new(points, DEMOS.stroke_width(2)))
        .map_err(drawing_error)?
        .label(label("demonstrations used"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], DEMOS.stroke_width(2)));
    let b = f64::from(c.budget);
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, b), (x_max, b)],
            10,
            6,
            GREY.stroke_width(2),
        ))
        .map_err(drawing_error)?
        .label(label(&format!("budget B = {}", c.budget)))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], GREY.stroke_width(2)));
    legend(&mut chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_picture_has_its_title_panels_and_legend() {
        let records: Vec<EpisodeRecord> = (0..30u32)
            .map(|i| EpisodeRecord {
                episode: i,
                ret: f64::from(i * 3),
                demos_used: i.min(12),
                shaped_steps: u32::from((5..15).contains(&i)),
                eval_return: if i % 10 == 9 { 500.0 } else { f64::NAN },
                ..EpisodeRecord::default()
            })
            .collect();
        let curve = Curve {
            title: "cartpole, bdqn (seed 0): my-run".into(),
            records: &records,
            expert: Some(("cartpole-1000".into(), 1000.0)),
            budget: 20,
        };
        let svg = svg(&curve).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        for text in [
            "cartpole, bdqn (seed 0): my-run",
            "return of each episode",
            "20-episode moving average",
            "greedy evaluation",
            "expert cartpole-1000: 1000.0",
            "shaping window",
            "demonstrations used",
            "budget B = 20",
        ] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert_eq!(shaping_windows(&records), vec![(5, 14)]);
    }

    #[test]
    fn windows_and_averages() {
        let r = |episode, shaped_steps| EpisodeRecord {
            episode,
            shaped_steps,
            ..EpisodeRecord::default()
        };
        let rs = [r(0, 1), r(1, 2), r(2, 0), r(3, 1), r(5, 1)];
        assert_eq!(shaping_windows(&rs), vec![(0, 1), (3, 3), (5, 5)]);
        assert_eq!(
            moving_average(&[1.0, 3.0, 5.0, 7.0], 2),
            vec![1.0, 2.0, 4.0, 6.0]
        );
    }
}
