//! A person among several experts, on a page served by a process of its own
//! (`alfd-expert --member I` for the `human` of `[[experts]]`), and the expert process's side of
//! it. The page's process serves the page, writes its address to the run directory's
//! human-page file, and answers each sync from the expert process at once with the person's
//! oldest decision not yet delivered (see `human::link`). The expert process supervises it as it
//! does every member: a page process that has ended is started again (a new address in the
//! human-page file) under the run's restart rule.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use alfd_common::restarts::{GiveUp, Restarts};
use alfd_harness::python::Adapter;
use alfd_harness::{BadInput, HarnessError};
use alfd_wire::{Process, RemoteClient, RemoteServer};
use tracing::{info, warn};

use crate::human::link::{self, PageSync, MAX_SHOWN_STATE};
use crate::human::{self, Decision, HumanPage, PageState, ShownQuery};
use crate::Args;

/// How long one wait for a sync lasts: how soon a gone parent is noticed.
const POLL: Duration = Duration::from_millis(200);

/// How often the expert process syncs with the page when nothing changed (a change is sent at
/// once): how soon a person's decision arrives.
pub const SYNC_EVERY: Duration = Duration::from_millis(50);

/// Serves the page of the person at place `member` of `[[experts]]` until a signal or the end
/// of its parent.
pub fn serve(args: &Args, member: usize, schema: u32) -> alfd_harness::Result<()> {
    let setup = args.process.load()?;
    let (obs_dim, actions) = setup.env_dims()?;
    if obs_dim > MAX_SHOWN_STATE {
        return Err(BadInput(link::too_long(obs_dim)).into());
    }
    let env = setup.config.env.name.as_str();
    let page = HumanPage::start(setup.runtime.human_port, PageState::blank(env, actions))
        .map_err(|e| BadInput(e.to_string()))?;
    let name = crate::member_name(args.generation, member);
    let mut server = RemoteServer::create(&args.process.run_id, &name, schema)?;
    info!(addr = %page.addr(), service = server.service(), "the person's page is served (its address with the token: the run directory's human-page file)");
    human::write_address(&args.process.run_dir, args.generation, &page)?;
    let parent = args
        .parent
        .unwrap_or_else(std::os::unix::process::parent_id);
    let mut undelivered = VecDeque::new();
    while !server.termination_requested() {
        server.serve(POLL, &mut |r| {
            let sync = PageSync::from_request(r)?;
            page.show(&sync);
            undelivered.extend(page.decisions());
            Ok(link::response(undelivered.pop_front()))
        })?;
        if std::os::unix::process::parent_id() != parent {
            info!("the process that started it has gone: stopping");
            return Ok(());
        }
    }
    info!("stopping");
    Ok(())
}

/// How long the expert process leaves a page that did not answer a sync (its process paused,
/// say) before it syncs again: each sync it does not answer holds the expert process up for the
/// sync's timeout.
pub const QUIET_AFTER_FAILURE: Duration = Duration::from_secs(2);

/// Starts the page's process and connects to it.
pub type Start = Box<dyn FnMut() -> alfd_harness::Result<(Adapter, RemoteClient)>>;

/// The expert process's side of a page in a process of its own: what the page shows, sent
/// when it changes (and every [`SYNC_EVERY`]), and the decisions that come back.
pub struct PageApart {
    adapter: Adapter,
    client: RemoteClient,
    start: Start,
    restarts: Restarts<()>,
    shown: PageSync,
    sent: Option<(PageSync, Instant)>,
    /// After a sync the page did not answer: no sync until then.
    quiet_until: Option<Instant>,
    timeout: Duration,
    run_id: String,
}

impl PageApart {
    /// Starts the page's process of run `run_id` with `start`, to restart it at most
    /// `max_restarts` times; a sync waits at most `timeout`.
    pub fn start(
        mut start: Start,
        run_id: &str,
        max_restarts: u32,
        timeout: Duration,
    ) -> alfd_harness::Result<Self> {
        let (adapter, client) = start()?;
        Ok(Self {
            adapter,
            client,
            start,
            restarts: Restarts::new(max_restarts),
            shown: PageSync::default(),
            sent: None,
            quiet_until: None,
            timeout,
            run_id: run_id.to_owned(),
        })
    }

    /// Which queries wait (oldest first): the page shows the first and their number.
    pub fn set_waiting(&mut self, waiting: &[ShownQuery]) {
        self.shown.waiting = waiting.len();
        self.shown.query = waiting.first().cloned();
    }

    /// Changes what the page shows (sent with the next sync).
    pub fn update(&mut self, change: impl FnOnce(&mut PageSync)) {
        change(&mut self.shown);
    }

    /// The person's decisions that arrived: syncs while the page changed since the last one,
    /// [`SYNC_EVERY`] passed, or a decision came back. A page that does not answer is logged
    /// and left alone for [`QUIET_AFTER_FAILURE`]; one whose process ended is started again
    /// while the restart rule allows, and is an error once it does not.
    pub fn decisions(&mut self, now: Instant) -> alfd_harness::Result<Vec<Decision>> {
        let mut out = Vec::new();
        while self.due(now) || !out.is_empty() {
            match self.sync(now)? {
                Some(d) => out.push(d),
                None => break,
            }
            if out.len() >= 16 {
                break;
            }
        }
        Ok(out)
    }

    fn due(&self, now: Instant) -> bool {
        sync_due(self.sent.as_ref(), self.quiet_until, &self.shown, now)
    }

    /// One sync: the page's oldest undelivered decision, if any.
    fn sync(&mut self, now: Instant) -> alfd_harness::Result<Option<Decision>> {
        self.revive()?;
        let request = self.shown.request().map_err(BadInput)?;
        self.sent = Some((self.shown.clone(), now));
        match self.client.call(request, self.timeout) {
            Ok(r) => Ok(link::decision(&r)),
            Err(e) if self.adapter.exited().is_some() => {
                warn!("the person's page did not answer a sync: {e}");
                self.revive()?;
                Ok(None)
            }
            Err(e) => {
                warn!(
                    "the person's page did not answer a sync: {e}; the next in {} s",
                    QUIET_AFTER_FAILURE.as_secs()
                );
                self.sent = None;
                self.quiet_until = Some(now + QUIET_AFTER_FAILURE);
                Ok(None)
            }
        }
    }

    /// Starts the page's process again if it ended and the restart rule allows.
    fn revive(&mut self) -> alfd_harness::Result<()> {
        let exited = self.adapter.exited();
        match crate::member::restart_due(&mut self.restarts, exited, &self.run_id) {
            Ok(None) => Ok(()),
            Ok(Some(nth)) => {
                let code = exited.flatten();
                warn!(
                    nth,
                    ?code,
                    "the person's page's process ended: starting it again"
                );
                (self.adapter, self.client) = (self.start)()?;
                self.sent = None;
                Ok(())
            }
            Err(GiveUp::Refused) => {
                Err(BadInput(format!("the person's page {}", GiveUp::Refused)).into())
            }
            Err(why) => Err(HarnessError::Run(format!("the person's page {why}"))),
        }
    }
}

/// Whether to sync with the page showing `shown` at `now`, the last sync `sent` (what it showed,
/// and when; `None`: none yet, or it failed): when the page changed, or [`SYNC_EVERY`] passed,
/// unless it is before `quiet_until` (a sync failed).
fn sync_due(
    sent: Option<&(PageSync, Instant)>,
    quiet_until: Option<Instant>,
    shown: &PageSync,
    now: Instant,
) -> bool {
    quiet_until.is_none_or(|t| now >= t)
        && sent.is_none_or(|(was, at)| was != shown || now.duration_since(*at) >= SYNC_EVERY)
}

/// Connects to the page process `adapter`, started already, as `me`.
pub fn connect(
    adapter: Adapter,
    run_id: &str,
    me: Process,
    schema: u32,
) -> alfd_harness::Result<(Adapter, RemoteClient)> {
    let client = adapter.connect(run_id, me, schema)?;
    Ok((adapter, client))
}

/// The page a person answers on: served by the expert process itself (the person is the
/// expert) or by a process of its own (the person is one of several experts).
pub enum PageLink {
    Here(HumanPage),
    Apart(Box<PageApart>),
}

impl PageLink {
    /// The person's decisions that arrived.
    pub fn decisions(&mut self, now: Instant) -> alfd_harness::Result<Vec<Decision>> {
        match self {
            PageLink::Here(page) => Ok(page.decisions()),
            PageLink::Apart(page) => page.decisions(now),
        }
    }

    /// Shows the waiting queries (oldest first) and what `change` sets.
    pub fn show(&mut self, waiting: &[ShownQuery], change: impl FnOnce(&mut PageSync)) {
        match self {
            PageLink::Here(page) => {
                page.set_waiting(waiting);
                page.update(|s| {
                    let mut sync = PageSync::of(s);
                    change(&mut sync);
                    sync.apply(s);
                });
            }
            PageLink::Apart(page) => {
                page.set_waiting(waiting);
                page.update(change);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sync_is_due_first_on_a_change_and_every_sync_period_but_not_soon_after_a_failure() {
        let t0 = Instant::now();
        let shown = PageSync::default();
        assert!(sync_due(None, None, &shown, t0));
        let sent = (shown.clone(), t0);
        let later = |ms| t0 + Duration::from_millis(ms);
        assert!(!sync_due(Some(&sent), None, &shown, later(10)));
        assert!(sync_due(Some(&sent), None, &shown, t0 + SYNC_EVERY));
        let changed = PageSync {
            waiting: 1,
            ..PageSync::default()
        };
        assert!(sync_due(Some(&sent), None, &changed, later(1)));
        // After a sync the page did not answer: nothing until the quiet time is over.
        let quiet = Some(t0 + QUIET_AFTER_FAILURE);
        assert!(!sync_due(None, quiet, &changed, later(1000)));
        assert!(sync_due(None, quiet, &changed, t0 + QUIET_AFTER_FAILURE));
    }
}
