//! The chaos run's injector: which fault comes when, drawn from a seed. Pure: time is passed in,
//! nothing is killed here (`chaos/mod.rs` carries the faults out).

use std::time::Duration;

use alfd_common::rng::{seeded, Rng};
use rand::Rng as _;

/// A process of the run a fault is aimed at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    Actor(u16),
    Learner,
    Expert,
    /// The Python environment adapter of an actor (a Gymnasium environment's run).
    Adapter(u16),
    /// The joined host (`alfd join` on 127.0.0.1 with actors of its own); killed, it is started
    /// again.
    Host,
    /// The process of one of several experts (`[[experts]]`, by its place; a built-in one's
    /// or a person's page's `alfd-expert --member`, or an external one's adapter): killed or
    /// paused, the panel asks the others (a killed one is started again).
    Member(u16),
}

impl Target {
    /// The binary that plays it (`""`: the adapter's Python interpreter, whatever its name).
    pub fn binary(self) -> &'static str {
        match self {
            Target::Actor(_) => "alfd-actor",
            Target::Learner => "alfd-learner",
            Target::Expert => "alfd-expert",
            Target::Adapter(_) | Target::Member(_) => "",
            Target::Host => "alfd",
        }
    }
}

/// One fault.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Fault {
    /// SIGKILL.
    Kill(Target),
    /// SIGSTOP, then SIGCONT after the duration.
    Pause(Target, #[serde(with = "millis")] Duration),
    /// `alfd swap-expert` to this demonstrator.
    SwapExpert(String),
    /// SIGKILL to the launcher; `alfd resume` continues the run.
    KillLauncher,
    /// The run directory's file system filled up for the duration, then freed.
    FillDisk(#[serde(with = "millis")] Duration),
    /// The link to the joined expert host holds every byte for the first duration (longer than
    /// the actors wait for an answer), for the second.
    DelayLink(
        #[serde(with = "millis")] Duration,
        #[serde(with = "millis")] Duration,
    ),
}

impl Fault {
    /// Its kind, as the report counts them.
    pub fn kind(&self) -> &'static str {
        match self {
            Fault::Kill(_) => "kill",
            Fault::Pause(..) => "pause",
            Fault::SwapExpert(_) => "swap",
            Fault::KillLauncher => "launcher",
            Fault::FillDisk(_) => "disk",
            Fault::DelayLink(..) => "delay",
        }
    }
}

mod millis {
    pub fn serialize<S: serde::Serializer>(
        d: &std::time::Duration,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.serialize_u64(d.as_millis() as u64)
    }
}

/// How often each kind of fault is drawn (relative weights; 0: never).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mix {
    pub kill: u32,
    pub pause: u32,
    pub swap: u32,
    pub launcher: u32,
    pub disk: u32,
    /// The link to a joined expert host slowed down (only with one).
    pub delay: u32,
}

impl Mix {
    fn total(&self) -> u32 {
        self.kill + self.pause + self.swap + self.launcher + self.disk + self.delay
    }
}

/// Draws the faults of a chaos run: one every `gap` on average (uniformly between half and one
/// and a half of it), of a kind drawn by the [`Mix`], aimed at a process drawn uniformly.
#[derive(Debug)]
pub struct Injector {
    rng: Rng,
    gap: Duration,
    actors: u16,
    experts: Vec<String>,
    mix: Mix,
    adapters: bool,
    host: bool,
    members: Vec<u16>,
    next: Duration,
}

impl Injector {
    /// Faults for a run of `actors` actors whose experts may be swapped among `experts`
    /// (none: no swaps), the first after one gap.
    pub fn new(seed: u64, gap: Duration, actors: u16, experts: Vec<String>, mix: Mix) -> Self {
        let mut mix = mix;
        if experts.is_empty() {
            mix.swap = 0;
        }
        let mut injector = Self {
            rng: seeded(seed),
            gap,
            actors,
            experts,
            mix,
            adapters: false,
            host: false,
            members: Vec::new(),
            next: Duration::ZERO,
        };
        injector.next = injector.draw_gap();
        injector
    }

    /// Aims kills and pauses at the actors' environment adapters too, each as likely as an
    /// actor (with `false`, a seed gives the schedule of a run without adapters).
    pub fn with_adapters(mut self, adapters: bool) -> Self {
        self.adapters = adapters;
        self
    }

    /// Slows the link to a joined expert host down too (with `false`, no delay faults whatever
    /// their weight).
    pub fn with_expert_host(mut self, expert_host: bool) -> Self {
        if !expert_host {
            self.mix.delay = 0;
        }
        self
    }

    /// Aims kills and pauses at a joined host too, as likely as the learner (with `false`, a
    /// seed gives the schedule of a run without one).
    pub fn with_host(mut self, host: bool) -> Self {
        self.host = host;
        self
    }

    /// Aims kills and pauses at the processes of these experts of `[[experts]]` (their places)
    /// too, each as likely as the learner (none: a seed gives the schedule of a run
    /// without them).
    pub fn with_members(mut self, members: Vec<u16>) -> Self {
        self.members = members;
        self
    }

    fn draw_gap(&mut self) -> Duration {
        self.gap.mul_f64(self.rng.random_range(0.5..1.5))
    }

    /// The fault due at `now` (time since the run started), if one is; the next is then drawn.
    pub fn due(&mut self, now: Duration) -> Option<Fault> {
        if now < self.next || self.mix.total() == 0 {
            return None;
        }
        self.next = now + self.draw_gap();
        Some(self.draw())
    }

    fn draw(&mut self) -> Fault {
        let m = self.mix;
        let mut pick = self.rng.random_range(0..m.total());
        for (weight, kind) in [
            (m.kill, 0),
            (m.pause, 1),
            (m.swap, 2),
            (m.launcher, 3),
            (m.disk, 4),
            (m.delay, 5),
        ] {
            if pick >= weight {
                pick -= weight;
                continue;
            }
            return match kind {
                0 => Fault::Kill(self.target()),
                1 => {
                    let target = self.target();
                    Fault::Pause(target, self.pause_length())
                }
                2 => {
                    let i = self.rng.random_range(0..self.experts.len());
                    Fault::SwapExpert(self.experts[i].clone())
                }
                3 => Fault::KillLauncher,
                4 => Fault::FillDisk(self.pause_length()),
                _ => {
                    let hold = Duration::from_millis(self.rng.random_range(1200..3000));
                    Fault::DelayLink(hold, self.pause_length() * 2)
                }
            };
        }
        unreachable!("the pick is below the total of the weights")
    }

    /// An actor, the learner, the expert, (with adapters) an actor's adapter, (with a joined
    /// host) the host or (with members) one of several experts' processes, each as likely as
    /// the learner.
    fn target(&mut self) -> Target {
        let actors = u32::from(self.actors);
        let adapters = if self.adapters { actors } else { 0 };
        let host = u32::from(self.host);
        let before_members = actors + adapters + 2 + host;
        let all = before_members + self.members.len() as u32;
        match self.rng.random_range(0..all) {
            0 => Target::Learner,
            1 => Target::Expert,
            a if a < actors + 2 => Target::Actor((a - 2) as u16),
            a if a < actors + adapters + 2 => Target::Adapter((a - 2 - actors) as u16),
            a if a < before_members => Target::Host,
            a => Target::Member(self.members[(a - before_members) as usize]),
        }
    }

    /// Between 0.3 and 3 seconds.
    fn pause_length(&mut self) -> Duration {
        Duration::from_millis(self.rng.random_range(300..3000))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: Mix = Mix {
        kill: 4,
        pause: 3,
        swap: 1,
        launcher: 1,
        disk: 1,
        delay: 0,
    };

    fn faults(seed: u64, mix: Mix, experts: &[&str], secs: u64) -> Vec<(u64, Fault)> {
        let experts = experts.iter().map(|e| e.to_string()).collect();
        let mut inj = Injector::new(seed, Duration::from_secs(2), 2, experts, mix);
        (0..secs * 10)
            .filter_map(|t| {
                inj.due(Duration::from_millis(t * 100))
                    .map(|f| (t * 100, f))
            })
            .collect()
    }

    #[test]
    fn adapters_are_aimed_at_only_when_asked_and_a_seed_without_them_is_unchanged() {
        let schedule = |inj: Injector| {
            let mut inj = inj;
            (0..400)
                .filter_map(|t| inj.due(Duration::from_millis(t * 100)))
                .collect::<Vec<_>>()
        };
        let new = || Injector::new(5, Duration::from_secs(1), 2, vec![], ALL);
        let at_adapters = |faults: &[Fault]| {
            faults
                .iter()
                .filter_map(|f| match f {
                    Fault::Kill(Target::Adapter(a)) | Fault::Pause(Target::Adapter(a), _) => {
                        Some(*a)
                    }
                    _ => None,
                })
                .collect::<Vec<_>>()
        };
        let without = schedule(new().with_adapters(false));
        assert_eq!(without, schedule(new()));
        assert!(at_adapters(&without).is_empty());
        let with = schedule(new().with_adapters(true));
        let hit = at_adapters(&with);
        assert!(!hit.is_empty(), "{with:?}");
        assert!(
            hit.iter().all(|&a| a < 2),
            "only the 2 actors' adapters: {hit:?}"
        );
    }

    #[test]
    fn external_experts_are_aimed_at_only_when_named_and_a_seed_without_them_is_unchanged() {
        let schedule = |members: Vec<u16>| {
            let mut inj =
                Injector::new(7, Duration::from_secs(1), 2, vec![], ALL).with_members(members);
            (0..400)
                .filter_map(|t| inj.due(Duration::from_millis(t * 100)))
                .collect::<Vec<_>>()
        };
        let at_members = |faults: &[Fault]| {
            faults
                .iter()
                .filter_map(|f| match f {
                    Fault::Kill(Target::Member(m)) | Fault::Pause(Target::Member(m), _) => Some(*m),
                    _ => None,
                })
                .collect::<Vec<_>>()
        };
        let without = schedule(vec![]);
        assert!(at_members(&without).is_empty());
        let plain = Injector::new(7, Duration::from_secs(1), 2, vec![], ALL);
        let mut plain = plain;
        let unchanged: Vec<Fault> = (0..400)
            .filter_map(|t| plain.due(Duration::from_millis(t * 100)))
            .collect();
        assert_eq!(without, unchanged);
        let hit = at_members(&schedule(vec![1]));
        assert!(!hit.is_empty() && hit.iter().all(|&m| m == 1), "{hit:?}");
    }

    #[test]
    fn a_joined_host_is_aimed_at_only_when_there_is_one() {
        let schedule = |host: bool| {
            let mut inj = Injector::new(6, Duration::from_secs(1), 2, vec![], ALL).with_host(host);
            (0..400)
                .filter_map(|t| inj.due(Duration::from_millis(t * 100)))
                .collect::<Vec<_>>()
        };
        let at_host = |faults: &[Fault]| {
            faults
                .iter()
                .filter(|f| matches!(f, Fault::Kill(Target::Host) | Fault::Pause(Target::Host, _)))
                .count()
        };
        let (without, with) = (schedule(false), schedule(true));
        assert_eq!(at_host(&without), 0);
        assert!(at_host(&with) > 0, "{with:?}");
    }

    #[test]
    fn the_link_is_delayed_only_with_an_expert_host_and_longer_than_an_answer_is_awaited() {
        let mix = Mix { delay: 1, ..ALL };
        let schedule = |expert_host: bool| {
            let mut inj = Injector::new(9, Duration::from_secs(1), 2, vec![], mix)
                .with_expert_host(expert_host);
            (0..400)
                .filter_map(|t| inj.due(Duration::from_millis(t * 100)))
                .collect::<Vec<_>>()
        };
        assert!(schedule(false).iter().all(|f| f.kind() != "delay"));
        let delays: Vec<(Duration, Duration)> = schedule(true)
            .into_iter()
            .filter_map(|f| match f {
                Fault::DelayLink(hold, lasting) => Some((hold, lasting)),
                _ => None,
            })
            .collect();
        assert!(!delays.is_empty());
        for (hold, lasting) in delays {
            // The actors wait 1 s for an answer by default (`--query-timeout-ms`).
            assert!(
                (1200..3000).contains(&(hold.as_millis() as u64)),
                "{hold:?}"
            );
            assert!(
                (600..6000).contains(&(lasting.as_millis() as u64)),
                "{lasting:?}"
            );
        }
    }

    #[test]
    fn one_seed_gives_one_schedule_and_another_seed_another() {
        let a = faults(7, ALL, &["cartpole-500"], 120);
        assert_eq!(a, faults(7, ALL, &["cartpole-500"], 120));
        assert_ne!(a, faults(8, ALL, &["cartpole-500"], 120));
    }

    #[test]
    fn faults_come_between_half_and_one_and_a_half_gaps_apart() {
        let a = faults(3, ALL, &["cartpole-500"], 600);
        // 600 s at one every 2 s on average.
        assert!((250..350).contains(&a.len()), "{}", a.len());
        for w in a.windows(2) {
            let gap = w[1].0 - w[0].0;
            assert!((1000..=3100).contains(&gap), "{gap} ms");
        }
        assert!(a[0].0 >= 1000 && a[0].0 <= 3100, "{}", a[0].0);
    }

    #[test]
    fn every_kind_and_every_process_is_drawn_in_proportion() {
        let a = faults(11, ALL, &["cartpole-500", "cartpole-1000"], 2000);
        let count = |k: &str| a.iter().filter(|(_, f)| f.kind() == k).count() as f64;
        let n = a.len() as f64;
        for (kind, share) in [
            ("kill", 0.4),
            ("pause", 0.3),
            ("swap", 0.1),
            ("launcher", 0.1),
            ("disk", 0.1),
        ] {
            assert!(
                (count(kind) / n - share).abs() < 0.05,
                "{kind}: {} of {n}",
                count(kind)
            );
        }
        let kills: Vec<Target> = a
            .iter()
            .filter_map(|(_, f)| match f {
                Fault::Kill(t) => Some(*t),
                _ => None,
            })
            .collect();
        for t in [
            Target::Learner,
            Target::Expert,
            Target::Actor(0),
            Target::Actor(1),
        ] {
            let share = kills.iter().filter(|k| **k == t).count() as f64 / kills.len() as f64;
            assert!((share - 0.25).abs() < 0.07, "{t:?}: {share}");
        }
        assert!(!kills.contains(&Target::Actor(2)));
        for (_, f) in &a {
            if let Fault::Pause(_, d) | Fault::FillDisk(d) = f {
                assert!((300..3000).contains(&(d.as_millis() as u64)), "{d:?}");
            }
        }
    }

    #[test]
    fn no_expert_to_swap_to_means_no_swaps_and_no_weights_no_faults() {
        let a = faults(5, ALL, &[], 300);
        assert!(!a.is_empty());
        assert!(a.iter().all(|(_, f)| f.kind() != "swap"));
        let none = Mix {
            kill: 0,
            pause: 0,
            swap: 0,
            launcher: 0,
            disk: 0,
            delay: 0,
        };
        assert!(faults(5, none, &["x"], 300).is_empty());
    }
}
