//! The page that shows a run as it learns (`alfd watch`, `alfd run --watch`): it answers only at
//! its secret address, its data are the run directory's, and in Chromium its curve grows while
//! the run goes (two screenshots seconds apart differ).

use std::io::{Read as _, Write as _};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::support::{alfd, repo, text, timed, tmp};

const CONFIG: &str = "deploy/configs/cartpole-bdqn-krr.toml";

/// The page's address once it is written to `run_dir/watch-page.txt`.
fn page_url(run_dir: &Path, child: &mut std::process::Child) -> String {
    let start = Instant::now();
    loop {
        if let Ok(url) = std::fs::read_to_string(run_dir.join("watch-page.txt")) {
            return url.trim().to_owned();
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the process ended ({status}) before it served the page");
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no watch-page.txt"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A plain HTTP GET of `url`: its status and body.
fn get(url: &str) -> (u16, String) {
    let rest = url.strip_prefix("http://").unwrap();
    let (addr, path) = rest.split_at(rest.find('/').unwrap());
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let status = out[9..12].parse().unwrap();
    let body = out.split_once("\r\n\r\n").map_or("", |(_, b)| b).to_owned();
    (status, body)
}

#[test]
fn alfd_watch_serves_a_finished_run_only_at_its_secret_address() {
    let _time = timed!();
    let dir = tmp("watch-done");
    let out = dir.join("run");
    let o = alfd()
        .args(["local", "--config", CONFIG, "--quiet", "--out"])
        .arg(&out)
        .args(["--set", "episodes=6", "--set", "budget.total=10"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let missing = alfd()
        .args(["watch"])
        .arg(dir.join("nothing"))
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(2), "{}", text(&missing));
    assert!(
        text(&missing).contains("is not a directory"),
        "{}",
        text(&missing)
    );
    let mut child = alfd()
        .args(["watch"])
        .arg(&out)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let url = page_url(&out, &mut child);
    let (status, body) = get(&format!("{url}data"));
    assert_eq!(status, 200, "{body}");
    let data: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(data["episodes"].as_array().unwrap().len(), 6);
    assert_eq!(data["budget"], 10);
    assert_eq!(data["finished"], true);
    assert!(data["scalars"]["demos/used"].as_array().unwrap().len() == 6);
    let (page, html) = get(&url);
    assert_eq!(page, 200);
    assert!(html.contains("watching a run"));
    // Without the token: refused.
    let base = url.trim_end_matches('/').rsplit_once('/').unwrap().0;
    assert_eq!(get(&format!("{base}/data")).0, 403);
    assert_eq!(get(&format!("{base}/0123/data")).0, 403);
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn in_chromium_the_watch_page_grows_while_the_run_goes() {
    let _time = timed!();
    let Some(_) = crate::human::browser() else {
        return;
    };
    let driver = repo().join("deploy/cli/tests/browser/watch.mjs");
    let dir = tmp("watch-live");
    let out = dir.join("run");
    let mut run = alfd()
        .args([
            "run", "--config", CONFIG, "--actors", "2", "--quiet", "--watch", "--out",
        ])
        .arg(&out)
        // Longer than the test: it is stopped once the page has grown.
        .args([
            "--set",
            "episodes=0",
            "--set",
            "steps=2000000",
            "--set",
            "evaluation.every=10",
        ])
        .args(["--set", "evaluation.episodes=1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let url = page_url(&out, &mut run);
    let (first, second) = (
        crate::human::screenshot(&dir, "watch-1.png"),
        crate::human::screenshot(&dir, "watch-2.png"),
    );
    let node = Command::new("node")
        .arg(&driver)
        .arg(&url)
        .arg(&first)
        .arg(&second)
        .arg("mark")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("node runs");
    // Once the first screenshot is taken, actor 0 is killed: its restart is marked on the page.
    let start = std::time::Instant::now();
    while !first.is_file() && start.elapsed() < std::time::Duration::from_secs(150) {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let id = crate::runtime::run_id(&out);
    let actor =
        crate::runtime::find_process("alfd-actor", &[&format!("--run-id={id}"), "--actor-id=0"]);
    crate::runtime::signal("KILL", actor.expect("actor 0"));
    let o = node.wait_with_output().expect("node runs");
    // Stopped as Ctrl-C would stop it: the run ends cleanly, interrupted (exit code 130).
    let term = Command::new("kill")
        .args(["-TERM", &run.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    let ended = run.wait().unwrap();
    assert_eq!(ended.code(), Some(130), "the interrupted run: {ended}");
    assert!(o.status.success(), "{}", text(&o));
    let seen: Value = serde_json::from_str(String::from_utf8_lossy(&o.stdout).trim()).unwrap();
    let (a, b) = (&seen["first"], &seen["second"]);
    assert!(
        b["episodes"].as_u64().unwrap() >= a["episodes"].as_u64().unwrap() + 5,
        "{seen}"
    );
    assert!(
        a["status"].as_str().unwrap().contains("(running)"),
        "{seen}"
    );
    assert!(b["paths"].as_u64().unwrap() >= 1, "{seen}");
    assert_eq!(a["marks"], 0, "{seen}");
    assert!(
        b["marks"].as_u64().unwrap() >= 1,
        "the restart is marked: {seen}"
    );
    let (x, y) = (
        std::fs::read(&first).unwrap(),
        std::fs::read(&second).unwrap(),
    );
    assert_ne!(x, y, "the two screenshots are the same");
}
