//! `alfd env`: look at the environments from the command line — roll CartPole out from a given
//! state (to check our dynamics against another implementation) and show a CliffWalk map.
//!
//! Bad input (a malformed state or action list, an unknown env name, an unreadable or malformed
//! map, an out-of-range parameter) is returned as a [`UsageError`], which `main` maps to exit
//! code 2 (see [`crate::usage::exit_code`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use alfd_common::env::cliffwalk::{
    self, CliffMap, CliffWalk, DEFAULT_GAMMA, DEFAULT_MAX_EPISODE_STEPS, DEFAULT_P_SUCCESS,
};
use alfd_common::env::{cartpole, CartPole, Env};
use anyhow::Context;

#[cfg(test)]
use crate::usage::is_usage_error;
use crate::usage::usage;
pub use crate::usage::UsageError;

/// Arguments of `alfd env`.
#[derive(Debug, clap::Args)]
pub struct EnvArgs {
    #[command(subcommand)]
    pub command: EnvCommand,
}

/// The subcommands of `alfd env`.
#[derive(Debug, clap::Subcommand)]
pub enum EnvCommand {
    /// Step CartPole from a given state through a list of actions, printing one JSON object per
    /// step: {"state":[x,x_dot,theta,theta_dot],"reward":1.0,"terminated":false,"truncated":false}.
    Rollout(RolloutArgs),
    /// Print a CliffWalk map as text, then its size and the optimal value of S.
    Show(ShowArgs),
}

/// Arguments of `alfd env rollout`.
#[derive(Debug, clap::Args)]
pub struct RolloutArgs {
    /// Environment name; only `cartpole` can be rolled out from a given state.
    #[arg(long)]
    pub env: String,
    /// The float64 state the episode begins from: 4 comma-separated numbers.
    #[arg(long, value_name = "X,XDOT,THETA,THETADOT", allow_hyphen_values = true)]
    pub initial_state: String,
    /// Comma-separated actions, each 0 (push left) or 1 (push right). Actions left over when the
    /// episode ends are ignored, with a warning.
    #[arg(long, value_name = "A,A,...")]
    pub actions: String,
    /// Step limit of the episode (reported as `truncated`).
    #[arg(long, default_value_t = cartpole::DEFAULT_MAX_EPISODE_STEPS)]
    pub max_steps: usize,
}

/// Arguments of `alfd env show`.
#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    /// Environment name; only `cliffwalk` has a map.
    #[arg(long)]
    pub env: String,
    /// A map file of `S`, `G`, `X`, `.` (one row per line); the built-in 15×15 map if absent.
    #[arg(long, value_name = "FILE")]
    pub map: Option<PathBuf>,
    /// Probability that the chosen move happens, in (0, 1], for the value shown.
    #[arg(long, default_value_t = DEFAULT_P_SUCCESS)]
    pub p_success: f64,
    /// Discount factor, in [0, 1), for the value shown.
    #[arg(long, default_value_t = DEFAULT_GAMMA)]
    pub gamma: f64,
}

/// Runs `alfd env ...`, printing to stdout (warnings to stderr).
pub fn run(args: EnvArgs) -> anyhow::Result<()> {
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let stderr = std::io::stderr();
    let mut err = stderr.lock();
    match args.command {
        EnvCommand::Rollout(a) => rollout(&a, &mut out, &mut err)?,
        EnvCommand::Show(a) => show(&a, &mut out)?,
    }
    out.flush().context("writing to stdout")?;
    Ok(())
}

const KNOWN_ENVS: &str = "cartpole, cliffwalk";

/// Refuses names that are not environments, and environments the subcommand does not support.
fn check_env(name: &str, supported: &str, subcommand: &str) -> anyhow::Result<()> {
    if name == supported {
        Ok(())
    } else if KNOWN_ENVS.split(", ").any(|known| known == name) {
        Err(usage(format!(
            "--env {name}: `alfd env {subcommand}` supports only `{supported}`"
        )))
    } else {
        Err(usage(format!(
            "--env: unknown environment `{name}` (known: {KNOWN_ENVS})"
        )))
    }
}

/// Parses `--initial-state`: exactly 4 finite comma-separated numbers.
pub fn parse_state(text: &str) -> Result<[f64; 4], UsageError> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != 4 {
        return Err(UsageError(format!(
            "--initial-state: expected 4 comma-separated numbers X,XDOT,THETA,THETADOT, got {} value(s) in {text:?}",
            fields.len()
        )));
    }
    let mut state = [0.0; 4];
    for (i, (slot, field)) in state.iter_mut().zip(&fields).enumerate() {
        let value: f64 = field.parse().map_err(|_| {
            UsageError(format!(
                "--initial-state: value {} ({field:?}) is not a number",
                i + 1
            ))
        })?;
        if !value.is_finite() {
            return Err(UsageError(format!(
                "--initial-state: value {} ({field:?}) is not finite",
                i + 1
            )));
        }
        *slot = value;
    }
    Ok(state)
}

/// Parses `--actions`: a non-empty comma-separated list of actions in `0..num_actions`.
pub fn parse_actions(text: &str, num_actions: usize) -> Result<Vec<usize>, UsageError> {
    if text.trim().is_empty() {
        return Err(UsageError(
            "--actions: expected at least one action".to_string(),
        ));
    }
    text.split(',')
        .map(str::trim)
        .enumerate()
        .map(|(i, field)| match field.parse::<usize>() {
            Ok(a) if a < num_actions => Ok(a),
            _ => Err(UsageError(format!(
                "--actions: action {} ({field:?}) must be an integer from 0 to {}",
                i + 1,
                num_actions - 1
            ))),
        })
        .collect()
}

/// One line of `alfd env rollout`'s output.
#[derive(Debug, serde::Serialize)]
struct RolloutLine {
    state: [f64; 4],
    reward: f64,
    terminated: bool,
    truncated: bool,
}

/// `alfd env rollout`: one JSON line per step on `out`, warnings on `err`.
fn rollout(args: &RolloutArgs, out: &mut impl Write, err: &mut impl Write) -> anyhow::Result<()> {
    check_env(&args.env, "cartpole", "rollout")?;
    let state = parse_state(&args.initial_state)?;
    let mut env = CartPole::new(args.max_steps);
    let actions = parse_actions(&args.actions, env.num_actions())?;
    env.set_state(state);
    for (i, &action) in actions.iter().enumerate() {
        let step = env
            .step(action)
            .with_context(|| format!("step {} (action {action})", i + 1))?;
        let line = RolloutLine {
            state: env.state(),
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
        };
        serde_json::to_writer(&mut *out, &line).context("writing a step")?;
        writeln!(out).context("writing a step")?;
        if step.done() && i + 1 < actions.len() {
            writeln!(
                err,
                "warning: the episode ended after step {} ({}); the {} remaining action(s) were ignored",
                i + 1,
                if step.terminated { "terminated" } else { "truncated" },
                actions.len() - i - 1
            )
            .context("writing to stderr")?;
            break;
        }
    }
    Ok(())
}

/// Reads and parses a map file; both failures are usage errors naming the file.
fn load_map(path: &Path) -> anyhow::Result<CliffMap> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| usage(format!("--map {}: cannot read: {e}", path.display())))?;
    CliffMap::parse(&text).map_err(|e| usage(format!("--map {}: {e}", path.display())))
}

/// `alfd env show`: the map, then `WIDTHxHEIGHT, N pits; V*(S) = ...`.
fn show(args: &ShowArgs, out: &mut impl Write) -> anyhow::Result<()> {
    check_env(&args.env, "cliffwalk", "show")?;
    let map = match &args.map {
        Some(path) => load_map(path)?,
        None => CliffMap::default_map(),
    };
    let env = CliffWalk::new(map, args.p_success, DEFAULT_MAX_EPISODE_STEPS)
        .map_err(|e| usage(format!("--p-success: {e}")))?;
    let vi = cliffwalk::value_iteration(&env, args.gamma, 1e-10).map_err(|e| match e {
        cliffwalk::CliffWalkError::Gamma(_) => usage(format!("--gamma: {e}")),
        other => anyhow::Error::new(other).context("value iteration"),
    })?;
    let map = env.map();
    write!(out, "{map}").context("writing the map")?;
    writeln!(
        out,
        "{}x{} (width x height), {} pits; V*(S) = {:.6} (value iteration, gamma {}, p_success {})",
        map.width(),
        map.height(),
        map.num_pits(),
        vi.values[map.start()],
        args.gamma,
        args.p_success
    )
    .context("writing the map")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rollout_args(env: &str, state: &str, actions: &str, max_steps: usize) -> RolloutArgs {
        RolloutArgs {
            env: env.to_string(),
            initial_state: state.to_string(),
            actions: actions.to_string(),
            max_steps,
        }
    }

    fn run_rollout(args: &RolloutArgs) -> anyhow::Result<(String, String)> {
        let (mut out, mut err) = (Vec::new(), Vec::new());
        rollout(args, &mut out, &mut err)?;
        Ok((String::from_utf8(out)?, String::from_utf8(err)?))
    }

    #[test]
    fn rollout_prints_full_precision_states_that_match_the_library() {
        let (out, err) = run_rollout(&rollout_args(
            "cartpole",
            "0.01,-0.02,0.03,-0.04",
            "1,0,1",
            1000,
        ))
        .expect("valid input");
        assert_eq!(err, "");
        let mut env = CartPole::new(1000);
        env.set_state([0.01, -0.02, 0.03, -0.04]);
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 3);
        for (line, action) in lines.iter().zip([1, 0, 1]) {
            env.step(action).expect("running");
            let v: serde_json::Value = serde_json::from_str(line).expect("json");
            // Bit-exact: the printed numbers round-trip. (Parsed with `str::parse`, which is
            // correctly rounded; serde_json's default parser may be 1 ulp off.)
            let printed = line
                .strip_prefix("{\"state\":[")
                .and_then(|rest| rest.split(']').next())
                .expect("state first");
            let state: Vec<f64> = printed
                .split(',')
                .map(|x| x.parse().expect("number"))
                .collect();
            assert_eq!(state, env.state().to_vec());
            assert_eq!(v["reward"], 1.0);
            assert_eq!(v["terminated"], false);
            assert_eq!(v["truncated"], false);
        }
    }

    #[test]
    fn rollout_stops_at_the_end_of_the_episode_and_warns() {
        let (out, err) =
            run_rollout(&rollout_args("cartpole", "0,0,0,0", "1,1,1,1,1", 2)).expect("valid input");
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 2);
        assert!(
            lines[1].ends_with("\"terminated\":false,\"truncated\":true}"),
            "{}",
            lines[1]
        );
        assert!(err.contains("3 remaining action(s) were ignored"), "{err}");
    }

    #[test]
    fn rollout_accepts_a_negative_first_value_on_the_command_line() {
        use clap::Parser;
        #[derive(Debug, clap::Parser)]
        struct Cli {
            #[command(subcommand)]
            command: EnvCommand,
        }
        let cli = Cli::try_parse_from([
            "env",
            "rollout",
            "--env",
            "cartpole",
            "--initial-state",
            "-0.02,0.01,-0.03,0.04",
            "--actions",
            "0,1",
        ])
        .expect("parses");
        let EnvCommand::Rollout(args) = cli.command else {
            panic!("rollout expected")
        };
        assert_eq!(
            parse_state(&args.initial_state),
            Ok([-0.02, 0.01, -0.03, 0.04])
        );
        assert_eq!(args.max_steps, 1000);
    }

    #[test]
    fn bad_rollout_input_is_a_usage_error_naming_the_field() {
        let cases = [
            (
                rollout_args("cartpole", "0,0,0", "1", 10),
                "--initial-state: expected 4",
            ),
            (
                rollout_args("cartpole", "0,0,0,0,0", "1", 10),
                "got 5 value(s)",
            ),
            (
                rollout_args("cartpole", "0,zero,0,0", "1", 10),
                "value 2 (\"zero\") is not a number",
            ),
            (
                rollout_args("cartpole", "0,0,nan,0", "1", 10),
                "value 3 (\"nan\") is not finite",
            ),
            (
                rollout_args("cartpole", "0,0,0,0", "1,2", 10),
                "--actions: action 2 (\"2\")",
            ),
            (
                rollout_args("cartpole", "0,0,0,0", "1,-1", 10),
                "--actions: action 2 (\"-1\")",
            ),
            (
                rollout_args("cartpole", "0,0,0,0", "", 10),
                "--actions: expected at least one",
            ),
            (
                rollout_args("pendulum", "0,0,0,0", "1", 10),
                "unknown environment `pendulum`",
            ),
            (
                rollout_args("cliffwalk", "0,0,0,0", "1", 10),
                "supports only `cartpole`",
            ),
        ];
        for (args, expected) in cases {
            let e = run_rollout(&args).expect_err("bad input");
            assert!(is_usage_error(&e), "{e:#}");
            assert!(
                format!("{e:#}").contains(expected),
                "{e:#} should contain {expected}"
            );
        }
    }

    fn run_show(args: &ShowArgs) -> anyhow::Result<String> {
        let mut out = Vec::new();
        show(args, &mut out)?;
        Ok(String::from_utf8(out)?)
    }

    fn show_args(env: &str, map: Option<PathBuf>) -> ShowArgs {
        ShowArgs {
            env: env.to_string(),
            map,
            p_success: DEFAULT_P_SUCCESS,
            gamma: DEFAULT_GAMMA,
        }
    }

    #[test]
    fn show_prints_the_default_map_and_the_value_of_s() {
        let out = run_show(&show_args("cliffwalk", None)).expect("valid");
        let (map, summary) = out.split_at(cliffwalk::DEFAULT_MAP.len());
        assert_eq!(map, cliffwalk::DEFAULT_MAP);
        assert!(
            summary.starts_with("15x15 (width x height), 21 pits; V*(S) = 1.553473"),
            "{summary}"
        );
    }

    #[test]
    fn show_reads_a_map_file_and_refuses_bad_ones() {
        let dir = std::env::temp_dir().join(format!("alfd-cmd-env-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let good = dir.join("good.txt");
        std::fs::write(&good, "S.G\n").expect("write");
        let out = run_show(&show_args("cliffwalk", Some(good))).expect("valid");
        assert!(
            out.starts_with("S.G\n3x1 (width x height), 0 pits; V*(S) = "),
            "{out}"
        );

        let bad = dir.join("bad.txt");
        std::fs::write(&bad, "S.G\n.q.\n").expect("write");
        let e = run_show(&show_args("cliffwalk", Some(bad))).expect_err("bad map");
        assert!(is_usage_error(&e));
        assert!(e.to_string().contains("line 2, column 2"), "{e}");

        let e =
            run_show(&show_args("cliffwalk", Some(dir.join("missing.txt")))).expect_err("missing");
        assert!(
            is_usage_error(&e) && e.to_string().contains("missing.txt"),
            "{e}"
        );

        let e = run_show(&show_args("cartpole", None)).expect_err("no map");
        assert!(
            is_usage_error(&e) && e.to_string().contains("supports only `cliffwalk`"),
            "{e}"
        );
        let e = run_show(&show_args("gridworld", None)).expect_err("unknown");
        assert!(
            is_usage_error(&e) && e.to_string().contains("`gridworld`"),
            "{e}"
        );

        let mut args = show_args("cliffwalk", None);
        args.p_success = 1.5;
        let e = run_show(&args).expect_err("bad p_success");
        assert!(
            is_usage_error(&e) && e.to_string().contains("p_success"),
            "{e}"
        );
        let mut args = show_args("cliffwalk", None);
        args.gamma = 1.0;
        let e = run_show(&args).expect_err("bad gamma");
        assert!(is_usage_error(&e) && e.to_string().contains("gamma"), "{e}");
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
