//! The watch page's server: axum on a thread of its own (see the parent module).

use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context as _;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::{Json, Router};
use serde::Serialize;

use alfd_common::record::parse_episodes_csv;
use alfd_common::tensorboard::read_scalars;

const PAGE: &str = include_str!("../watch.html");
/// The file in the run directory that holds the page's address.
const WATCH_PAGE_FILE: &str = "watch-page.txt";

/// The page, served on a thread of its own until the process exits.
#[derive(Debug)]
pub struct WatchPage {
    addr: SocketAddr,
    token: String,
}

impl WatchPage {
    /// The page's address with its secret token.
    pub fn url(&self) -> String {
        format!("http://{}/{}/", self.addr, self.token)
    }
}

/// Serves the page of `run_dir` on `127.0.0.1:port` and writes its address to
/// `run_dir/watch-page.txt` (the directory is created if need be).
pub fn serve(run_dir: &Path, port: u16) -> anyhow::Result<WatchPage> {
    let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port)).map_err(|e| {
        crate::usage::usage(format!(
            "cannot serve the watch page on 127.0.0.1:{port}: {e}"
        ))
    })?;
    listener.set_nonblocking(true)?;
    let addr = listener.local_addr()?;
    let token = alfd_expert::human::new_token();
    let dir = Arc::new(run_dir.to_path_buf());
    let at = |path: &str| format!("/{token}/{path}");
    let app = Router::new()
        .route(&at(""), get(|| async { Html(PAGE) }))
        .route(&at("data"), get(data))
        .fallback(|| async {
            (
                StatusCode::FORBIDDEN,
                "this page answers only at the address in the run directory's watch-page.txt",
            )
                .into_response()
        })
        .with_state(dir);
    alfd_expert::human::serve_in_background(listener, app, ("watch-page", "the watch page"))?;
    let page = WatchPage { addr, token };
    std::fs::create_dir_all(run_dir)
        .with_context(|| format!("cannot create {}", run_dir.display()))?;
    alfd_harness::write_private(&run_dir.join(WATCH_PAGE_FILE), page.url().as_bytes())?;
    Ok(page)
}

/// What the page draws.
#[derive(Debug, Default, Serialize)]
struct Data {
    /// Per episode: `[episode, total_steps, return, eval_return or null, queries, demos_used,
    /// actor]`.
    episodes: Vec<[Option<f64>; 7]>,
    budget: Option<u32>,
    /// Per scalar tag of the event files: `[wall-clock seconds since the first event, step,
    /// value]`.
    scalars: std::collections::BTreeMap<String, Vec<[f64; 3]>>,
    finished: bool,
}

async fn data(State(dir): State<Arc<PathBuf>>) -> Json<Data> {
    Json(read(&dir))
}

/// The run directory as the page shows it; what cannot be read (yet) is left out.
fn read(dir: &Path) -> Data {
    let mut d = Data {
        finished: dir.join("summary.json").is_file(),
        ..Data::default()
    };
    if let Ok(text) = std::fs::read_to_string(dir.join("episodes.csv")) {
        // A row being written is cut at the last whole line.
        let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
        if let Ok(records) = parse_episodes_csv(whole) {
            d.episodes = records
                .iter()
                .map(|r| {
                    let eval = (!r.eval_return.is_nan()).then_some(r.eval_return);
                    [
                        Some(f64::from(r.episode)),
                        Some(r.total_steps as f64),
                        Some(r.ret),
                        eval,
                        Some(f64::from(r.queries)),
                        Some(f64::from(r.demos_used)),
                        Some(f64::from(r.actor)),
                    ]
                })
                .collect();
        }
    }
    if let Ok(text) = std::fs::read_to_string(dir.join("config.toml")) {
        d.budget = alfd_common::config::ExperimentConfig::from_toml(&text)
            .ok()
            .map(|c| c.budget());
    }
    let mut events = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir.join(alfd_harness::tensorboard::TB_DIR)) {
        for e in entries.flatten() {
            if let Ok(bytes) = std::fs::read(e.path()) {
                events.extend(read_scalars(&bytes));
            }
        }
    }
    let start = events
        .iter()
        .map(|e| e.wall_time)
        .fold(f64::INFINITY, f64::min);
    events.sort_by(|a, b| a.wall_time.total_cmp(&b.wall_time));
    for e in events {
        d.scalars.entry(e.tag).or_default().push([
            e.wall_time - start,
            e.step as f64,
            f64::from(e.value),
        ]);
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_data_of_a_run_directory_comes_from_its_files_and_skips_a_half_written_row() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(read(dir.path()).episodes.len(), 0, "nothing yet");
        let csv = format!(
            "{}\n0,-200,200,3,0.1,3,0,200,0,\n1,-150,150,5,0.1,2,0,350,1,-160\n2,-1",
            alfd_common::record::CSV_HEADER
        );
        std::fs::write(dir.path().join("episodes.csv"), csv).unwrap();
        let d = read(dir.path());
        assert_eq!(d.episodes.len(), 2);
        assert_eq!(d.episodes[1][3], Some(-160.0));
        assert_eq!(d.episodes[0][3], None);
        assert!(!d.finished);
        let mut w = alfd_harness::tensorboard::EventWriter::create(dir.path(), "t").unwrap();
        w.scalars(350, &[("actor/0/sps".into(), 120.0)]).unwrap();
        let d = read(dir.path());
        assert_eq!(d.scalars["actor/0/sps"][0][1..], [350.0, 120.0]);
    }
}
