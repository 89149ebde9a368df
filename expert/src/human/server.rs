//! The human expert's page server: axum on a thread of its own, on 127.0.0.1 under a secret
//! token (see the parent module).

use std::convert::Infallible;
use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::sync::{mpsc, Arc, Mutex};

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use tokio::sync::watch;

use super::{new_token, Decision, HumanError, PageState, ShownQuery};

const PAGE: &str = include_str!("page.html");

/// Serves `app` on `listener` (bound, non-blocking) until the process exits, from a thread of
/// its own named `thread` on a single-threaded tokio runtime; `what` names the page in the log.
/// `alfd watch`'s page is served the same way.
pub fn serve_in_background(
    listener: TcpListener,
    app: Router,
    (thread, what): (&str, &'static str),
) -> std::io::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    std::thread::Builder::new()
        .name(thread.into())
        .spawn(move || {
            runtime.block_on(async move {
                match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => {
                        if let Err(e) = axum::serve(l, app).await {
                            tracing::error!("{what} stopped: {e}");
                        }
                    }
                    Err(e) => tracing::error!("{what} cannot start: {e}"),
                }
            });
        })?;
    Ok(())
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
        serve_in_background(listener, app, ("human-page", "the human expert's page"))
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

    /// Shows what a sync from the expert process says (a page in a process of its own): the
    /// oldest waiting query is the only one the person can decide.
    pub fn show(&self, sync: &super::link::PageSync) {
        if let Ok(mut ids) = self.shared.waiting_ids.lock() {
            *ids = sync.query.iter().map(|q| q.id).collect();
        }
        self.update(|s| sync.apply(s));
    }

    /// The person's decisions since the last call.
    pub fn decisions(&self) -> Vec<Decision> {
        self.decisions.try_iter().collect()
    }
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
