//! How the time to a threshold grows with a task's size: from the `runs.csv` of one sweep per
//! size (DeepSea N = 10, 20, ..., say), per method the share of runs whose greedy evaluation
//! reached the threshold and the Kaplan-Meier medians of the demonstrations and the episodes until
//! it did, each with a 95% bootstrap interval over the seeds. Writes `scaling.csv`, `scaling.md`
//! and one plot per measure (`scaling-demos`, `scaling-episodes`, SVG and PNG).

use std::path::{Path, PathBuf};

use super::experiment::LegendPosition;
use super::plot::{self, Plot, Series};
use super::runs::km_median;
use super::stats::bootstrap::{Estimate, Interval, Resamples};
use crate::error::{msg, usage, Context as _};

/// `alfd scaling`: the sweeps, one per size, and where to write.
#[derive(Debug, Clone, clap::Args)]
pub struct ScalingArgs {
    /// One sweep per size, as SIZE=DIR: DIR holds that sweep's `runs.csv` (written by every
    /// training sweep whose experiment has an `eval_threshold`).
    #[arg(long = "sweep", value_name = "SIZE=DIR", required = true, num_args = 1..)]
    pub sweeps: Vec<String>,
    /// The plots' title.
    #[arg(long, default_value = "Time to the threshold against the size")]
    pub title: String,
    /// What the size is, for the plots' x axis.
    #[arg(long, default_value = "size")]
    pub size: String,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// One run's time to the threshold, as `runs.csv` gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct Time {
    pub method: String,
    pub seed: u64,
    pub reached: bool,
    /// Episodes until greedy evaluation reached the threshold (+∞ when it never did: every run of
    /// a sweep ends at the same episode, after any other run's reach).
    pub episodes: f64,
    /// Demonstrations used by then (when never reached: all the run used, where it is censored).
    pub demos: f64,
}

/// A method at one size: how many runs, how many reached, and the two medians.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    pub method: String,
    pub size: f64,
    pub runs: usize,
    pub reached: usize,
    /// Kaplan-Meier medians (+∞: fewer than half reach) with their 95% bootstrap intervals.
    pub demos: Estimate,
    pub episodes: Estimate,
}

/// Reads the runs of a `runs.csv` (its columns found by name in the header).
pub fn parse_runs(text: &str) -> crate::Result<Vec<Time>> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| msg!("runs.csv has no column `{name}`"))
    };
    let (m, s, r) = (col("method")?, col("seed")?, col("reached")?);
    let (e, d, all) = (
        col("episodes_to_threshold")?,
        col("demos_to_threshold")?,
        col("demos")?,
    );
    let mut out = Vec::new();
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let f: Vec<&str> = line.split(',').collect();
        let bad = |what: &str| msg!("runs.csv line {}: {what}: {line}", i + 2);
        let get = |k: usize| f.get(k).copied().ok_or_else(|| bad("too few fields"));
        let num =
            |k: usize| -> crate::Result<f64> { get(k)?.parse().map_err(|_| bad("not a number")) };
        let reached = match get(r)? {
            "true" => true,
            "false" => false,
            _ => {
                return Err(bad(
                    "`reached` is neither true nor false (no eval_threshold?)",
                ))
            }
        };
        out.push(Time {
            method: get(m)?.to_owned(),
            seed: get(s)?
                .parse()
                .map_err(|_| bad("the seed is not a number"))?,
            reached,
            episodes: if reached { num(e)? } else { f64::INFINITY },
            demos: if reached { num(d)? } else { num(all)? },
        });
    }
    Ok(out)
}

/// The cell of `method` at `size` from the runs of that size's sweep (`None`: no run of it).
pub fn cell(times: &[Time], method: &str, size: f64) -> Option<Cell> {
    let runs: Vec<&Time> = times.iter().filter(|t| t.method == method).collect();
    if runs.is_empty() {
        return None;
    }
    let median = |f: fn(&Time) -> f64, stream: &str| {
        let resamples = Resamples::new(runs.len(), &format!("scaling-{method}-{size}-{stream}"));
        let (value, ci) = resamples.time(|draw| {
            let pairs: Vec<(f64, bool)> = draw
                .iter()
                .map(|&i| (f(runs[i]), runs[i].reached))
                .collect();
            km_median(&pairs)
        });
        let never = f64::INFINITY;
        Estimate {
            value: value.unwrap_or(never),
            ci: Interval {
                low: ci.low.unwrap_or(never),
                high: ci.high.unwrap_or(never),
            },
        }
    };
    Some(Cell {
        method: method.to_owned(),
        size,
        runs: runs.len(),
        reached: runs.iter().filter(|t| t.reached).count(),
        demos: median(|t| t.demos, "demos"),
        episodes: median(|t| t.episodes, "episodes"),
    })
}

/// Every method's cells, methods in their order of first appearance.
pub fn cells(sizes: &[(f64, Vec<Time>)]) -> Vec<Cell> {
    let mut methods: Vec<&str> = Vec::new();
    for t in sizes.iter().flat_map(|(_, ts)| ts) {
        if !methods.contains(&t.method.as_str()) {
            methods.push(&t.method);
        }
    }
    methods
        .iter()
        .flat_map(|m| sizes.iter().filter_map(|(n, ts)| cell(ts, m, *n)))
        .collect()
}

/// A method as tables and plots show it: gate `oracle` marked as the ceiling it is (it consults
/// the expert at every step), every other by its name.
fn display(method: &str) -> String {
    if method == "oracle" {
        "oracle (ceiling)".to_owned()
    } else {
        method.to_owned()
    }
}

/// A number, or "not reached" for +∞.
fn shown(v: f64) -> String {
    if v.is_finite() {
        format!("{v}")
    } else {
        "not reached".to_owned()
    }
}

pub fn csv(cells: &[Cell]) -> String {
    let mut out = "method,size,runs,reached,median_demos,demos_low,demos_high,\
                   median_episodes,episodes_low,episodes_high\n"
        .to_owned();
    let v = |x: f64| {
        if x.is_finite() {
            format!("{x}")
        } else {
            String::new()
        }
    };
    for c in cells {
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{}\n",
            c.method,
            c.size,
            c.runs,
            c.reached,
            v(c.demos.value),
            v(c.demos.ci.low),
            v(c.demos.ci.high),
            v(c.episodes.value),
            v(c.episodes.ci.low),
            v(c.episodes.ci.high)
        ));
    }
    out
}

/// Three tables, one row per method and one column per size: the runs that reached the
/// threshold, the median demonstrations and the median episodes until they did.
pub fn markdown(cells: &[Cell], size: &str) -> String {
    let mut sizes: Vec<f64> = cells.iter().map(|c| c.size).collect();
    sizes.sort_by(f64::total_cmp);
    sizes.dedup();
    let mut methods: Vec<&str> = Vec::new();
    for c in cells {
        if !methods.contains(&c.method.as_str()) {
            methods.push(&c.method);
        }
    }
    let est = |e: &Estimate| {
        if [e.value, e.ci.low, e.ci.high]
            .iter()
            .all(|v| v.is_infinite())
        {
            return "not reached".to_owned();
        }
        format!(
            "{} [{}, {}]",
            shown(e.value),
            shown(e.ci.low),
            shown(e.ci.high)
        )
    };
    let table = |title: &str, show: &dyn Fn(&Cell) -> String| {
        let mut t = format!("\n{title}\n\n| method |");
        for n in &sizes {
            t.push_str(&format!(" {size} = {n} |"));
        }
        t.push_str(&format!("\n|---|{}\n", "---:|".repeat(sizes.len())));
        for m in &methods {
            t.push_str(&format!("| {} |", display(m)));
            for n in &sizes {
                let c = cells.iter().find(|c| c.method == *m && c.size == *n);
                t.push_str(&format!(" {} |", c.map_or("–".to_owned(), show)));
            }
            t.push('\n');
        }
        t
    };
    let mut md = "Until greedy evaluation first reaches the threshold: the runs that reached it, \
                  and the Kaplan-Meier medians of the demonstrations and of the episodes with \
                  95% bootstrap intervals over the seeds (\"not reached\": fewer than half of the \
                  runs, or of a resample's, reach it; a run that never reaches it counts as still \
                  waiting at its end). Empty fields of `scaling.csv` are \"not reached\".\n"
        .to_owned();
    md += &table("Runs that reached it:", &|c| {
        format!("{} of {}", c.reached, c.runs)
    });
    md += &table("Median demonstrations:", &|c| est(&c.demos));
    md += &table("Median episodes:", &|c| est(&c.episodes));
    md
}

/// What a plot shows of a cell.
type Measure = fn(&Cell) -> &Estimate;

/// One line per method of `measure` against the size, at the sizes where its median is reached.
fn series(cells: &[Cell], measure: Measure) -> Vec<Series> {
    let mut out: Vec<Series> = Vec::new();
    for c in cells {
        let e = measure(c);
        if !e.value.is_finite() {
            continue;
        }
        let label = display(&c.method);
        let s = match out.iter_mut().find(|s| s.label == label) {
            Some(s) => s,
            None => {
                out.push(Series {
                    label,
                    x: vec![],
                    y: vec![],
                    lo: vec![],
                    hi: vec![],
                });
                out.last_mut().expect("just pushed")
            }
        };
        s.x.push(c.size);
        s.y.push(e.value);
        s.lo.push(e.ci.low);
        s.hi.push(e.ci.high);
    }
    out
}

/// `SIZE=DIR` as a size and a directory.
fn parse_sweep(arg: &str) -> crate::Result<(f64, PathBuf)> {
    let (n, dir) = arg.split_once('=').ok_or_else(|| {
        usage(format!(
            "--sweep {arg}: expected SIZE=DIR, such as 10=results/deepsea-gates/n10"
        ))
    })?;
    let n: f64 = n
        .parse()
        .map_err(|_| usage(format!("--sweep {arg}: the size `{n}` is not a number")))?;
    Ok((n, PathBuf::from(dir)))
}

/// Reads the sweeps, writes the table, the CSV and the plots; returns the table.
pub fn run(args: &ScalingArgs) -> crate::Result<String> {
    let mut sizes = Vec::new();
    for arg in &args.sweeps {
        let (n, dir) = parse_sweep(arg)?;
        let path = dir.join("runs.csv");
        let text = std::fs::read_to_string(&path).map_err(|e| {
            usage(format!(
                "--sweep {arg}: cannot read {}: {e}",
                path.display()
            ))
        })?;
        let times = parse_runs(&text)
            .map_err(|e| usage(format!("--sweep {arg}: {}: {e}", path.display())))?;
        sizes.push((n, times));
    }
    let cells = cells(&sizes);
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    crate::output::write(out, "scaling.csv", csv(&cells).as_bytes())?;
    let md = markdown(&cells, &args.size);
    crate::output::write(out, "scaling.md", md.as_bytes())?;
    let measures: [(&str, &str, Measure); 2] = [
        (
            "demos",
            "demonstrations until the threshold (median)",
            |c| &c.demos,
        ),
        ("episodes", "episodes until the threshold (median)", |c| {
            &c.episodes
        }),
    ];
    for (name, y_desc, measure) in measures {
        let lines = series(&cells, measure);
        let svg = plot::svg(&Plot {
            title: &args.title,
            x_desc: &args.size,
            y_desc,
            log_y: false,
            y_range: None,
            legend: LegendPosition::UpperLeft,
            band_desc: Some("band: 95% bootstrap CI"),
            series: &lines,
        })?;
        write_plot(out, &format!("scaling-{name}"), &svg)?;
    }
    Ok(md)
}

fn write_plot(dir: &Path, stem: &str, svg: &str) -> crate::Result<()> {
    crate::output::write(dir, &format!("{stem}.svg"), svg.as_bytes())?;
    if let Some(png) = crate::output::png_from_svg(svg)? {
        crate::output::write(dir, &format!("{stem}.png"), &png)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "method,seed,budget,demos,final_eval,eval_auc,evaluations,reached,\
                       episodes_to_threshold,steps_to_threshold,demos_to_threshold\n\
                       a,0,20,20,0.99,0.5,100,true,30,300,4\n\
                       a,1,20,18,0,0.1,100,false,,,\n\
                       a,2,20,20,0.99,0.5,100,true,50,500,6\n\
                       b,0,20,20,0,0.0,100,false,,,\n";

    #[test]
    fn runs_csv_reads_back_with_unreached_runs_censored_at_their_end() {
        let t = parse_runs(CSV).unwrap();
        assert_eq!(t.len(), 4);
        assert_eq!((t[0].episodes, t[0].demos, t[0].reached), (30.0, 4.0, true));
        // Not reached: censored at all the demonstrations it used, at +∞ episodes.
        assert_eq!(
            (t[1].episodes, t[1].demos, t[1].reached),
            (f64::INFINITY, 18.0, false)
        );
        let no_threshold = CSV.replace("true", "").replace("false", "");
        let e = parse_runs(&no_threshold).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("reached"), "{e}");
        let e = parse_runs("method,seed\n").unwrap_err().to_string();
        assert!(e.contains("`reached`"), "{e}");
    }

    #[test]
    fn a_cell_has_the_kaplan_meier_medians_and_none_when_fewer_than_half_reach() {
        let t = parse_runs(CSV).unwrap();
        // a: episodes 30, 50 reached and one censored at +∞: S(30) = 2/3, S(50) = 1/3, median 50.
        // Demos 4 and 6 reached, 18 censored: S(4) = 2/3, S(6) = 1/3, median 6.
        let a = cell(&t, "a", 10.0).unwrap();
        assert_eq!((a.runs, a.reached), (3, 2));
        assert_eq!((a.episodes.value, a.demos.value), (50.0, 6.0));
        assert!(a.demos.ci.low >= 4.0, "{:?}", a.demos);
        // A resample of only the censored run never reaches: the upper bound is "not reached".
        assert!(a.episodes.ci.high.is_infinite(), "{:?}", a.episodes);
        let b = cell(&t, "b", 10.0).unwrap();
        assert_eq!(b.reached, 0);
        assert!(b.demos.value.is_infinite());
        assert!(cell(&t, "c", 10.0).is_none());
        let md = markdown(&[a, b], "N");
        let md = md.replace('\n', "@");
        assert!(
            md.contains("@| method | N = 10 |@|---|---:|@| a | 2 of 3 |@| b | 0 of 1 |"),
            "{md}"
        );
        assert!(md.contains("@| a | 6 [4, "), "{md}");
        assert!(md.contains("@| b | not reached |@"), "{md}");
    }

    #[test]
    fn the_lines_leave_out_sizes_where_the_median_is_not_reached() {
        let t = parse_runs(CSV).unwrap();
        let cells = cells(&[(10.0, t.clone()), (20.0, t)]);
        assert_eq!(cells.len(), 4);
        assert_eq!(cells[0].method, "a");
        let lines = series(&cells, |c| &c.demos);
        assert_eq!(lines.len(), 1, "b never reaches");
        assert_eq!(
            (lines[0].x.clone(), lines[0].y.clone()),
            (vec![10.0, 20.0], vec![6.0, 6.0])
        );
        let csv = csv(&cells);
        assert!(csv.lines().any(|l| l == "b,10,1,0,,,,,,"), "{csv}");
    }

    #[test]
    fn a_sweep_argument_is_a_size_and_a_directory() {
        assert_eq!(
            parse_sweep("10=r/n10").unwrap(),
            (10.0, PathBuf::from("r/n10"))
        );
        assert!(parse_sweep("r/n10")
            .unwrap_err()
            .to_string()
            .contains("SIZE=DIR"));
        assert!(parse_sweep("ten=r")
            .unwrap_err()
            .to_string()
            .contains("`ten`"));
    }
}
