//! A person as the expert: `alfd run --expert human` serves a page on
//! 127.0.0.1; these tests act as the person, over HTTP from Rust and in Debian's Chromium driven
//! by Playwright (`deploy/cli/tests/browser/`, installed with npm by the test itself).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use alfd_expert::human::{action_labels, HumanPage, PageState, ShownQuery};
use serde_json::Value;

use crate::support::{alfd, repo, text, timed, tmp, Background};

/// A CartPole config answered by a person: queries on the first steps, `budget` of them.
fn cartpole_config(dir: &Path, budget: u32, episodes: u32) -> PathBuf {
    let config = dir.join("human.toml");
    std::fs::write(
        &config,
        format!(
            "seed = 3\nepisodes = {episodes}\n[env]\nname = \"cartpole\"\nmax_episode_steps = 20\n\
             [agent]\nkind = \"bdqn\"\nbatch_size = 16\n[query]\nmode = \"first\"\n\
             [budget]\ntotal = {budget}\n[expert]\nname = \"cartpole-perfect\"\nmodel = \"krr\"\n"
        ),
    )
    .unwrap();
    config
}

/// Starts `alfd run --expert human` on a free port; returns the run and the page's address
/// (`127.0.0.1:PORT`), as the expert wrote it in the run directory.
fn start_run(config: &Path, run_dir: &Path, actors: usize) -> (Background, String) {
    start_run_with(config, run_dir, actors, &["--expert=human"])
}

/// [`start_run`] with more arguments of `alfd run`.
fn start_run_with(
    config: &Path,
    run_dir: &Path,
    actors: usize,
    args: &[&str],
) -> (Background, String) {
    let mut run = Background(Some(
        alfd()
            .args(["run", "--quiet", "--human-port=0"])
            .args(args)
            .arg(format!("--actors={actors}"))
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", run_dir.display()))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let start = Instant::now();
    loop {
        if let Some(addr) = page_addr(run_dir) {
            return (run, addr);
        }
        if let Ok(Some(status)) = run.child().try_wait() {
            panic!("alfd run exited ({status}) before serving the page");
        }
        assert!(start.elapsed() < Duration::from_secs(120), "no page");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_paused_page_of_a_person_among_several_experts_is_synced_seldom_and_the_others_answer() {
    let _time = timed!();
    let out = tmp("human-paused");
    // Six answers of the script and six queries of the person, each given up after 0.5 s: the
    // run lasts longer than the pause below (2000 short episodes besides).
    // Each in turn: the person (whose queries time out, nobody answering) and the script.
    let config =
        person_and_script_config(&out, (6, 2000), "route = \"round-robin\"\ndouble_ask = 0.0");
    let run_dir = out.join("run");
    let (mut run, _) = start_run_with(&config, &run_dir, 1, &["--human-query-timeout-ms=500"]);
    let run_arg = format!("--run-dir={}", run_dir.display());
    let pids = crate::experts::processes_with(&["--member=0", &run_arg]);
    assert_eq!(pids.len(), 1, "{pids:?}");
    // Paused for 3 s: without a pause between failed syncs (200 ms each) there would be about
    // 15 of them; with 2 s between, at most 3.
    crate::runtime::signal("STOP", pids[0]);
    std::thread::sleep(Duration::from_secs(3));
    // Not asserted: a run that ended meanwhile has taken the page's process with it.
    let _ = Command::new("kill")
        .args(["-CONT", &pids[0].to_string()])
        .status();
    let o = run.0.take().unwrap().wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let log = std::fs::read_to_string(run_dir.join("expert-1.log")).unwrap();
    let failed = log
        .matches("the person's page did not answer a sync")
        .count();
    assert!((1..=3).contains(&failed), "{failed} failed syncs:\n{log}");
    // The page's process was not started again: paused is not gone.
    assert!(!log.contains("starting it again"), "{log}");
    // The script answered its turns; the person none.
    let demos = std::fs::read_to_string(run_dir.join("demos.jsonl")).unwrap();
    let script = demos.matches("\"expert\":\"cartpole-perfect\"").count();
    assert_eq!((script, demos.lines().count()), (6, 6), "{demos}");
}

/// [`cartpole_config`] (`budget` and `episodes`) with two experts, the person at cost 10 and
/// `cartpole-perfect` at cost 1, `routing` (lines of `[expert]`) between them.
fn person_and_script_config(out: &Path, (budget, episodes): (u32, u32), routing: &str) -> PathBuf {
    let config = cartpole_config(out, budget, episodes);
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace("name = \"cartpole-perfect\"\n", "")
        + routing
        + "\n[[experts]]\nname = \"human\"\ncost = 10\n\
           [[experts]]\nname = \"cartpole-perfect\"\ncost = 1\n";
    std::fs::write(&config, text).unwrap();
    config
}

/// The page's address (`HOST:PORT/TOKEN`) in the run directory's human-page file of the first
/// expert generation, once it is written.
fn page_addr(run_dir: &Path) -> Option<String> {
    let url = std::fs::read_to_string(run_dir.join("human-page-1.txt")).ok()?;
    let url = url.trim();
    let addr = url
        .strip_prefix("http://")
        .and_then(|u| u.strip_suffix('/'))
        .unwrap_or_else(|| panic!("not an address: {url}"));
    Some(addr.to_owned())
}

/// The page's address once the human-page file names another than `old`.
fn new_page_addr(run_dir: &Path, old: &str) -> String {
    let start = Instant::now();
    loop {
        if let Some(addr) = page_addr(run_dir).filter(|a| a != old) {
            return addr;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no new page");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// One HTTP/1.1 request to the page at `addr` (`HOST:PORT/TOKEN`, the page's address without
/// its scheme), `path` under its token; the status and the body.
fn http(addr: &str, method: &str, path: &str, body: Option<&str>) -> (u16, String) {
    let (host, token) = addr
        .split_once('/')
        .expect("the page's address has its token");
    raw_http(host, method, &format!("/{token}{path}"), body)
}

/// One HTTP/1.1 request to `host` with `path` as it is.
fn raw_http(addr: &str, method: &str, path: &str, body: Option<&str>) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    let body = body.unwrap_or("");
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let (head, body) = out.split_once("\r\n\r\n").unwrap();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    (status, body.to_owned())
}

fn state(addr: &str) -> Value {
    let (status, body) = http(addr, "GET", "/state", None);
    assert_eq!(status, 200, "{body}");
    serde_json::from_str(&body).unwrap()
}

/// Polls the page's state until `ok` holds.
fn until(addr: &str, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let start = Instant::now();
    loop {
        let s = state(addr);
        if ok(&s) {
            return s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "never {what}: {s}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The first server-sent event of `GET /events`, parsed.
fn first_event(addr: &str) -> Value {
    let (host, token) = addr
        .split_once('/')
        .expect("the page's address has its token");
    let mut s = TcpStream::connect(host).unwrap();
    write!(
        s,
        "GET /{token}/events HTTP/1.1\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n"
    )
    .unwrap();
    let mut lines = BufReader::new(s).lines();
    let head = lines.next().unwrap().unwrap();
    assert!(head.contains(" 200 "), "{head}");
    for line in lines {
        let line = line.unwrap();
        if let Some(data) = line.strip_prefix("data: ") {
            return serde_json::from_str(data).unwrap();
        }
    }
    panic!("the event stream ended without an event");
}

#[test]
fn a_person_among_several_experts_answers_on_a_page_of_its_own_process_restarted_when_killed() {
    let _time = timed!();
    let out = tmp("human-panel");
    // The person is the best known: each query goes to them, and the same state to the
    // script (a double ask, every time); the person is never asked second.
    let config = person_and_script_config(&out, (4, 3), "route = \"best-known\"\ndouble_ask = 1.0");
    let run_dir = out.join("run");
    let (mut run, mut addr) = start_run_with(&config, &run_dir, 1, &[]);
    // The page is served by a process of its own, as every one of several experts answers.
    let run_arg = format!("--run-dir={}", run_dir.display());
    let page_process = || crate::experts::processes_with(&["--member=0", &run_arg]);
    let mut given = Vec::new();
    for n in 1..=2u64 {
        if n == 2 {
            // Killed between two answers, the page's process is started again on a new
            // address; the query waiting in the expert process is shown there.
            let pids = page_process();
            assert_eq!(pids.len(), 1, "{pids:?}");
            crate::experts::kill(pids[0]);
            addr = new_page_addr(&run_dir, &addr);
            assert!(!page_process().contains(&pids[0]));
        }
        let s = until(&addr, "a query to answer", |s| {
            s["active"] == true
                && s["query"]["id"]
                    .as_u64()
                    .is_some_and(|id| !given.contains(&id))
        });
        let id = s["query"]["id"].as_u64().unwrap();
        let (code, body) = http(
            &addr,
            "POST",
            "/answer",
            Some(&format!("{{\"id\":{id},\"action\":0}}")),
        );
        assert_eq!(code, 202, "{body}");
        given.push(id);
        // The last answer may end the run (and its page) before the page shows it taken:
        // demos.jsonl says so below.
        if n == 1 {
            until(&addr, "the answer taken", |s| s["answered"] == n);
        }
    }
    let child = run.0.take().unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let lines: Vec<Value> = std::fs::read_to_string(run_dir.join("demos.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let who: Vec<(&str, f64, bool)> = lines
        .iter()
        .map(|l| {
            let (e, c, d) = (&l["expert"], &l["cost"], &l["double_asked"]);
            (
                e.as_str().unwrap(),
                c.as_f64().unwrap(),
                d.as_bool().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        who,
        [
            ("human", 10.0, true),
            ("cartpole-perfect", 1.0, true),
            ("human", 10.0, true),
            ("cartpole-perfect", 1.0, true)
        ]
    );
    // The person's answers are their action; each second answer is on the same state.
    assert!(lines.iter().step_by(2).all(|l| l["action"] == 0));
    assert!(lines.chunks(2).all(|p| p[0]["state"] == p[1]["state"]));
    let qualities = std::fs::read_to_string(run_dir.join("experts.csv")).unwrap();
    assert_eq!(qualities.lines().count(), 5, "{qualities}");
    let log = std::fs::read_to_string(run_dir.join("adapter-expert-1-0.log")).unwrap();
    assert_eq!(
        log.matches("the person's page is served").count(),
        2,
        "{log}"
    );
    let log = std::fs::read_to_string(run_dir.join("expert-1.log")).unwrap();
    assert!(
        log.contains("the person's page's process ended: starting it again"),
        "{log}"
    );
    crate::runtime::check_run_dir(&run_dir, 4);
}

#[test]
fn a_person_answers_and_declines_over_http_and_only_answers_spend_budget() {
    let _time = timed!();
    let out = tmp("human-http");
    let config = cartpole_config(&out, 2, 4);
    let run_dir = out.join("run");
    let (mut run, addr) = start_run(&config, &run_dir, 2);

    // The page itself, and its live state as events.
    let (status, page) = http(&addr, "GET", "/", None);
    assert!(status == 200 && page.contains("EventSource"), "{page}");
    // Only at its token: without it, or with another, every path is refused.
    let (host, token) = addr.split_once('/').unwrap();
    assert_eq!(token.len(), 32, "{addr}");
    for path in [
        "/",
        "/state",
        "/events",
        "/0123456789abcdef0123456789abcdef/state",
    ] {
        assert_eq!(raw_http(host, "GET", path, None).0, 403, "GET {path}");
    }
    assert_eq!(
        raw_http(host, "POST", "/answer", Some("{\"id\":0,\"action\":0}")).0,
        403
    );
    // The address with its token is readable by its owner only.
    use std::os::unix::fs::PermissionsExt as _;
    let mode = std::fs::metadata(run_dir.join("human-page-1.txt"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o600);
    let event = first_event(&addr);
    assert_eq!(event["env"], "cartpole");
    assert_eq!(
        event["actions"],
        serde_json::json!(["push left", "push right"])
    );

    // Both actors ask on their first step and wait for the person (minutes by default).
    let s = until(&addr, "two queries waiting", |s| {
        s["active"] == true && s["waiting"] == 2
    });
    assert_eq!(
        (s["budget_left"].as_u64(), s["budget_total"].as_u64()),
        (Some(2), Some(2))
    );
    let first = s["query"]["id"].as_u64().unwrap();
    assert_eq!(s["query"]["state"].as_array().unwrap().len(), 4);

    // A bad answer is refused with a reason, and changes nothing.
    let (code, body) = http(
        &addr,
        "POST",
        "/answer",
        Some(&format!("{{\"id\":{first},\"action\":2}}")),
    );
    assert_eq!(code, 400, "{body}");
    assert!(body.contains("not one of the 2 actions"), "{body}");
    let (code, _) = http(&addr, "POST", "/decline", Some("{\"id\":999}"));
    assert_eq!(code, 409);

    // Declined: no budget spent, nothing written; that actor asks again (its next step).
    let (code, body) = http(
        &addr,
        "POST",
        "/decline",
        Some(&format!("{{\"id\":{first}}}")),
    );
    assert_eq!(code, 202, "{body}");
    let s = until(&addr, "the decline taken", |s| {
        s["declined"] == 1 && s["waiting"] == 2
    });
    assert_eq!(s["budget_left"], 2);
    assert_eq!(s["demos"], 0);
    assert_eq!(
        std::fs::read_to_string(run_dir.join("demos.jsonl")).unwrap_or_default(),
        ""
    );

    // Two answers: each a demonstration in demos.jsonl with the person's action and name.
    let mut given = Vec::new();
    for (n, action) in [(1u64, 0u64), (2, 1)] {
        let s = until(&addr, "a query to answer", |s| {
            s["query"]["id"]
                .as_u64()
                .is_some_and(|id| !given.iter().any(|(g, _, _)| *g == id) && id != first)
        });
        let q = s["query"].clone();
        let id = q["id"].as_u64().unwrap();
        let (code, body) = http(
            &addr,
            "POST",
            "/answer",
            Some(&format!("{{\"id\":{id},\"action\":{action}}}")),
        );
        assert_eq!(code, 202, "{body}");
        given.push((id, action, q["state"].clone()));
        until(&addr, "the answer taken", |s| s["answered"] == n);
    }
    // The budget is spent: the other queries are answered "budget exhausted", the run ends.
    let child = run.0.take().unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains(&format!(
            "you are the expert: answer the queries at http://{addr}/"
        )),
        "{stderr}"
    );
    let demos = alfd_demonstrators::demo_log::read(&run_dir.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 2);
    for (d, (_, action, shown)) in demos.iter().zip(&given) {
        assert_eq!(d.expert, "human");
        assert_eq!(d.action as u64, *action);
        let shown: Vec<f64> = shown
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(d.state.len(), 4);
        for (a, b) in d.state.iter().zip(&shown) {
            assert!((a - b).abs() < 1e-6, "{:?} vs {shown:?}", d.state);
        }
    }
    // The actors got the answers (not timeouts): the demonstrations are theirs in the summary.
    let summary = crate::runtime::summary(&run_dir);
    assert_eq!(summary["demos"], 2, "{summary}");
    for a in 0..2 {
        let log = std::fs::read_to_string(run_dir.join(format!("actor-{a}.log"))).unwrap();
        assert!(!log.contains("did not answer in time"), "{log}");
    }
    crate::runtime::check_run_dir(&run_dir, 2);
}

/// Chromium from Debian's packages, if installed.
fn chromium() -> Option<PathBuf> {
    let p = PathBuf::from(
        std::env::var_os("ALFD_CHROMIUM").unwrap_or_else(|| "/usr/bin/chromium".into()),
    );
    p.is_file().then_some(p)
}

/// Playwright (`playwright-core`, pinned in deploy/cli/tests/browser/package.json), installed with
/// `npm ci` on first use; the error says why it cannot be.
pub(crate) fn browser_driver() -> Result<PathBuf, String> {
    // One install at a time (the browser tests run in parallel).
    static INSTALL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = INSTALL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = repo().join("deploy/cli/tests/browser");
    if !dir.join("node_modules/playwright-core").is_dir() {
        let status = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--silent"])
            .current_dir(&dir)
            .status()
            .map_err(|e| format!("npm cannot run: {e}"))?;
        if !status.success() {
            return Err(format!("npm install failed ({status})"));
        }
    }
    Ok(dir.join("drive.mjs"))
}

/// The browser and its driver; `None` only when Chromium is not installed (said loudly), and a
/// failure then when `CI` is set: a test that did not run does not pass there.
pub(crate) fn browser() -> Option<PathBuf> {
    if chromium().is_none() {
        assert!(
            !crate::support::under_ci(),
            "no Chromium at /usr/bin/chromium (apt-get install -y chromium, or set ALFD_CHROMIUM): \
             the human page's browser test cannot run, and CI is set"
        );
        eprintln!(
            "\n*** SKIPPED: no Chromium at /usr/bin/chromium (apt-get install -y chromium, or set \
             ALFD_CHROMIUM); the human page's browser test did not run ***\n"
        );
        return None;
    }
    Some(browser_driver().unwrap_or_else(|e| panic!("the browser driver: {e}")))
}

/// Where a screenshot goes: `docs/` with `ALFD_UPDATE_SCREENSHOTS=1`, else `dir`.
pub(crate) fn screenshot(dir: &Path, name: &str) -> PathBuf {
    if std::env::var_os("ALFD_UPDATE_SCREENSHOTS").is_some() {
        repo().join("docs").join(name)
    } else {
        dir.join(name)
    }
}

/// Runs the driver over the page at `url`; its JSON report.
fn drive(driver: &Path, url: &str, shot: &Path, steps: &[&str]) -> std::process::Child {
    Command::new("node")
        .arg(driver)
        .arg(url)
        .arg(shot)
        .args(steps)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("node runs")
}

fn report(o: &std::process::Output) -> Value {
    assert!(o.status.success(), "{}", text(o));
    serde_json::from_str(String::from_utf8_lossy(&o.stdout).trim()).unwrap()
}

#[test]
fn in_chromium_a_person_sees_cartpole_declines_one_query_and_clicks_an_action() {
    let _time = timed!();
    let Some(driver) = browser() else { return };
    let out = tmp("human-browser");
    let config = cartpole_config(&out, 1, 2);
    let run_dir = out.join("run");
    let (run, addr) = start_run(&config, &run_dir, 1);
    let shot = screenshot(&out, "human-cartpole.png");
    let o = drive(
        &driver,
        &format!("http://{addr}/"),
        &shot,
        &["decline", "click:1"],
    )
    .wait_with_output()
    .unwrap();
    let r = report(&o);
    let seen = r["seen"].as_array().unwrap();
    // The browser saw the cart and the pole, the budget and the queries waiting.
    for s in seen {
        assert_eq!(s["pole"], true, "{s}");
        assert_eq!(s["waiting"], "1", "{s}");
        assert_eq!(s["budget"], "1 / 1", "{s}");
        assert!(
            s["status"].as_str().unwrap().contains("actor 0 asks"),
            "{s}"
        );
    }
    assert!(shot.is_file());
    let mut child = run;
    let o = child.0.take().unwrap().wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    // The decline spent nothing; the click is the one demonstration, with the person's name.
    let demos = alfd_demonstrators::demo_log::read(&run_dir.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 1);
    assert_eq!((demos[0].action, demos[0].expert.as_str()), (1, "human"));
    let clicked: Vec<f64> = seen[1]["state"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(demos[0]
        .state
        .iter()
        .zip(&clicked)
        .all(|(a, b)| (a - b).abs() < 1e-6));
    assert_eq!(r["after"]["declined"], 1);
    assert_eq!(crate::runtime::summary(&run_dir)["demos"], 1);
}

#[test]
fn in_chromium_the_cliffwalk_page_shows_the_grid_and_takes_an_arrow_key() {
    let _time = timed!();
    let Some(driver) = browser() else { return };
    let out = tmp("human-cliffwalk");
    // The page alone (`alfd run` plays vector environments): the expert process's page as it
    // shows a CliffWalk state: the agent just above the cliff, third column.
    let page = HumanPage::start(
        0,
        PageState {
            env: "cliffwalk".into(),
            actions: action_labels("cliffwalk", 4),
            active: true,
            budget_total: 10,
            budget_left: 7,
            demos: 3,
            waiting: 0,
            query: None,
            answered: 0,
            declined: 0,
            version: 0,
        },
    )
    .unwrap();
    let query = ShownQuery {
        id: 1,
        actor: 0,
        step: 42,
        state: vec![26.0],
    };
    page.set_waiting(&[
        query.clone(),
        ShownQuery {
            id: 2,
            ..query.clone()
        },
    ]);
    let shot = screenshot(&out, "human-cliffwalk.png");
    let mut node = drive(&driver, &page.url(), &shot, &["key:ArrowUp"]);
    let mut decisions = Vec::new();
    while node.try_wait().unwrap().is_none() {
        for d in page.decisions() {
            decisions.push(d);
            page.set_waiting(&[ShownQuery {
                id: 2,
                ..query.clone()
            }]);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let r = report(&node.wait_with_output().unwrap());
    assert_eq!(
        decisions,
        vec![alfd_expert::human::Decision {
            id: 1,
            action: Some(0)
        }]
    );
    let s = &r["seen"][0];
    assert_eq!(
        (s["agent"].as_bool(), s["pole"].as_bool()),
        (Some(true), Some(false))
    );
    assert_eq!(s["budget"], "7 / 10");
    assert_eq!(s["waiting"], "2");
    assert_eq!(s["buttons"][0], "up (0)");
    assert!(shot.is_file());
}

/// A person far slower than the actor waits (300 ms): the page stops showing a query its actor
/// gave up, a click on it afterwards is refused with 409 and records nothing, and the run ends
/// with no demonstration and nothing refused.
#[test]
fn a_persons_click_after_the_actor_stopped_waiting_is_refused_and_records_nothing() {
    let _time = timed!();
    let out = tmp("human-late");
    let config = cartpole_config(&out, 2, 3);
    let run_dir = out.join("run");
    let (mut run, addr) = start_run_with(
        &config,
        &run_dir,
        1,
        &["--expert=human", "--human-query-timeout-ms=300"],
    );
    let s = until(&addr, "a query", |s| s["waiting"] == 1);
    let old = s["query"]["id"].as_u64().unwrap();
    // The actor gives up after 300 ms and asks again on a later step: another query is shown.
    until(&addr, "the first query given up", |s| {
        s["query"]["id"].as_u64().is_some_and(|id| id != old)
    });
    let (code, body) = http(
        &addr,
        "POST",
        "/answer",
        Some(&format!("{{\"id\":{old},\"action\":1}}")),
    );
    assert_eq!(code, 409, "{body}");
    assert!(body.contains("given up"), "{body}");
    let s = state(&addr);
    assert_eq!(
        (s["answered"].as_u64(), s["budget_left"].as_u64()),
        (Some(0), Some(2))
    );
    let o = run.0.take().unwrap().wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let summary = crate::runtime::summary(&run_dir);
    assert_eq!(summary["demos"], 0, "{summary}");
    assert_eq!(summary["demos_refused"], 0, "{summary}");
    assert_eq!(summary["demos_experts_wrote"], 0, "{summary}");
    assert_eq!(
        std::fs::read_to_string(run_dir.join("demos.jsonl")).unwrap_or_default(),
        ""
    );
    crate::runtime::check_run_dir(&run_dir, 1);
}

#[test]
fn swap_expert_goes_from_a_built_in_expert_to_a_person_and_back() {
    let _time = timed!();
    let out = tmp("human-swap");
    let demos = || alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap_or_default();
    // CartPole's built-in expert, asked on every step (a budget that lasts).
    let mut run = Background(Some(
        alfd()
            .args(["run", "--quiet", "--actors=1", "--query-timeout-ms=5000"])
            .arg(format!("--out={}", out.display()))
            .arg(format!(
                "--config={}",
                cartpole_config(&out, 100_000, 1_000_000).display()
            ))
            .args(["--set", "expert.model=none"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let swap = |to: &str, generation: u64| {
        let o = alfd()
            .args(["swap-expert", "--run"])
            .arg(&*out)
            .args(["--expert", to])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        let r: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(
            (r["ok"].as_bool(), r["generation"].as_u64()),
            (Some(true), Some(generation))
        );
    };
    crate::runtime::wait_until(&mut run, "built-in demonstrations", || demos().len() >= 10);
    swap("human", 2);
    let url = std::fs::read_to_string(out.join("human-page-2.txt")).unwrap();
    let addr = url
        .trim()
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();
    // The person answers one query (a query the actor asked before the person's model reached
    // it may be given up at its short timeout: then the next one is answered).
    loop {
        let s = until(&addr, "a query", |s| {
            s["active"] == true && s["waiting"] == 1
        });
        let id = s["query"]["id"].as_u64().unwrap();
        let (code, _) = http(
            &addr,
            "POST",
            "/answer",
            Some(&format!("{{\"id\":{id},\"action\":0}}")),
        );
        let s = until(&addr, "the answer taken or the query gone", |s| {
            s["answered"] == 1 || s["query"]["id"].as_u64() != Some(id)
        });
        if code == 202 && s["answered"] == 1 {
            break;
        }
    }
    // The actor now waits on the person again; a swap away releases it at once.
    until(&addr, "the next query", |s| s["waiting"] == 1);
    swap("cartpole-perfect", 3);
    let before = demos().len();
    crate::runtime::wait_until(&mut run, "built-in demonstrations again", || {
        demos().len() >= before + 10
    });
    let o = crate::runtime::interrupt(run);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let demos = demos();
    let segments: Vec<&str> =
        demos
            .iter()
            .map(|d| d.expert.as_str())
            .fold(Vec::new(), |mut v, e| {
                if v.last() != Some(&e) {
                    v.push(e);
                }
                v
            });
    assert_eq!(segments, ["cartpole-perfect", "human", "cartpole-perfect"]);
    let human: Vec<_> = demos.iter().filter(|d| d.expert == "human").collect();
    assert_eq!((human.len(), human[0].action), (1, 0));
    for (i, d) in demos.iter().enumerate() {
        assert_eq!(d.index as usize, i, "no demonstration lost or repeated");
    }
    assert_eq!(crate::runtime::summary(&out)["demos"], demos.len());
}

#[test]
fn a_human_page_port_in_use_is_refused_with_exit_code_2() {
    let _time = timed!();
    let out = tmp("human-port");
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = held.local_addr().unwrap().port();
    let o = alfd()
        .args(["run", "--quiet", "--expert=human"])
        .arg(format!("--human-port={port}"))
        .arg(format!(
            "--config={}",
            cartpole_config(&out, 1, 1).display()
        ))
        .arg(format!("--out={}", out.join("run").display()))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains(&format!(
            "--human-port {port}: cannot serve the human expert's page"
        )),
        "{stderr}"
    );
    // `alfd local` has no expert process to serve the page: said so.
    let o = alfd()
        .args(["local", "--set=expert.name=human"])
        .arg(format!(
            "--config={}",
            cartpole_config(&out, 1, 1).display()
        ))
        .arg(format!("--out={}", out.join("local").display()))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}
