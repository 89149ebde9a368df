//! A person as the expert: a small web page on `127.0.0.1` (axum on a thread of its own) shows
//! the oldest waiting query as a picture (CliffWalk's grid, CartPole's cart and pole, the raw
//! observation otherwise), the budget left and how many queries wait, and takes the answer by
//! button or key, or a decline. Live updates go out as server-sent events (`GET /events`);
//! `GET /state` gives the same JSON once; `POST /answer {"id", "action"}` and
//! `POST /decline {"id"}` send the person's decision to the expert process, which answers the
//! actor (see the process module: budget, `demos.jsonl` and the model are handled there, as for
//! every other expert).
//!
//! The page answers only its person: every path lives under a secret token made when the page
//! starts (`http://127.0.0.1:PORT/TOKEN/`, 128 random bits), which the expert process writes to
//! the run directory in a file only its owner can read; any other request gets 403.

use serde::{Deserialize, Serialize};

// The page's server (axum), behind the `page` feature; without it, `HumanPage::start` says how
// to build it.
pub mod link;
#[cfg(feature = "page")]
mod server;
#[cfg(not(feature = "page"))]
#[path = "server_off.rs"]
mod server;
#[cfg(feature = "page")]
pub use server::serve_in_background;
pub use server::HumanPage;

/// The name that makes the expert process ask a person (`--expert human`).
pub const HUMAN: &str = alfd_harness::HUMAN_EXPERT;

/// The file in the run directory that holds the page's address (`http://127.0.0.1:PORT/`) of
/// the human expert of `generation`.
pub fn human_page_file(generation: u16) -> String {
    format!("human-page-{generation}.txt")
}

/// The page cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum HumanError {
    #[error("cannot serve the human expert's page on 127.0.0.1:{port}: {source}")]
    Bind {
        port: u16,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the human expert's page: {0}")]
    Start(#[source] std::io::Error),
    #[error(
        "a person answers on a web page, and this alfd-expert was built without it (the \
         `page` feature; deploy/run.sh builds the main job so): build every feature with \
         `cargo build --release --workspace`"
    )]
    Unavailable,
}

/// A query as the page shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShownQuery {
    /// The page's number for it (answers name it).
    pub id: u64,
    pub actor: u32,
    pub step: u64,
    pub state: Vec<f32>,
}

/// Everything the page shows (sent whole on every change).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PageState {
    /// The environment, as the config names it (`cartpole`, `cliffwalk`, ...).
    pub env: String,
    /// One label per action.
    pub actions: Vec<String>,
    /// Whether this expert answers now (a swapped-in expert waits to be made active).
    pub active: bool,
    pub budget_total: u32,
    pub budget_left: u32,
    /// Demonstrations given in the run.
    pub demos: u32,
    /// Queries waiting for the person, this one included.
    pub waiting: usize,
    /// The oldest waiting query.
    pub query: Option<ShownQuery>,
    /// The person's decisions so far in this process: answers and declines.
    pub answered: u64,
    pub declined: u64,
    /// Bumped on every change.
    pub version: u64,
}

impl PageState {
    /// The page of `env` with `actions` actions, standing by, before anything is known.
    pub fn blank(env: &str, actions: usize) -> Self {
        Self {
            env: env.to_owned(),
            actions: action_labels(env, actions),
            active: false,
            budget_total: 0,
            budget_left: 0,
            demos: 0,
            waiting: 0,
            query: None,
            answered: 0,
            declined: 0,
            version: 0,
        }
    }
}

/// Writes the address of `page` (with its token) to the run directory's human-page file of
/// `generation`, which only its owner can read.
pub fn write_address(
    run_dir: &std::path::Path,
    generation: u16,
    page: &HumanPage,
) -> alfd_harness::Result<()> {
    alfd_harness::write_private(
        &run_dir.join(human_page_file(generation)),
        format!("{}\n", page.url()).as_bytes(),
    )
}

/// What the person decided about a query: an action, or `None` (declined).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    pub id: u64,
    pub action: Option<usize>,
}

/// Labels of the actions of `env` (`actions` of them).
pub fn action_labels(env: &str, actions: usize) -> Vec<String> {
    let named: &[&str] = match env {
        "cartpole" => &["push left", "push right"],
        "cliffwalk" => &["up", "right", "down", "left"],
        "mountaincar" => &["push left", "no push", "push right"],
        "acrobot" => &["torque -1", "torque 0", "torque +1"],
        _ => &[],
    };
    (0..actions)
        .map(|a| {
            named
                .get(a)
                .filter(|_| named.len() == actions)
                .map_or_else(|| format!("action {a}"), |s| (*s).to_owned())
        })
        .collect()
}

/// 128 random bits from the operating system's generator, as 32 hexadecimal digits: the secret
/// path segment of a page on 127.0.0.1 (this one's, and `alfd watch`'s).
pub fn new_token() -> String {
    use rand::Rng as _;
    format!("{:032x}", rand::rng().random::<u128>())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::Ipv4Addr;

    #[test]
    fn actions_are_labelled_by_environment_and_numbered_otherwise() {
        assert_eq!(action_labels("cartpole", 2), ["push left", "push right"]);
        assert_eq!(action_labels("cliffwalk", 4)[3], "left");
        assert_eq!(
            action_labels("gymnasium", 3),
            ["action 0", "action 1", "action 2"]
        );
        // Another number of actions than the environment's usual: numbered.
        assert_eq!(action_labels("cartpole", 3)[0], "action 0");
    }

    #[test]
    fn a_port_in_use_is_refused_naming_it() {
        let held = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let port = held.local_addr().unwrap().port();
        let e = HumanPage::start(port, PageState::blank("cartpole", 2))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(&format!(
                "cannot serve the human expert's page on 127.0.0.1:{port}"
            )),
            "{e}"
        );
    }
}
