//! Run housekeeping: the files a run leaves in the system,
//! and the removal of what dead processes and finished runs leave behind.

use std::path::PathBuf;

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

use crate::connection::{run_config, run_prefix, validate_run_id, Transport};
use crate::error::{transport, Result, WireError};

/// Files of run `run_id` left in iceoryx2's directories (`/tmp/iceoryx2`, `/dev/shm`). Empty once
/// every process of the run has exited cleanly.
pub fn leftover_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = run_prefix(run_id);
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/tmp/iceoryx2"), PathBuf::from("/dev/shm")];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
            if entry.file_name().to_string_lossy().starts_with(&prefix) {
                found.push(path);
            } else if is_dir {
                stack.push(path);
            }
        }
    }
    found.sort();
    found
}

/// Removes the resources of dead processes of run `run_id` (killed with SIGKILL, say); returns
/// the names of the nodes it removed.
pub fn cleanup_dead_nodes(run_id: &str) -> Result<Vec<String>> {
    let cfg = run_config(run_id)?;
    let mut dead = Vec::new();
    Node::<Transport>::list(&cfg, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(transport("list the nodes of", run_id))?;
    let mut removed = Vec::new();
    for view in dead {
        let name = view
            .details()
            .as_ref()
            .map(|d| d.name().to_string())
            .unwrap_or_else(|| "?".to_owned());
        if view.try_remove_stale_resources().is_ok() {
            removed.push(name);
        }
    }
    Ok(removed)
}

/// Names of the nodes of run `run_id` whose process is alive.
pub fn alive_nodes(run_id: &str) -> Result<Vec<String>> {
    let cfg = run_config(run_id)?;
    let mut alive = Vec::new();
    Node::<Transport>::list(&cfg, |state| {
        if let NodeState::Alive(view) = state {
            alive.push(
                view.details()
                    .as_ref()
                    .map(|d| d.name().to_string())
                    .unwrap_or_else(|| "?".to_owned()),
            );
        }
        CallbackProgression::Continue
    })
    .map_err(transport("list the nodes of", run_id))?;
    Ok(alive)
}

/// Waits (polling every 50 ms, at most `timeout`) until no process of run `run_id` is alive;
/// returns the nodes still alive then (empty: the run has ended).
pub fn wait_for_run_end(run_id: &str, timeout: std::time::Duration) -> Result<Vec<String>> {
    let start = std::time::Instant::now();
    loop {
        let alive = alive_nodes(run_id)?;
        if alive.is_empty() || start.elapsed() >= timeout {
            return Ok(alive);
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Removes what run `run_id` left in the system after its last process exited: the resources of
/// dead nodes, and the run's node counter (a persistent segment iceoryx2 keeps per prefix).
/// Refuses while a node of the run is alive (including one of the calling process), and never
/// touches another run, even one whose id starts with this one's.
///
/// iceoryx2 0.10 creates the node counter without an owner, so no node removes it, and offers
/// no public way to: the dead-node clean-up above (`Node::list`, `DeadNodeView`) leaves it, and
/// `Node::force_remove_service` removes services only. It is POSIX shared memory named
/// `<prefix><40 hex digits>_node.<version>.global_mgmt` (`/dev/shm`), used only while a node is
/// created; `node_counters` finds it by that exact form, so never another run's, even one whose
/// id starts with this one's (the part after this run's prefix would hold a `_` or a non-hex
/// letter). A test checks that no file of a closed run is left.
pub fn close_run(run_id: &str) -> Result<()> {
    validate_run_id(run_id)?;
    cleanup_dead_nodes(run_id)?;
    let alive = alive_nodes(run_id)?;
    if !alive.is_empty() {
        return Err(WireError::RunAlive {
            run_id: run_id.to_owned(),
            nodes: alive.join(", "),
        });
    }
    for counter in node_counters(run_id) {
        match std::fs::remove_file(&counter) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(WireError::Transport {
                    op: "remove the node counter of",
                    service: format!("{run_id} ({})", counter.display()),
                    detail: e.to_string(),
                })
            }
        }
    }
    Ok(())
}

/// The node counters of run `run_id` in `/dev/shm` (see [`close_run`]).
fn node_counters(run_id: &str) -> Vec<PathBuf> {
    let prefix = run_prefix(run_id);
    let is_counter = |name: &str| {
        let Some(rest) = name.strip_prefix(&prefix) else {
            return false;
        };
        let Some((hash, tail)) = rest.split_once("_node.") else {
            return false;
        };
        hash.len() == 40
            && hash.bytes().all(|b| b.is_ascii_hexdigit())
            && tail.ends_with(".global_mgmt")
            && !tail.contains('/')
    };
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return Vec::new();
    };
    let mut found: Vec<PathBuf> = entries
        .flatten()
        .filter(|e| is_counter(&e.file_name().to_string_lossy()))
        .map(|e| e.path())
        .collect();
    found.sort();
    found
}

/// Whether `run_id` has the form the launcher gives run ids, `r<unix seconds>-<pid>` (such an
/// id holds no `_`, so its file prefix is no other run's).
pub fn is_launcher_run_id(run_id: &str) -> bool {
    has_id_form(run_id, 'r')
}

/// The process that made run `run_id` (`alfd run` or `alfd resume`, or `alfd join`: the pid in
/// its id), if it is alive: such a run is live even before (or between) its nodes are up, so that
/// `alfd clean` never takes the files of a run that is starting.
pub fn owner_alive(run_id: &str) -> Option<u32> {
    if !is_alfd_run_id(run_id) {
        return None;
    }
    let pid: u32 = run_id.rsplit_once('-')?.1.parse().ok()?;
    // A pid of a dead launcher that another program took is not the run's.
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
    let program = cmdline.split(|&b| b == 0).next().unwrap_or_default();
    String::from_utf8_lossy(program)
        .rsplit('/')
        .next()
        .is_some_and(|name| name == "alfd")
        .then_some(pid)
}

/// `<letter><unix seconds>-<pid>`.
fn has_id_form(run_id: &str, letter: char) -> bool {
    let Some((secs, pid)) = run_id.strip_prefix(letter).and_then(|r| r.split_once('-')) else {
        return false;
    };
    let digits = |t: &str| !t.is_empty() && t.len() <= 20 && t.bytes().all(|b| b.is_ascii_digit());
    digits(secs) && digits(pid)
}

/// Whether `run_id` is one `alfd clean` looks at: a launcher's run ([`is_launcher_run_id`]) or
/// the local copy of a run's services that `alfd join` makes for its actors (`j<secs>-<pid>`)
/// or its expert (`k<secs>-<pid>`), which a host killed with SIGKILL leaves behind.
pub fn is_alfd_run_id(run_id: &str) -> bool {
    ['r', 'j', 'k'].into_iter().any(|l| has_id_form(run_id, l))
}

/// The runs of alfd (see [`is_alfd_run_id`]) that have files in iceoryx2's directories, live or
/// not, sorted.
pub fn runs_with_files() -> Vec<String> {
    let mut runs = std::collections::BTreeSet::new();
    let mut stack = vec![PathBuf::from("/tmp/iceoryx2"), PathBuf::from("/dev/shm")];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(id) = name
                .strip_prefix("alfd_")
                .and_then(|rest| rest.split_once('_'))
                .map(|(id, _)| id)
                .filter(|id| is_alfd_run_id(id))
            {
                runs.insert(id.to_owned());
            } else if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(entry.path());
            }
        }
    }
    runs.into_iter().collect()
}

/// What [`clean_run`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cleaned {
    /// A process of the run is alive: nothing was touched. Its nodes' names.
    Live(Vec<String>),
    /// The run is dead: these files of it were removed.
    Removed(Vec<PathBuf>),
}

/// Removes everything a dead run left in iceoryx2's directories (a run whose launcher was
/// killed, say): the dead nodes' resources, the node counter, and whatever file of the run is
/// still there. A run with a live process, or whose launcher ([`owner_alive`]) lives, is left
/// alone.
pub fn clean_run(run_id: &str) -> Result<Cleaned> {
    validate_run_id(run_id)?;
    if let Some(pid) = owner_alive(run_id) {
        return Ok(Cleaned::Live(vec![format!("its launcher, pid {pid}")]));
    }
    close_dead_run(run_id)
}

/// What [`clean_run`] does once the run's launcher is gone, for the launcher itself as it ends
/// (its children are gone, its own node dropped): unless a process of the run is alive, the
/// dead nodes' resources, the node counter, and every other file of the run are removed. The
/// last include what a process killed while it created its node leaves: a node monitor without
/// the node's details, which iceoryx2's list of nodes does not report as dead.
pub fn close_dead_run(run_id: &str) -> Result<Cleaned> {
    validate_run_id(run_id)?;
    let alive = alive_nodes(run_id)?;
    if !alive.is_empty() {
        return Ok(Cleaned::Live(alive));
    }
    let before = leftover_files(run_id);
    match close_run(run_id) {
        Ok(()) => {}
        // A process of the run came up meanwhile: leave it.
        Err(WireError::RunAlive { nodes, .. }) => return Ok(Cleaned::Live(vec![nodes])),
        // Otherwise its files are removed one by one below.
        Err(_) => {}
    }
    for path in leftover_files(run_id) {
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        if let Err(e) = removed {
            if e.kind() != std::io::ErrorKind::NotFound {
                return Err(WireError::Transport {
                    op: "remove a file of",
                    service: format!("{run_id} ({})", path.display()),
                    detail: e.to_string(),
                });
            }
        }
    }
    Ok(Cleaned::Removed(before))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use crate::test_support::{run_id, wire};
    use crate::*;

    /// A control message goes from `tx` to `rx` (the newest `rx` holds): the run still works.
    fn control_round_trip(tx: &mut Sender<'_, Control>, rx: &Receiver<'_, Control>, expert: u32) {
        tx.send(Control {
            command: command::RUN,
            active_expert: expert,
            ..Control::default()
        })
        .unwrap();
        assert_eq!(rx.latest().unwrap().unwrap().active_expert, expert);
    }

    /// The files `leftover_files` reports for a run, each checked to exist.
    fn existing_files(run: &str) -> Vec<PathBuf> {
        let files = leftover_files(run);
        assert!(files.iter().all(|p| p.exists()), "{files:?}");
        files
    }

    #[test]
    fn a_run_whose_launcher_lives_is_live_whatever_its_nodes() {
        // This test binary is not an alfd program: its pid names no live run.
        let me = std::process::id();
        assert_eq!(owner_alive(&format!("r1796205976-{me}")), None);
        assert_eq!(owner_alive("test-live"), None);
        // A live program named alfd: the run of its pid is live, and `clean_run` leaves it.
        let dir = tempfile::tempdir().unwrap();
        let program = dir.path().join("alfd");
        std::fs::copy("/bin/sleep", &program).unwrap();
        let mut child = std::process::Command::new(&program)
            .arg("30")
            .spawn()
            .unwrap();
        let id = format!("r1796205976-{}", child.id());
        // Until its exec, the child is a copy of this test binary.
        let start = std::time::Instant::now();
        while owner_alive(&id).is_none() && start.elapsed() < std::time::Duration::from_secs(5) {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert_eq!(owner_alive(&id), Some(child.id()));
        assert!(matches!(clean_run(&id).unwrap(), Cleaned::Live(_)));
        child.kill().unwrap();
        child.wait().unwrap();
        assert_eq!(owner_alive(&id), None);
        assert_eq!(clean_run(&id).unwrap(), Cleaned::Removed(Vec::new()));
    }

    #[test]
    fn alfd_clean_looks_at_launcher_runs_and_the_copies_joined_hosts_make() {
        for id in [
            "r1796205976-30847",
            "j1796205976-30847",
            "k1796205976-30847",
        ] {
            assert!(is_alfd_run_id(id), "{id}");
        }
        assert!(is_launcher_run_id("r1-2") && !is_launcher_run_id("j1-2"));
        for id in ["x1-2", "j1_2", "j-2", "j1-", "jj1-2", "r1-2_x", "test-live"] {
            assert!(!is_alfd_run_id(id), "{id}");
        }
    }

    #[test]
    fn closing_or_cleaning_another_run_leaves_a_live_run_alone() {
        // Besides the live run, a finished run whose id the live run's extends, and one whose id
        // extends the live run's: their file prefixes (`alfd_<id>_`) start one another.
        let shorter = run_id("live");
        let live = format!("{shorter}_y");
        let longer = format!("{live}_z");
        assert!(run_prefix(&live).starts_with(&run_prefix(&shorter)));
        assert!(run_prefix(&longer).starts_with(&run_prefix(&live)));
        let launcher = wire(&live, Role::Launcher, 0);
        let actor = wire(&live, Role::Actor, 0);
        let mut tx = launcher.control_sender().unwrap();
        let rx = actor.control_receiver().unwrap();
        control_round_trip(&mut tx, &rx, 1);
        let before = existing_files(&live);
        assert!(!before.is_empty(), "a live run has files");

        for other in [&longer, &shorter] {
            drop(wire(other, Role::Launcher, 0));
            assert_eq!(alive_nodes(other).unwrap(), Vec::<String>::new());
            assert_eq!(cleanup_dead_nodes(other).unwrap(), Vec::<String>::new());
            close_run(other).unwrap();
            // `leftover_files` matches names by prefix, so the shorter id's list shows the live
            // run's files: they must be all it shows.
            assert!(
                existing_files(other)
                    .iter()
                    .all(|p| p.to_string_lossy().contains(&run_prefix(&live))),
                "closing `{other}` left its own files"
            );
        }
        assert_eq!(cleanup_dead_nodes(&live).unwrap(), Vec::<String>::new());
        assert_eq!(launcher.cleanup_dead_nodes(), 0);

        let after = existing_files(&live);
        assert!(
            before.iter().all(|p| after.contains(p)),
            "a live run lost files: before {before:?}, after {after:?}"
        );
        assert_eq!(alive_nodes(&live).unwrap().len(), 2);
        control_round_trip(&mut tx, &rx, 2);
        // A process joining later still finds the run's services.
        let late = wire(&live, Role::Actor, 1);
        let late_rx = late.control_receiver().unwrap();
        control_round_trip(&mut tx, &late_rx, 3);

        drop((tx, rx, late_rx));
        drop((late, actor, launcher));
        close_run(&live).unwrap();
        assert_eq!(leftover_files(&live), Vec::<PathBuf>::new());
    }

    #[test]
    fn closing_a_live_run_is_refused_and_removes_nothing() {
        let run = run_id("close-live");
        let launcher = wire(&run, Role::Launcher, 0);
        let learner = wire(&run, Role::Learner, 0);
        let mut tx = launcher.control_sender().unwrap();
        let rx = learner.control_receiver().unwrap();
        control_round_trip(&mut tx, &rx, 1);
        let before = existing_files(&run);

        match close_run(&run) {
            Err(WireError::RunAlive { run_id, nodes }) => {
                assert_eq!(run_id, run);
                assert!(
                    nodes.contains("launcher") && nodes.contains("learner"),
                    "{nodes}"
                );
            }
            other => panic!("close_run of a live run: {other:?}"),
        }
        assert_eq!(
            existing_files(&run),
            before,
            "a refused close removed files"
        );
        control_round_trip(&mut tx, &rx, 2);
        // The node counter survived: another process still joins.
        let late = wire(&run, Role::Actor, 0);
        control_round_trip(&mut tx, &late.control_receiver().unwrap(), 3);

        drop((tx, rx));
        drop((late, learner));
        let refused = close_run(&run);
        assert!(
            matches!(&refused, Err(WireError::RunAlive { nodes, .. }) if nodes == "launcher"),
            "one live node is enough to refuse: {refused:?}"
        );
        drop(launcher);
        close_run(&run).unwrap();
        assert_eq!(leftover_files(&run), Vec::<PathBuf>::new());
    }

    #[test]
    fn two_runs_do_not_see_each_other_and_leave_nothing_behind() {
        let run_a = run_id("iso-a");
        let run_b = run_id("iso-b");
        {
            let a_launcher = wire(&run_a, Role::Launcher, 0);
            let b_launcher = wire(&run_b, Role::Launcher, 0);
            let a_actor = wire(&run_a, Role::Actor, 0);
            let b_actor = wire(&run_b, Role::Actor, 0);
            let mut a_tx = a_launcher.control_sender().unwrap();
            let mut b_tx = b_launcher.control_sender().unwrap();
            let a_rx = a_actor.control_receiver().unwrap();
            let b_rx = b_actor.control_receiver().unwrap();
            a_tx.send(Control {
                command: command::SHUTDOWN,
                ..Control::default()
            })
            .unwrap();
            assert_eq!(a_rx.receive().unwrap().unwrap().command, command::SHUTDOWN);
            assert!(
                b_rx.receive().unwrap().is_none(),
                "run b saw run a's control"
            );
            b_tx.send(Control {
                command: command::RUN,
                active_expert: 4,
                ..Control::default()
            })
            .unwrap();
            assert!(a_rx.receive().unwrap().is_none());
            assert_eq!(b_rx.receive().unwrap().unwrap().active_expert, 4);
            assert!(!leftover_files(&run_a).is_empty(), "a live run has files");
            assert!(leftover_files(&run_a)
                .iter()
                .all(|p| p.to_string_lossy().contains(&run_prefix(&run_a))));
            assert!(matches!(close_run(&run_a), Err(WireError::RunAlive { .. })));
            assert_eq!(alive_nodes(&run_b).unwrap().len(), 2);
        }
        assert_eq!(cleanup_dead_nodes(&run_a).unwrap(), Vec::<String>::new());
        assert_eq!(alive_nodes(&run_a).unwrap(), Vec::<String>::new());
        close_run(&run_a).unwrap();
        close_run(&run_b).unwrap();
        assert_eq!(leftover_files(&run_a), Vec::<std::path::PathBuf>::new());
        assert_eq!(leftover_files(&run_b), Vec::<std::path::PathBuf>::new());
    }

    #[test]
    fn a_finished_run_is_closed_with_what_a_node_killed_while_starting_left() {
        let run = run_id("half-node");
        drop(wire(&run, Role::Launcher, 0));
        // What a process killed inside iceoryx2's node creation leaves: a node monitor and a
        // port tag, without the node's details; the list of nodes reports no such node.
        let nodes = std::path::Path::new("/tmp/iceoryx2/nodes");
        std::fs::create_dir_all(nodes.join("4242")).unwrap();
        let monitor = nodes.join(format!("{}4242.node_monitor", run_prefix(&run)));
        let tag = nodes.join(format!("4242/{}77.port_tag", run_prefix(&run)));
        std::fs::write(&monitor, b"").unwrap();
        std::fs::write(&tag, b"").unwrap();
        assert_eq!(alive_nodes(&run).unwrap(), Vec::<String>::new());
        close_run(&run).unwrap();
        assert!(monitor.exists() && tag.exists(), "close_run leaves them");
        match close_dead_run(&run).unwrap() {
            Cleaned::Removed(files) => assert!(files.contains(&monitor) && files.contains(&tag)),
            other => panic!("{other:?}"),
        }
        assert_eq!(leftover_files(&run), Vec::<PathBuf>::new());
        // A run with a live process is left alone.
        let live = run_id("half-node-live");
        let _launcher = wire(&live, Role::Launcher, 0);
        let before = leftover_files(&live);
        assert!(matches!(close_dead_run(&live).unwrap(), Cleaned::Live(_)));
        assert_eq!(leftover_files(&live), before);
    }

    #[test]
    fn run_ids_are_checked() {
        assert!(validate_run_id("20250101-120000_ab12").is_ok());
        for bad in ["", "a/b", "a b", "ü", &"x".repeat(65)] {
            assert_eq!(
                validate_run_id(bad),
                Err(WireError::InvalidRunId(bad.to_owned()))
            );
        }
        assert!(Wire::connect("bad/id", Process::new(Role::Tool, 0), SCHEMA_VERSION).is_err());
    }
}
