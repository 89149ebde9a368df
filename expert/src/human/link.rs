//! A person among several experts answers on a page served by a process of its own
//! (`alfd-expert --member I`), as every other expert of `[[experts]]` does. The expert process
//! keeps the queries, the budget and the counts, and sends the page what it shows with every
//! sync (a `PAGE` request); the answer carries back the person's oldest decision not yet
//! delivered. A sync asks nothing of the person, so it is answered at once: the person's time
//! passes between syncs, and the expert process goes on answering the other experts' queries.
//!
//! A sync's values: `active`, `budget_total`, `budget_left`, `demos`, `waiting`, `answered`,
//! `declined`, then 1 and the oldest query's `id`, `actor`, `step` and state, or 0 when none
//! waits. An answer's values: none, or the decision's `id` and its action (-1: declined).

use alfd_wire::{remote_kind, RemoteRequest, RemoteResponse, MAX_REMOTE_VALUES};

use super::{Decision, PageState, ShownQuery};

/// The values of a sync before the query's state.
const HEAD: usize = 11;

/// The most values of a state a sync can show.
pub const MAX_SHOWN_STATE: usize = MAX_REMOTE_VALUES - HEAD;

/// What the page shows that the expert process decides: everything but the environment and
/// the action labels (the page's process knows them from the config) and the version.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PageSync {
    pub active: bool,
    pub budget_total: u32,
    pub budget_left: u32,
    pub demos: u32,
    /// Queries waiting for the person.
    pub waiting: usize,
    pub answered: u64,
    pub declined: u64,
    /// The oldest waiting query.
    pub query: Option<ShownQuery>,
}

impl PageSync {
    /// What `state` shows.
    pub fn of(state: &PageState) -> Self {
        Self {
            active: state.active,
            budget_total: state.budget_total,
            budget_left: state.budget_left,
            demos: state.demos,
            waiting: state.waiting,
            answered: state.answered,
            declined: state.declined,
            query: state.query.clone(),
        }
    }

    /// Shows this on `state`.
    pub fn apply(&self, state: &mut PageState) {
        state.active = self.active;
        state.budget_total = self.budget_total;
        state.budget_left = self.budget_left;
        state.demos = self.demos;
        state.waiting = self.waiting;
        state.answered = self.answered;
        state.declined = self.declined;
        state.query = self.query.clone();
    }

    /// The `PAGE` request that sends it; refused for a state longer than [`MAX_SHOWN_STATE`].
    pub fn request(&self) -> Result<RemoteRequest, String> {
        let mut v = vec![
            f64::from(u8::from(self.active)),
            f64::from(self.budget_total),
            f64::from(self.budget_left),
            f64::from(self.demos),
            self.waiting as f64,
            self.answered as f64,
            self.declined as f64,
        ];
        match &self.query {
            None => v.push(0.0),
            Some(q) => {
                if q.state.len() > MAX_SHOWN_STATE {
                    return Err(too_long(q.state.len()));
                }
                v.extend([1.0, q.id as f64, f64::from(q.actor), q.step as f64]);
                v.extend(q.state.iter().map(|&x| f64::from(x)));
            }
        }
        RemoteRequest::new(remote_kind::PAGE, 0)
            .with_values(&v)
            .map_err(|e| e.to_string())
    }

    /// The sync `r` sends.
    pub fn from_request(r: &RemoteRequest) -> Result<Self, String> {
        if r.kind != remote_kind::PAGE {
            return Err(format!(
                "a person's page answers PAGE ({}), not {}",
                remote_kind::PAGE,
                r.kind
            ));
        }
        let v = &r.values[..(r.len as usize).min(r.values.len())];
        let whole = |i: usize| v[i] as u64;
        if v.len() < HEAD - 3 || (v[7] != 0.0 && v.len() < HEAD) {
            return Err(format!("a sync of {} values is cut short", v.len()));
        }
        let query = (v[7] != 0.0).then(|| ShownQuery {
            id: whole(8),
            actor: whole(9) as u32,
            step: whole(10),
            state: v[HEAD..].iter().map(|&x| x as f32).collect(),
        });
        Ok(Self {
            active: v[0] != 0.0,
            budget_total: whole(1) as u32,
            budget_left: whole(2) as u32,
            demos: whole(3) as u32,
            waiting: whole(4) as usize,
            answered: whole(5),
            declined: whole(6),
            query,
        })
    }
}

/// Why a state cannot be shown by a page in a process of its own.
pub fn too_long(len: usize) -> String {
    format!(
        "a person among several experts is shown states of at most {MAX_SHOWN_STATE} values, \
         and this environment's have {len}"
    )
}

/// The answer to a sync: `decision`, or none.
pub fn response(decision: Option<Decision>) -> RemoteResponse {
    let mut r = RemoteResponse::default();
    if let Some(d) = decision {
        r.values[0] = d.id as f64;
        r.values[1] = d.action.map_or(-1.0, |a| a as f64);
        r.len = 2;
    }
    r
}

/// The decision an answer to a sync carries, if any.
pub fn decision(r: &RemoteResponse) -> Option<Decision> {
    (r.len >= 2).then(|| Decision {
        id: r.values[0] as u64,
        action: (r.values[1] >= 0.0).then_some(r.values[1] as usize),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sync(query: Option<ShownQuery>) -> PageSync {
        PageSync {
            active: true,
            budget_total: 300,
            budget_left: 12,
            demos: 288,
            waiting: 3,
            answered: 250,
            declined: 7,
            query,
        }
    }

    #[test]
    fn a_sync_arrives_as_sent_with_or_without_a_query() {
        let q = ShownQuery {
            id: 41,
            actor: 2,
            step: 123_456,
            state: vec![0.5, -1.25, 3.0, 0.0],
        };
        for s in [sync(None), sync(Some(q))] {
            let r = s.request().unwrap();
            assert_eq!(r.kind, remote_kind::PAGE);
            assert_eq!(PageSync::from_request(&r).unwrap(), s);
        }
    }

    #[test]
    fn a_state_too_long_to_show_and_a_request_of_another_kind_are_refused() {
        let q = ShownQuery {
            id: 1,
            actor: 0,
            step: 0,
            state: vec![0.0; MAX_SHOWN_STATE + 1],
        };
        let e = sync(Some(q.clone())).request().unwrap_err();
        assert!(
            e.contains(&format!("at most {MAX_SHOWN_STATE} values")),
            "{e}"
        );
        let fits = ShownQuery {
            state: vec![1.0; MAX_SHOWN_STATE],
            ..q
        };
        assert!(sync(Some(fits)).request().is_ok());
        let act = RemoteRequest::new(remote_kind::ACT, 0);
        let e = PageSync::from_request(&act).unwrap_err();
        assert!(e.contains("PAGE (8), not 7"), "{e}");
        let short = RemoteRequest::new(remote_kind::PAGE, 0)
            .with_values(&[1.0, 2.0])
            .unwrap();
        assert!(PageSync::from_request(&short).is_err());
    }

    #[test]
    fn an_answer_carries_an_action_a_decline_or_nothing() {
        let answer = Decision {
            id: 9,
            action: Some(2),
        };
        let decline = Decision {
            id: 10,
            action: None,
        };
        for d in [Some(answer), Some(decline), None] {
            assert_eq!(decision(&response(d)), d);
        }
    }

    #[test]
    fn a_sync_shows_on_the_page_what_the_expert_process_decides_and_nothing_else() {
        let mut state = PageState {
            version: 5,
            ..PageState::blank("cartpole", 2)
        };
        let s = sync(None);
        s.apply(&mut state);
        assert_eq!(PageSync::of(&state), s);
        assert_eq!((state.env.as_str(), state.version), ("cartpole", 5));
    }
}
