//! `alfd demo-model`: fits a demonstration model (KRR or SVM) on demonstrations read from a file
//! and prints its outputs for query states, to evaluate the model on its own as the paper does.
//!
//! The demos file holds JSON lines `{"state":[…],"action":a}` with an optional `"weight"` (≥ 0,
//! default 1; KRR weighs each demonstration by it, as a run does, so a run's `demos.jsonl` gives
//! the run's model), the query file JSON lines `{"state":[…]}` (other fields are ignored, blank
//! lines skipped). One JSON line
//! `{"raw":[…],"probs":[…]}` is printed per query.

use std::io::Write;
use std::path::{Path, PathBuf};

use alfd_common::demo_model::nystrom::MAX_APPROX_DEMOS;
use alfd_common::demo_model::{DemoModel, DemoModelError, DemoModelKind, MAX_ACTIONS, MAX_DEMOS};
use anyhow::Context;
use serde::{Deserialize, Serialize};

pub use alfd_harness::BadInput;

/// Which demonstration model to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum KindArg {
    /// Kernel Ridge Regression on one-hot actions (RBF gamma 0.1, alpha 0.1).
    Krr,
    /// Kernel SVM (C = 10, RBF gamma 0.1) with Platt scaling; two actions only.
    Svm,
    /// KRR on the first 512 demonstrations as Nyström landmarks: up to 1,000,000 demonstrations.
    Nystrom,
}

impl From<KindArg> for DemoModelKind {
    fn from(k: KindArg) -> Self {
        match k {
            KindArg::Krr => DemoModelKind::Krr,
            KindArg::Svm => DemoModelKind::Svm,
            KindArg::Nystrom => DemoModelKind::Nystrom,
        }
    }
}

/// Arguments of `alfd demo-model`.
#[derive(Debug, Clone, clap::Args)]
pub struct DemoModelArgs {
    /// The demonstration model to fit.
    #[arg(long, value_enum)]
    pub kind: KindArg,
    /// JSON lines of demonstrations, `{"state":[…],"action":a}`, each with an optional
    /// `"weight"` ≥ 0 (default 1; KRR weighs by it as a run does, SVM and Nyström ignore it).
    #[arg(long)]
    pub demos: PathBuf,
    /// JSON lines of query states, `{"state":[…]}`.
    #[arg(long)]
    pub query: PathBuf,
    /// Number of actions (default: the largest demonstrated action + 1, at least 2), at most 1024.
    #[arg(long)]
    pub actions: Option<usize>,
    /// Threads the fit shares its independent work among (default: every core this process may
    /// use). The model is the same, bit for bit, on any number.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=1024))]
    pub threads: Option<u16>,
}

#[derive(Deserialize)]
struct DemoLine {
    state: Vec<f64>,
    action: usize,
    #[serde(default = "one")]
    weight: f64,
}

fn one() -> f64 {
    1.0
}

#[derive(Deserialize)]
struct QueryLine {
    state: Vec<f64>,
}

#[derive(Serialize)]
struct OutputLine<'a> {
    raw: &'a [f64],
    probs: &'a [f64],
}

/// Demonstrations parsed from a demos file.
#[derive(Debug, Clone, PartialEq)]
pub struct Demos {
    pub states: Vec<Vec<f64>>,
    pub actions: Vec<usize>,
    /// Each demonstration's weight in a KRR model (1 where the line gives none).
    pub weights: Vec<f64>,
    /// The 1-based line number of each demonstration in its file.
    pub lines: Vec<usize>,
}

/// Parses JSON lines into `T`, checking that every `state` (got by `state`) is non-empty, finite
/// and of the same length (`dim`, if given, else the first line's). Errors name `file` and the
/// 1-based line number.
fn parse_lines<T: for<'de> Deserialize<'de>>(
    text: &str,
    file: &str,
    mut dim: Option<usize>,
    state: impl Fn(&T) -> &[f64],
) -> Result<Vec<(usize, T)>, BadInput> {
    let mut out = Vec::new();
    let mut first_line = 0;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let item: T = serde_json::from_str(line).map_err(|e| {
            // serde_json's message ends with its own "at line 1 column N": keep the column only.
            let msg = e.to_string();
            let msg = msg.split(" at line ").next().unwrap_or_default();
            BadInput(format!(
                "{file}:{line_no}: malformed line (column {}): {msg}",
                e.column()
            ))
        })?;
        let s = state(&item);
        if s.is_empty() {
            return Err(BadInput(format!("{file}:{line_no}: the state is empty")));
        }
        match dim {
            None => {
                dim = Some(s.len());
                first_line = line_no;
            }
            Some(d) if d != s.len() => {
                let reference = if first_line > 0 {
                    format!("as line {first_line}")
                } else {
                    "as the demonstrations".to_string()
                };
                return Err(BadInput(format!(
                    "{file}:{line_no}: the state has {} components, expected {d} ({reference})",
                    s.len()
                )));
            }
            Some(_) => {}
        }
        if let Some(c) = s.iter().position(|v| !v.is_finite()) {
            return Err(BadInput(format!(
                "{file}:{line_no}: state component {c} is not finite"
            )));
        }
        out.push((line_no, item));
    }
    Ok(out)
}

/// Parses a demos file's text (`file` names it in errors) for a model of `kind`: at most
/// [`MAX_DEMOS`] demonstrations ([`MAX_APPROX_DEMOS`] for the Nyström model).
pub fn parse_demos(text: &str, file: &str, kind: DemoModelKind) -> Result<Demos, BadInput> {
    let items = parse_lines::<DemoLine>(text, file, None, |d| &d.state)?;
    if items.is_empty() {
        return Err(BadInput(format!("{file}: no demonstrations")));
    }
    if kind == DemoModelKind::Nystrom && items.len() > MAX_APPROX_DEMOS {
        return Err(BadInput(format!(
            "{file}: {} demonstrations, but the nystrom model is fitted on at most \
             {MAX_APPROX_DEMOS}",
            items.len()
        )));
    }
    if kind != DemoModelKind::Nystrom && items.len() > MAX_DEMOS {
        return Err(BadInput(format!(
            "{file}: {} demonstrations, but a demonstration model is fitted on at most {MAX_DEMOS} \
             (its kernel matrix holds n × n numbers; `--kind nystrom` takes more)",
            items.len()
        )));
    }
    let mut demos = Demos {
        states: Vec::new(),
        actions: Vec::new(),
        weights: Vec::new(),
        lines: Vec::new(),
    };
    for (line, d) in items {
        if !(d.weight.is_finite() && d.weight >= 0.0) {
            return Err(BadInput(format!(
                "{file}:{line}: weight {} is not a finite number ≥ 0",
                d.weight
            )));
        }
        demos.states.push(d.state);
        demos.actions.push(d.action);
        demos.weights.push(d.weight);
        demos.lines.push(line);
    }
    Ok(demos)
}

/// Parses a query file's text; every state must have `dim` components.
pub fn parse_queries(text: &str, file: &str, dim: usize) -> Result<Vec<Vec<f64>>, BadInput> {
    let items = parse_lines::<QueryLine>(text, file, Some(dim), |q| &q.state)?;
    Ok(items.into_iter().map(|(_, q)| q.state).collect())
}

/// The number of actions: `requested` if given (every action must be below it), else the largest
/// action + 1, at least 2; at most [`MAX_ACTIONS`] either way.
pub fn num_actions(demos: &Demos, requested: Option<usize>, file: &str) -> Result<usize, BadInput> {
    let Some(n) = requested else {
        if let Some(i) = demos.actions.iter().position(|&a| a >= MAX_ACTIONS) {
            return Err(BadInput(format!(
                "{file}:{}: action {} is too large: a demonstration model handles at most \
                 {MAX_ACTIONS} actions (0 to {})",
                demos.lines[i],
                demos.actions[i],
                MAX_ACTIONS - 1
            )));
        }
        return Ok(demos.actions.iter().max().map_or(2, |&m| (m + 1).max(2)));
    };
    if n == 0 {
        return Err(BadInput("--actions must be at least 1".to_string()));
    }
    if n > MAX_ACTIONS {
        return Err(BadInput(format!(
            "--actions {n}: a demonstration model handles at most {MAX_ACTIONS} actions"
        )));
    }
    if let Some(i) = demos.actions.iter().position(|&a| a >= n) {
        return Err(BadInput(format!(
            "{file}:{}: action {} is outside the action space {{0..{n}}} set by --actions",
            demos.lines[i], demos.actions[i]
        )));
    }
    Ok(n)
}

fn read(path: &Path, what: &str) -> Result<String, BadInput> {
    std::fs::read_to_string(path).map_err(|e| {
        BadInput(format!(
            "cannot read the {what} file {}: {e}",
            path.display()
        ))
    })
}

/// Runs `alfd demo-model`.
pub fn run(args: DemoModelArgs) -> anyhow::Result<()> {
    let demos_name = args.demos.display().to_string();
    let query_name = args.query.display().to_string();
    let kind = DemoModelKind::from(args.kind);
    let demos = parse_demos(&read(&args.demos, "demos")?, &demos_name, kind)?;
    let num_actions = num_actions(&demos, args.actions, &demos_name)?;
    let dim = demos.states[0].len();
    let queries = parse_queries(&read(&args.query, "query")?, &query_name, dim)?;
    tracing::info!(
        kind = ?args.kind,
        demos = demos.actions.len(),
        num_actions,
        queries = queries.len(),
        "fitting the demonstration model"
    );

    let lanes = args
        .threads
        .map_or_else(alfd_harness::Threads::machine, |t| {
            alfd_harness::Threads::new(usize::from(t))
        });
    let columns = (&demos.states[..], &demos.actions[..], &demos.weights[..]);
    let model = match DemoModel::fit_weighted_on(kind, columns, num_actions, &lanes) {
        Ok(m) => m,
        Err(
            e @ (DemoModelError::Unsupported(_)
            | DemoModelError::TooManyActions(_)
            | DemoModelError::TooManyDemos(_)
            | DemoModelError::TooManyApproxDemos(_)),
        ) => return Err(BadInput(format!("{kind} on {demos_name}: {e}")).into()),
        Err(e) => return Err(e).with_context(|| format!("fitting {kind} on {demos_name}")),
    };

    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for s in &queries {
        let line = OutputLine {
            raw: &model.raw(s),
            probs: &model.probs(s),
        };
        serde_json::to_writer(&mut out, &line).context("writing the output")?;
        out.write_all(b"\n").context("writing the output")?;
    }
    out.flush().context("writing the output")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demos_parse_and_skip_blank_lines() {
        let text =
            "{\"state\":[0.5,1],\"action\":1}\n\n{\"state\":[2,3],\"action\":0,\"reward\":1}\n";
        let d = parse_demos(text, "d.jsonl", DemoModelKind::Krr).unwrap();
        assert_eq!(d.states, vec![vec![0.5, 1.0], vec![2.0, 3.0]]);
        assert_eq!(d.actions, vec![1, 0]);
        assert_eq!(d.lines, vec![1, 3]);
        assert_eq!(num_actions(&d, None, "d.jsonl").unwrap(), 2);
    }

    #[test]
    fn malformed_lines_are_named() {
        let text = "{\"state\":[0,1],\"action\":1}\n{\"state\":[0,1],\"action\":-1}\n";
        let e = parse_demos(text, "d.jsonl", DemoModelKind::Krr).unwrap_err();
        assert!(e.0.starts_with("d.jsonl:2: malformed line"), "{e}");

        let text = "{\"state\":[0,1],\"action\":1}\n\n{\"state\":[0,1]\n";
        let e = parse_demos(text, "d.jsonl", DemoModelKind::Krr).unwrap_err();
        assert!(e.0.starts_with("d.jsonl:3: malformed line"), "{e}");

        let text = "{\"state\":[0,1],\"action\":1}\n{\"action\":0}\n";
        let e = parse_demos(text, "d.jsonl", DemoModelKind::Krr).unwrap_err();
        assert!(
            e.0.starts_with("d.jsonl:2:") && e.0.contains("state"),
            "{e}"
        );
    }

    #[test]
    fn inconsistent_dimensions_are_named() {
        let text = "{\"state\":[0,1],\"action\":1}\n{\"state\":[0,1,2],\"action\":0}\n";
        let e = parse_demos(text, "d.jsonl", DemoModelKind::Krr).unwrap_err();
        assert_eq!(
            e.0,
            "d.jsonl:2: the state has 3 components, expected 2 (as line 1)"
        );

        let e = parse_queries("{\"state\":[1,2]}\n{\"state\":[1]}\n", "q.jsonl", 2).unwrap_err();
        assert_eq!(
            e.0,
            "q.jsonl:2: the state has 1 components, expected 2 (as the demonstrations)"
        );

        let e = parse_queries("{\"state\":[]}\n", "q.jsonl", 2).unwrap_err();
        assert_eq!(e.0, "q.jsonl:1: the state is empty");
    }

    #[test]
    fn empty_demos_and_bad_action_counts_are_refused() {
        assert_eq!(
            parse_demos("\n\n", "d.jsonl", DemoModelKind::Krr)
                .unwrap_err()
                .0,
            "d.jsonl: no demonstrations"
        );
        let d = parse_demos(
            "{\"state\":[0],\"action\":0}\n{\"state\":[1],\"action\":3}\n",
            "d",
            DemoModelKind::Krr,
        )
        .unwrap();
        assert_eq!(num_actions(&d, None, "d").unwrap(), 4);
        assert_eq!(num_actions(&d, Some(5), "d").unwrap(), 5);
        let e = num_actions(&d, Some(3), "d").unwrap_err();
        assert!(e.0.starts_with("d:2: action 3"), "{e}");
        let d = parse_demos("{\"state\":[0],\"action\":0}\n", "d", DemoModelKind::Krr).unwrap();
        assert_eq!(num_actions(&d, None, "d").unwrap(), 2);
    }

    #[test]
    fn sizes_beyond_the_limits_are_refused_naming_the_argument_or_line() {
        let d = parse_demos("{\"state\":[0],\"action\":1}\n", "d", DemoModelKind::Krr).unwrap();
        assert_eq!(
            num_actions(&d, Some(100_000_000_000), "d").unwrap_err().0,
            "--actions 100000000000: a demonstration model handles at most 1024 actions"
        );
        assert_eq!(
            num_actions(&d, Some(MAX_ACTIONS), "d").unwrap(),
            MAX_ACTIONS
        );
        // An action in the file sets the number of actions when --actions is absent.
        let d = parse_demos(
            "{\"state\":[0],\"action\":0}\n{\"state\":[1],\"action\":100000000000}\n",
            "d",
            DemoModelKind::Krr,
        )
        .unwrap();
        assert_eq!(
            num_actions(&d, None, "d").unwrap_err().0,
            "d:2: action 100000000000 is too large: a demonstration model handles at most 1024 actions (0 to 1023)"
        );
        let many = "{\"state\":[0],\"action\":0}\n".repeat(MAX_DEMOS + 1);
        assert_eq!(
            parse_demos(&many, "d", DemoModelKind::Svm).unwrap_err().0,
            "d: 10001 demonstrations, but a demonstration model is fitted on at most 10000 (its kernel matrix holds n × n numbers; `--kind nystrom` takes more)"
        );
        assert_eq!(
            parse_demos(&many, "d", DemoModelKind::Nystrom)
                .unwrap()
                .actions
                .len(),
            MAX_DEMOS + 1
        );
    }

    #[test]
    fn missing_files_are_usage_errors() {
        let args = DemoModelArgs {
            kind: KindArg::Krr,
            demos: PathBuf::from("/nonexistent/alfd-demos.jsonl"),
            query: PathBuf::from("/nonexistent/alfd-query.jsonl"),
            actions: None,
            threads: None,
        };
        let e = run(args).unwrap_err();
        let usage = e.downcast_ref::<BadInput>().expect("a BadInput");
        assert!(
            usage.0.contains("demos file /nonexistent/alfd-demos.jsonl"),
            "{usage}"
        );
    }
}
