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

use std::convert::Infallible;
use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::sync::{mpsc, Arc, Mutex};

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use tokio::sync::watch;

/// The name that makes the expert process ask a person (`--expert human`).
pub const HUMAN: &str = alfd_harness::HUMAN_EXPERT;

/// The file in the run directory that holds the page's address (`http://127.0.0.1:PORT/`) of
/// the human expert of `generation`.
pub fn human_page_file(generation: u16) -> String {
    format!("human-page-{generation}.txt")
}

const PAGE: &str = include_str!("page.html");

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

/// What the person decided about a query: an action, or `None` (declined).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    pub id: u64,
    pub action: Option<usize>,
}

struct Shared {
    state: watch::Sender<PageState>,
    decisions: Mutex<mpsc::Sender<Decision>>,
    waiting_ids: Mutex<Vec<u64>>,
}

/// The page, served until the process exits.
pub struct HumanPage {
    addr: SocketAddr,
    /// The secret path segment every request must start with.
    token: String,
    shared: Arc<Shared>,
    decisions: mpsc::Receiver<Decision>,
}

impl std::fmt::Debug for HumanPage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "HumanPage({})", self.addr)
    }
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

impl HumanPage {
    /// Serves the page on `127.0.0.1:port` (0: a free port; see [`HumanPage::url`]).
    pub fn start(port: u16, initial: PageState) -> Result<Self, HumanError> {
        let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port))
            .map_err(|source| HumanError::Bind { port, source })?;
        listener.set_nonblocking(true).map_err(HumanError::Start)?;
        let addr = listener.local_addr().map_err(HumanError::Start)?;
        let (tx, rx) = mpsc::channel();
        let (state, _) = watch::channel(initial);
        let shared = Arc::new(Shared {
            state,
            decisions: Mutex::new(tx),
            waiting_ids: Mutex::new(Vec::new()),
        });
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(HumanError::Start)?;
        let token = new_token();
        let at = |path: &str| format!("/{token}/{path}");
        let app = Router::new()
            .route(&at(""), get(|| async { Html(PAGE) }))
            .route(&at("state"), get(current))
            .route(&at("events"), get(events))
            .route(&at("answer"), post(answer))
            .route(&at("decline"), post(decline))
            .fallback(|| async {
                refuse(
                    StatusCode::FORBIDDEN,
                    "this page answers only at the address in the run directory's human-page file"
                        .to_owned(),
                )
            })
            .with_state(shared.clone());
        std::thread::Builder::new()
            .name("human-page".into())
            .spawn(move || {
                runtime.block_on(async move {
                    match tokio::net::TcpListener::from_std(listener) {
                        Ok(l) => {
                            if let Err(e) = axum::serve(l, app).await {
                                tracing::error!("the human expert's page stopped: {e}");
                            }
                        }
                        Err(e) => tracing::error!("the human expert's page cannot start: {e}"),
                    }
                });
            })
            .map_err(HumanError::Start)?;
        Ok(Self {
            addr,
            token,
            shared,
            decisions: rx,
        })
    }

    /// The page's address with its secret token, `http://127.0.0.1:PORT/TOKEN/`.
    pub fn url(&self) -> String {
        format!("http://{}/{}/", self.addr, self.token)
    }

    /// Where the page listens, `127.0.0.1:PORT` (without the token: safe to log).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Changes what the page shows (sent to every open page if anything changed).
    pub fn update(&self, change: impl FnOnce(&mut PageState)) {
        self.shared.state.send_if_modified(|s| {
            let before = s.clone();
            change(s);
            let changed = *s != before;
            if changed {
                s.version += 1;
            }
            changed
        });
    }

    /// Says which queries wait (oldest first): the page shows the first.
    pub fn set_waiting(&self, waiting: &[ShownQuery]) {
        if let Ok(mut ids) = self.shared.waiting_ids.lock() {
            *ids = waiting.iter().map(|q| q.id).collect();
        }
        self.update(|s| {
            s.waiting = waiting.len();
            s.query = waiting.first().cloned();
        });
    }

    /// The person's decisions since the last call.
    pub fn decisions(&self) -> Vec<Decision> {
        self.decisions.try_iter().collect()
    }
}

/// 128 random bits from the operating system's generator, as 32 hexadecimal digits: the secret
/// path segment of a page on 127.0.0.1 (this one's, and `alfd watch`'s).
pub fn new_token() -> String {
    use rand::Rng as _;
    format!("{:032x}", rand::rng().random::<u128>())
}

async fn current(State(shared): State<Arc<Shared>>) -> Json<PageState> {
    Json(shared.state.borrow().clone())
}

async fn events(
    State(shared): State<Arc<Shared>>,
) -> Sse<impl futures_util::Stream<Item = Result<Event, Infallible>>> {
    let rx = shared.state.subscribe();
    let stream = futures_util::stream::unfold((rx, true), |(mut rx, first)| async move {
        if !first && rx.changed().await.is_err() {
            return None;
        }
        let json = serde_json::to_string(&*rx.borrow_and_update()).ok()?;
        Some((Ok(Event::default().data(json)), (rx, false)))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

#[derive(Debug, Deserialize)]
struct AnswerBody {
    id: u64,
    action: usize,
}

#[derive(Debug, Deserialize)]
struct DeclineBody {
    id: u64,
}

fn refuse(status: StatusCode, message: String) -> Response {
    (status, Json(serde_json::json!({ "error": message }))).into_response()
}

fn decide(shared: &Shared, decision: Decision) -> Response {
    let actions = shared.state.borrow().actions.len();
    if let Some(a) = decision.action {
        if a >= actions {
            return refuse(
                StatusCode::BAD_REQUEST,
                format!("action {a} is not one of the {actions} actions"),
            );
        }
    }
    let waits = shared
        .waiting_ids
        .lock()
        .map(|ids| ids.contains(&decision.id))
        .unwrap_or(false);
    if !waits {
        return refuse(
            StatusCode::CONFLICT,
            format!(
                "query {} is not waiting (answered, declined or given up)",
                decision.id
            ),
        );
    }
    let sent = shared
        .decisions
        .lock()
        .map(|tx| tx.send(decision).is_ok())
        .unwrap_or(false);
    if !sent {
        return refuse(
            StatusCode::SERVICE_UNAVAILABLE,
            "the expert is stopping".to_owned(),
        );
    }
    (
        StatusCode::ACCEPTED,
        Json(serde_json::json!({ "id": decision.id })),
    )
        .into_response()
}

async fn answer(State(shared): State<Arc<Shared>>, Json(body): Json<AnswerBody>) -> Response {
    decide(
        &shared,
        Decision {
            id: body.id,
            action: Some(body.action),
        },
    )
}

async fn decline(State(shared): State<Arc<Shared>>, Json(body): Json<DeclineBody>) -> Response {
    decide(
        &shared,
        Decision {
            id: body.id,
            action: None,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let state = PageState {
            env: "cartpole".into(),
            actions: action_labels("cartpole", 2),
            active: false,
            budget_total: 1,
            budget_left: 1,
            demos: 0,
            waiting: 0,
            query: None,
            answered: 0,
            declined: 0,
            version: 0,
        };
        let e = HumanPage::start(port, state).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "cannot serve the human expert's page on 127.0.0.1:{port}"
            )),
            "{e}"
        );
    }
}
