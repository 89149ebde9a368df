//! The join protocol as a pure state machine: which actor ids the remote hosts hold, and which
//! incarnation each gets. The launcher owns the ids below `local` (its own actors); remote hosts
//! get free ids above them, the lowest first; an id given up (a host left or its link dropped) is
//! given again with a new incarnation, so the learner's credit book sees a new actor process, as
//! after a crash on one host. A remote actor that crashed is restarted by its host with a new
//! incarnation of the id it holds, at most `max_restarts` times (`alfd_common::restarts`, the
//! launcher's rule for its own actors).

use alfd_common::restarts::{Ended, Restarts, Verdict};
use alfd_wire::MAX_ACTORS;
use serde::{Deserialize, Serialize};

/// What `alfd join` asks for.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct JoinRequest {
    /// Names this joining process, unique across hosts (host name, pid, time).
    pub join_id: String,
    pub host: String,
    pub actors: u16,
    /// The demonstrator this host serves as the run's expert (`alfd join --expert NAME`).
    pub expert: Option<String>,
}

/// What `alfd join` asks when one of its actors died: a new incarnation of the id it holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RestartRequest {
    pub join_id: String,
    pub actor: u16,
}

/// The run's answer to a [`RestartRequest`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum RestartReply {
    /// Start the actor again with this incarnation.
    Restart(u64),
    Refused(String),
}

/// What a host that left took with it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Left {
    pub actors: Vec<u16>,
    /// Whether it served an expert.
    pub expert: bool,
}

/// What the run answers.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum JoinReply {
    Joined(Joined),
    Refused(String),
}

/// A granted join: the run, and what the remote host needs to start its actors.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Joined {
    pub run_id: String,
    /// (actor id, incarnation) of each actor to start.
    pub actors: Vec<(u16, u64)>,
    /// `config.toml` and `runtime.toml` of the run, as the launcher wrote them.
    pub config_toml: String,
    pub runtime_toml: String,
}

/// Who holds which actor id.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Roster {
    local: usize,
    first_incarnation: u64,
    /// Per id: restarts since its holder joined.
    restarts: Restarts<u16>,
    /// Per id: the join holding it.
    holders: Vec<Option<String>>,
    /// Per id: the incarnation the next holder gets.
    next_incarnation: Vec<u64>,
    /// The joins that serve an expert.
    experts: Vec<String>,
}

impl Roster {
    /// A run with `local` actors of its own, whose actors' incarnations start at
    /// `first_incarnation`, and whose actors may be restarted `max_restarts` times each.
    pub fn new(local: usize, first_incarnation: u64, max_restarts: u32) -> Self {
        Self {
            local: local.min(MAX_ACTORS),
            first_incarnation,
            restarts: Restarts::new(max_restarts),
            holders: vec![None; MAX_ACTORS],
            next_incarnation: vec![first_incarnation; MAX_ACTORS],
            experts: Vec::new(),
        }
    }

    /// Gives `request.actors` free ids to `request.join_id` (and takes note of its expert).
    /// Asking again with the same join id (its reply was lost) gets the same ids.
    pub fn join(&mut self, request: &JoinRequest) -> Result<Vec<(u16, u64)>, String> {
        let held = self.held_by(&request.join_id);
        if !held.is_empty() || self.experts.contains(&request.join_id) {
            return Ok(held);
        }
        if request.actors == 0 && request.expert.is_none() {
            return Err(
                "a join brings at least one actor or an expert (--actors 1 or more, or --expert)"
                    .to_owned(),
            );
        }
        if request.expert.is_some() && !self.experts.is_empty() {
            return Err(format!(
                "another host ({}) serves an expert already; one remote expert at a time",
                self.experts[0]
            ));
        }
        let free: Vec<usize> = (self.local..MAX_ACTORS)
            .filter(|&i| self.holders[i].is_none())
            .collect();
        let n = usize::from(request.actors);
        if free.len() < n {
            return Err(format!(
                "{n} actors asked for, but only {} of the run's {MAX_ACTORS} actor ids are free \
                 ({} local, {} remote)",
                free.len(),
                self.local,
                self.remote()
            ));
        }
        if request.expert.is_some() {
            self.experts.push(request.join_id.clone());
        }
        Ok(free[..n]
            .iter()
            .map(|&i| {
                self.holders[i] = Some(request.join_id.clone());
                self.restarts.forget(&(i as u16));
                let inc = self.next_incarnation[i];
                self.next_incarnation[i] += 1;
                (i as u16, inc)
            })
            .collect())
    }

    /// Actor `id` of `join_id` died and its host restarts it: its new incarnation (the
    /// learner's credit book takes it as a new actor process). Refused for an id the host does
    /// not hold, and after `max_restarts` restarts of the id since the host joined.
    pub fn restart(&mut self, join_id: &str, id: u16) -> Result<u64, String> {
        let i = usize::from(id);
        if self.holders.get(i).and_then(|h| h.as_deref()) != Some(join_id) {
            return Err(format!("actor {id} is not held by {join_id}"));
        }
        if let Verdict::GiveUp(why) = self.restarts.ended(&id, Ended::Crashed) {
            return Err(format!("actor {id} {why}"));
        }
        let incarnation = self.next_incarnation[i];
        self.next_incarnation[i] += 1;
        Ok(incarnation)
    }

    /// `join_id` left (or its link dropped): its ids are free again, and its expert gone;
    /// returns what it held.
    pub fn leave(&mut self, join_id: &str) -> Left {
        let mut left = Left::default();
        for (i, h) in self.holders.iter_mut().enumerate() {
            if h.as_deref() == Some(join_id) {
                *h = None;
                left.actors.push(i as u16);
            }
        }
        let before = self.experts.len();
        self.experts.retain(|j| j != join_id);
        left.expert = self.experts.len() < before;
        left
    }

    /// (id, incarnation) of the actors `join_id` holds.
    fn held_by(&self, join_id: &str) -> Vec<(u16, u64)> {
        (0..MAX_ACTORS)
            .filter(|&i| self.holders[i].as_deref() == Some(join_id))
            .map(|i| (i as u16, self.next_incarnation[i] - 1))
            .collect()
    }

    /// Actor ids held by remote hosts now.
    pub fn remote(&self) -> usize {
        self.holders.iter().flatten().count()
    }

    /// Whether actor `id` is held by a remote host now.
    pub fn is_remote(&self, id: u16) -> bool {
        self.holders
            .get(usize::from(id))
            .is_some_and(|h| h.is_some())
    }

    /// The joined host holding actor `id`, if one does.
    pub fn holder(&self, id: u16) -> Option<&str> {
        self.holders.get(usize::from(id))?.as_deref()
    }

    /// The first incarnation of this launch's actors.
    pub fn first_incarnation(&self) -> u64 {
        self.first_incarnation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ask(id: &str, actors: u16) -> JoinRequest {
        JoinRequest {
            join_id: id.to_owned(),
            host: "h".to_owned(),
            actors,
            expert: None,
        }
    }

    fn expert(id: &str, actors: u16) -> JoinRequest {
        JoinRequest {
            expert: Some("cartpole-200".to_owned()),
            ..ask(id, actors)
        }
    }

    #[test]
    fn a_host_may_serve_the_expert_with_or_without_actors_one_at_a_time() {
        let mut r = Roster::new(1, 1, 5);
        assert_eq!(r.join(&expert("e", 0)).unwrap(), vec![]);
        // Asked again (a lost reply): the same answer, not a second expert.
        assert_eq!(r.join(&expert("e", 0)).unwrap(), vec![]);
        let e = r.join(&expert("f", 2)).unwrap_err();
        assert!(e.contains("serves an expert already"), "{e}");
        assert_eq!(r.remote(), 0, "a refused join holds nothing");
        assert_eq!(
            r.leave("e"),
            Left {
                actors: vec![],
                expert: true
            }
        );
        assert_eq!(r.join(&expert("f", 2)).unwrap(), vec![(1, 1), (2, 1)]);
        assert_eq!(
            r.leave("f"),
            Left {
                actors: vec![1, 2],
                expert: true
            }
        );
        assert_eq!(r.leave("f"), Left::default());
    }

    #[test]
    fn remote_actors_get_free_ids_above_the_local_ones_and_new_incarnations_on_rejoin() {
        let mut r = Roster::new(2, 1, 5);
        assert_eq!(r.join(&ask("a", 2)).unwrap(), vec![(2, 1), (3, 1)]);
        // A lost reply: asking again gets the same ids, not more.
        assert_eq!(r.join(&ask("a", 2)).unwrap(), vec![(2, 1), (3, 1)]);
        assert_eq!(r.join(&ask("b", 1)).unwrap(), vec![(4, 1)]);
        assert_eq!(r.remote(), 3);
        assert!(r.is_remote(3) && !r.is_remote(1) && !r.is_remote(5));
        // "a" drops: its ids come back, with the next incarnation.
        assert_eq!(r.leave("a").actors, vec![2, 3]);
        assert_eq!(r.leave("a"), Left::default());
        assert_eq!(r.remote(), 1);
        assert_eq!(r.join(&ask("a2", 3)).unwrap(), vec![(2, 2), (3, 2), (5, 1)]);
    }

    #[test]
    fn a_crashed_remote_actor_gets_a_new_incarnation_of_its_id_within_the_restart_limit() {
        let mut r = Roster::new(1, 1, 2);
        assert_eq!(r.join(&ask("a", 2)).unwrap(), vec![(1, 1), (2, 1)]);
        assert_eq!(r.restart("a", 2), Ok(2));
        assert_eq!(r.restart("a", 2), Ok(3));
        let e = r.restart("a", 2).unwrap_err();
        assert!(
            e.contains("restarted 2 times already") && e.contains("--max-restarts 2"),
            "{e}"
        );
        // The other id has its own count; an id of the launcher or of another host is refused.
        assert_eq!(r.restart("a", 1), Ok(2));
        assert!(r.restart("a", 0).unwrap_err().contains("not held by a"));
        assert!(r.restart("b", 1).is_err() && r.restart("a", 99).is_err());
        // A lost reply asked again: the newest incarnation.
        assert_eq!(r.join(&ask("a", 2)).unwrap(), vec![(1, 2), (2, 3)]);
        // A host joining after "a" left gets the next incarnations, and restarts anew.
        r.leave("a");
        assert_eq!(r.join(&ask("b", 1)).unwrap(), vec![(1, 3)]);
        assert_eq!((r.restart("b", 1), r.restart("b", 1)), (Ok(4), Ok(5)));
        assert!(r.restart("b", 1).is_err());
    }

    #[test]
    fn a_join_beyond_the_free_ids_or_of_no_actor_is_refused_by_number() {
        let mut r = Roster::new(14, 1_000_001, 5);
        let e = r.join(&ask("a", 3)).unwrap_err();
        assert!(e.contains("3 actors asked for, but only 2"), "{e}");
        assert_eq!(r.remote(), 0, "a refused join holds nothing");
        assert_eq!(
            r.join(&ask("a", 2)).unwrap(),
            vec![(14, 1_000_001), (15, 1_000_001)]
        );
        assert!(r
            .join(&ask("z", 0))
            .unwrap_err()
            .contains("at least one actor or an expert"));
        assert_eq!(r.first_incarnation(), 1_000_001);
    }
}
