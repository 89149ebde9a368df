//! `alfd env`: look at the environments from the command line — roll CartPole, MountainCar or
//! Acrobot out from a given state (to check our dynamics against another implementation) and
//! show a CliffWalk map.
//!
//! Bad input (a malformed state or action list, an unknown env name, an unreadable or malformed
//! map, an out-of-range parameter) is returned as a [`BadInput`], which `main` maps to exit
//! code 2 (see [`crate::usage::exit_code`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use alfd_common::config::EnvName;
use alfd_common::env::cliffwalk::{
    self, CliffMap, CliffWalk, DEFAULT_GAMMA, DEFAULT_MAX_EPISODE_STEPS, DEFAULT_P_SUCCESS,
};
use alfd_common::env::{Acrobot, CartPole, Env, MountainCar, Step};
use anyhow::Context;

#[cfg(test)]
use crate::usage::is_usage_error;
use crate::usage::usage;
pub use alfd_harness::BadInput;

/// Arguments of `alfd env`.
#[derive(Debug, clap::Args)]
pub struct EnvArgs {
    #[command(subcommand)]
    pub command: EnvCommand,
}

/// The subcommands of `alfd env`.
#[derive(Debug, clap::Subcommand)]
pub enum EnvCommand {
    /// Step CartPole, MountainCar or Acrobot from a given state through a list of actions,
    /// printing one JSON object per step with the float64 state after it, e.g. for CartPole
    /// `{"state":[x,x_dot,theta,theta_dot],"reward":1.0,"terminated":false,"truncated":false}`.
    Rollout(RolloutArgs),
    /// Print a CliffWalk map as text, then its size and the optimal value of S.
    Show(ShowArgs),
}

/// Arguments of `alfd env rollout`.
#[derive(Debug, clap::Args)]
pub struct RolloutArgs {
    /// Environment name: `cartpole`, `mountaincar`, `acrobot` or `deepsea`.
    #[arg(long)]
    pub env: String,
    /// The float64 state the episode begins from, comma-separated: X,XDOT,THETA,THETADOT
    /// (cartpole), POSITION,VELOCITY (mountaincar) or THETA1,THETA2,DTHETA1,DTHETA2 (acrobot);
    /// not for deepsea, which starts at the top-left cell.
    #[arg(long, value_name = "V,V,...", allow_hyphen_values = true)]
    pub initial_state: Option<String>,
    /// DeepSea: N, the grid's side (1 to 100).
    #[arg(long)]
    pub size: Option<usize>,
    /// DeepSea: the seed of the action mapping (bsuite's `mapping_seed`).
    #[arg(long)]
    pub mapping_seed: Option<u32>,
    /// Comma-separated actions: 0 (push left) or 1 (push right) for cartpole; 0 (left), 1 (none)
    /// or 2 (right) for mountaincar; 0, 1 or 2 (torque -1, 0, +1) for acrobot. Actions left over
    /// when the episode ends are ignored, with a warning.
    #[arg(long, value_name = "A,A,...")]
    pub actions: String,
    /// Step limit of the episode (reported as `truncated`); by default the environment's
    /// (cartpole 1000, mountaincar 200, acrobot 500).
    #[arg(long)]
    pub max_steps: Option<usize>,
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

/// The environment `name`, refused (as a usage error) if it is not one or if the subcommand does
/// not support it.
fn check_env(name: &str, supported: &[EnvName], subcommand: &str) -> anyhow::Result<EnvName> {
    let env: EnvName = name.parse().map_err(|e| usage(format!("--env: {e}")))?;
    if supported.contains(&env) {
        Ok(env)
    } else {
        let names: Vec<String> = supported.iter().map(|e| format!("`{e}`")).collect();
        Err(usage(format!(
            "--env {name}: `alfd env {subcommand}` supports only {}",
            names.join(", ")
        )))
    }
}

/// Parses `--initial-state`: exactly `N` finite comma-separated numbers, named `names`
/// (`X,XDOT,THETA,THETADOT`) in the error.
pub fn parse_state<const N: usize>(text: &str, names: &str) -> Result<[f64; N], BadInput> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != N {
        return Err(BadInput(format!(
            "--initial-state: expected {N} comma-separated numbers {names}, got {} value(s) in {text:?}",
            fields.len()
        )));
    }
    let mut state = [0.0; N];
    for (i, (slot, field)) in state.iter_mut().zip(&fields).enumerate() {
        let value: f64 = field.parse().map_err(|_| {
            BadInput(format!(
                "--initial-state: value {} ({field:?}) is not a number",
                i + 1
            ))
        })?;
        if !value.is_finite() {
            return Err(BadInput(format!(
                "--initial-state: value {} ({field:?}) is not finite",
                i + 1
            )));
        }
        *slot = value;
    }
    Ok(state)
}

/// Parses `--actions`: a non-empty comma-separated list of actions in `0..num_actions`.
pub fn parse_actions(text: &str, num_actions: usize) -> Result<Vec<usize>, BadInput> {
    if text.trim().is_empty() {
        return Err(BadInput(
            "--actions: expected at least one action".to_string(),
        ));
    }
    text.split(',')
        .map(str::trim)
        .enumerate()
        .map(|(i, field)| match field.parse::<usize>() {
            Ok(a) if a < num_actions => Ok(a),
            _ => Err(BadInput(format!(
                "--actions: action {} ({field:?}) must be an integer from 0 to {}",
                i + 1,
                num_actions - 1
            ))),
        })
        .collect()
}

/// One line of `alfd env rollout`'s output.
#[derive(Debug, serde::Serialize)]
struct RolloutLine<'a> {
    state: &'a [f64],
    reward: f64,
    terminated: bool,
    truncated: bool,
}

/// An environment that `alfd env rollout` starts from a given float64 state.
struct Rollable<E, const N: usize> {
    env: E,
    /// The state's values, as `--initial-state` takes them.
    names: &'static str,
    set_state: fn(&mut E, [f64; N]),
    state: fn(&E) -> [f64; N],
}

/// `alfd env rollout`: one JSON line per step on `out`, warnings on `err`.
fn rollout(args: &RolloutArgs, out: &mut impl Write, err: &mut impl Write) -> anyhow::Result<()> {
    let name = check_env(
        &args.env,
        &[
            EnvName::Cartpole,
            EnvName::Mountaincar,
            EnvName::Acrobot,
            EnvName::Deepsea,
        ],
        "rollout",
    )?;
    if name == EnvName::Deepsea {
        return roll_deepsea(args, out, err);
    }
    if args.size.is_some() || args.mapping_seed.is_some() {
        return Err(usage("--size and --mapping-seed apply to deepsea only"));
    }
    let limit = args.max_steps.unwrap_or(name.default_max_episode_steps());
    match name {
        EnvName::Cartpole => roll(
            Rollable {
                env: CartPole::new(limit),
                names: "X,XDOT,THETA,THETADOT",
                set_state: CartPole::set_state,
                state: CartPole::state,
            },
            args,
            out,
            err,
        ),
        EnvName::Mountaincar => roll(
            Rollable {
                env: MountainCar::new(limit),
                names: "POSITION,VELOCITY",
                set_state: MountainCar::set_state,
                state: MountainCar::state,
            },
            args,
            out,
            err,
        ),
        EnvName::Acrobot => roll(
            Rollable {
                env: Acrobot::new(limit),
                names: "THETA1,THETA2,DTHETA1,DTHETA2",
                set_state: Acrobot::set_state,
                state: Acrobot::state,
            },
            args,
            out,
            err,
        ),
        EnvName::Cliffwalk | EnvName::Gymnasium | EnvName::Deepsea => {
            unreachable!("refused by check_env, or rolled by roll_deepsea")
        }
    }
}

/// Steps `r.env` from `--initial-state` through `--actions`. The whole rollout is computed before
/// anything is printed: should the dynamics overflow (a state value becoming infinite or NaN, as
/// from an initial state of magnitude near 1e308), the rollout is refused, naming the step, and
/// no line is printed.
fn roll<E: Env, const N: usize>(
    mut r: Rollable<E, N>,
    args: &RolloutArgs,
    out: &mut impl Write,
    err: &mut impl Write,
) -> anyhow::Result<()> {
    let given = args.initial_state.as_deref().ok_or_else(|| {
        usage(format!(
            "--initial-state is needed: the state to start from ({})",
            r.names
        ))
    })?;
    let state = parse_state::<N>(given, r.names)?;
    let actions = parse_actions(&args.actions, r.env.num_actions())?;
    (r.set_state)(&mut r.env, state);
    let mut lines = Vec::new();
    let mut warning = None;
    for (i, &action) in actions.iter().enumerate() {
        let step = r
            .env
            .step(action)
            .with_context(|| format!("step {} (action {action})", i + 1))?;
        let state = (r.state)(&r.env);
        if let Some(c) = state.iter().position(|v| !v.is_finite()) {
            return Err(usage(format!(
                "--initial-state {}: the state stopped being finite at step {} (action {action}): \
                 {} became {}; the dynamics overflow f64 from an initial state this large, so \
                 nothing was printed (give one of smaller magnitude)",
                given,
                i + 1,
                r.names.split(',').nth(c).unwrap_or("a value"),
                state[c]
            )));
        }
        let line = RolloutLine {
            state: &state,
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
        };
        serde_json::to_writer(&mut lines, &line).context("writing a step")?;
        lines.push(b'\n');
        warning = ended_early(&step, i, actions.len());
        if warning.is_some() {
            break;
        }
    }
    print_rollout(&lines, warning, out, err)
}

/// The warning of a rollout whose episode ended at step `i` (0-based) of `n` actions, if
/// actions are left over.
fn ended_early<O>(step: &Step<O>, i: usize, n: usize) -> Option<String> {
    (step.done() && i + 1 < n).then(|| {
        format!(
            "warning: the episode ended after step {} ({}); the {} remaining action(s) were ignored",
            i + 1,
            if step.terminated { "terminated" } else { "truncated" },
            n - i - 1
        )
    })
}

/// The rollout's lines on `out`, then its warning (if any) on `err`.
fn print_rollout(
    lines: &[u8],
    warning: Option<String>,
    out: &mut impl Write,
    err: &mut impl Write,
) -> anyhow::Result<()> {
    out.write_all(lines).context("writing the steps")?;
    if let Some(w) = warning {
        writeln!(err, "{w}").context("writing to stderr")?;
    }
    Ok(())
}

/// One step of a DeepSea rollout: the agent's `[row, column]` after it (`null` after the last
/// row) and what the step gave.
#[derive(serde::Serialize)]
struct DeepSeaLine {
    position: Option<[usize; 2]>,
    reward: f64,
    terminated: bool,
    truncated: bool,
}

/// `alfd env rollout --env deepsea --size N --mapping-seed S --actions ...`: one line per step.
fn roll_deepsea(
    args: &RolloutArgs,
    out: &mut impl Write,
    err: &mut impl Write,
) -> anyhow::Result<()> {
    if args.initial_state.is_some() {
        return Err(usage(
            "--initial-state: deepsea starts at the top-left cell; give --size and --mapping-seed",
        ));
    }
    let size = args
        .size
        .ok_or_else(|| usage("--size is needed for deepsea (N, the grid's side)"))?;
    let seed = args
        .mapping_seed
        .ok_or_else(|| usage("--mapping-seed is needed for deepsea"))?;
    let limit = args.max_steps.unwrap_or(size);
    let mut env = alfd_common::env::DeepSea::with_max_episode_steps(size, seed, limit)
        .map_err(|e| usage(format!("--size: {e}")))?;
    let actions = parse_actions(&args.actions, env.num_actions())?;
    env.reset(Some(0));
    let mut lines = Vec::new();
    let mut warning = None;
    for (i, &action) in actions.iter().enumerate() {
        let step = env
            .step(action)
            .with_context(|| format!("step {} (action {action})", i + 1))?;
        let line = DeepSeaLine {
            position: env.position().map(|(r, c)| [r, c]),
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
        };
        serde_json::to_writer(&mut lines, &line).context("writing a step")?;
        lines.push(b'\n');
        warning = ended_early(&step, i, actions.len());
        if warning.is_some() {
            break;
        }
    }
    print_rollout(&lines, warning, out, err)
}

/// Reads and parses a map file; both failures are usage errors naming the file.
fn load_map(path: &Path) -> anyhow::Result<CliffMap> {
    let text = crate::setup::read_map_text(path)
        .map_err(|e| usage(format!("--map {}: {e}", path.display())))?;
    CliffMap::parse(&text).map_err(|e| usage(format!("--map {}: {e}", path.display())))
}

/// `alfd env show`: the map, then `WIDTHxHEIGHT, N pits; V*(S) = ...`.
fn show(args: &ShowArgs, out: &mut impl Write) -> anyhow::Result<()> {
    check_env(&args.env, &[EnvName::Cliffwalk], "show")?;
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
            initial_state: Some(state.to_string()),
            actions: actions.to_string(),
            max_steps: Some(max_steps),
            size: None,
            mapping_seed: None,
        }
    }

    /// The states printed by a rollout, parsed with `str::parse` (correctly rounded; serde_json's
    /// default parser may be 1 ulp off), and each line as JSON.
    fn printed_states(out: &str) -> Vec<(Vec<f64>, serde_json::Value)> {
        out.lines()
            .map(|line| {
                let printed = line
                    .strip_prefix("{\"state\":[")
                    .and_then(|rest| rest.split(']').next())
                    .expect("state first");
                let state = printed
                    .split(',')
                    .map(|x| x.parse().expect("number"))
                    .collect();
                (state, serde_json::from_str(line).expect("json"))
            })
            .collect()
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
        let lines = printed_states(&out);
        assert_eq!(lines.len(), 3);
        for ((state, v), action) in lines.into_iter().zip([1, 0, 1]) {
            env.step(action).expect("running");
            // Bit-exact: the printed numbers round-trip.
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
    fn a_rollout_whose_state_overflows_is_refused_naming_the_step_and_prints_nothing() {
        for (env, state, actions, step, value) in [
            ("cartpole", "0,0,0,1e308", "0,1", 1, "XDOT became NaN"),
            (
                "mountaincar",
                "1e308,1e308",
                "0,1",
                1,
                "POSITION became NaN",
            ),
            ("acrobot", "0,0,1e308,1e308", "0,1", 1, "THETA1 became NaN"),
        ] {
            let (mut out, mut err) = (Vec::new(), Vec::new());
            let e =
                rollout(&rollout_args(env, state, actions, 100), &mut out, &mut err).unwrap_err();
            assert!(is_usage_error(&e), "{env}: {e:#}");
            let msg = format!("{e:#}");
            assert!(
                msg.contains(&format!("stopped being finite at step {step} (action 0)"))
                    && msg.contains(value)
                    && msg.contains(&format!("--initial-state {state}")),
                "{env}: {msg}"
            );
            assert!(
                out.is_empty() && err.is_empty(),
                "{env}: something was printed"
            );
        }
        // A large state whose steps stay finite is rolled out.
        let (out, _) = run_rollout(&rollout_args("cartpole", "1e300,1e300,0,0", "0", 10))
            .expect("finite all along");
        assert_eq!(out.lines().count(), 1);
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
            parse_state::<4>(
                args.initial_state.as_deref().unwrap(),
                "X,XDOT,THETA,THETADOT"
            ),
            Ok([-0.02, 0.01, -0.03, 0.04])
        );
        assert_eq!(args.max_steps, None);
    }

    #[test]
    fn mountaincar_and_acrobot_roll_out_like_the_library_with_their_own_limits() {
        let mut args = rollout_args("mountaincar", "-0.5,0.01", "2,1,0", 0);
        args.max_steps = None;
        let (out, err) = run_rollout(&args).expect("valid input");
        assert_eq!(err, "");
        let mut env = MountainCar::new(200);
        env.set_state([-0.5, 0.01]);
        for ((state, v), action) in printed_states(&out).into_iter().zip([2, 1, 0]) {
            let step = env.step(action).expect("running");
            assert_eq!(state, env.state().to_vec());
            assert_eq!(
                (v["reward"].as_f64(), v["truncated"].as_bool()),
                (Some(-1.0), Some(false))
            );
            assert!(!step.done());
        }

        let mut args = rollout_args("acrobot", "0.1,-0.05,0,0.2", "0,2", 0);
        args.max_steps = None;
        let (out, _) = run_rollout(&args).expect("valid input");
        let mut env = Acrobot::new(500);
        env.set_state([0.1, -0.05, 0.0, 0.2]);
        let lines = printed_states(&out);
        assert_eq!(lines.len(), 2);
        for ((state, _), action) in lines.into_iter().zip([0, 2]) {
            env.step(action).expect("running");
            assert_eq!(state, env.state().to_vec());
        }

        // The default limits are the environments' own: MountainCar truncates at 200.
        let actions = vec!["1"; 201].join(",");
        let mut args = rollout_args("mountaincar", "-0.5,0", &actions, 0);
        args.max_steps = None;
        let (out, err) = run_rollout(&args).expect("valid input");
        assert_eq!(out.lines().count(), 200);
        assert!(out.lines().last().unwrap().ends_with("\"truncated\":true}"));
        assert!(err.contains("1 remaining action(s) were ignored"), "{err}");
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
                "unknown environment `pendulum` (known: cartpole, cliffwalk, mountaincar, acrobot, gymnasium, deepsea)",
            ),
            (
                rollout_args("cliffwalk", "0,0,0,0", "1", 10),
                "supports only `cartpole`, `mountaincar`, `acrobot`",
            ),
            (
                rollout_args("mountaincar", "0,0,0,0", "1", 10),
                "expected 2 comma-separated numbers POSITION,VELOCITY, got 4",
            ),
            (
                rollout_args("mountaincar", "-0.5,0", "3", 10),
                "--actions: action 1 (\"3\") must be an integer from 0 to 2",
            ),
            (
                rollout_args("acrobot", "0,0", "1", 10),
                "expected 4 comma-separated numbers THETA1,THETA2,DTHETA1,DTHETA2",
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
        let tmp = alfd_harness::test_dir("cmd-env");
        let dir = tmp.path();
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
    }
}
