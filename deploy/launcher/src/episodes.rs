//! `RUN_DIR/episodes.csv` as the launcher writes it, and each actor's share of an episode limit.

use std::fs::File;
use std::io::Write as _;
use std::path::Path;

use alfd_harness::What as _;

use crate::error::{bail, ensure};
use crate::Result;

use alfd_common::record::CSV_HEADER;

/// `episodes` split among `actors`: the first `episodes % actors` play one more.
pub(super) fn shares(episodes: u64, actors: usize) -> [u32; alfd_wire::MAX_ACTORS] {
    let mut q = [0u32; alfd_wire::MAX_ACTORS];
    let actors = actors.clamp(1, alfd_wire::MAX_ACTORS) as u64;
    for (i, share) in q.iter_mut().enumerate().take(actors as usize) {
        let n = episodes / actors + u64::from((i as u64) < episodes % actors);
        *share = u32::try_from(n).unwrap_or(u32::MAX);
    }
    q
}

/// A row of `episodes.csv` as a resumed launcher needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Row {
    pub ret: f64,
    pub demos_used: u32,
    pub length: u64,
    pub actor: u16,
}

/// `RUN_DIR/episodes.csv` opened for this launcher, and the rows already in it: a new run
/// creates it with its header; a resumed run appends to it, after dropping a last line cut short
/// by a crash.
pub(super) fn open_episodes(run_dir: &Path, resume: bool) -> Result<(File, Vec<Row>)> {
    let path = run_dir.join("episodes.csv");
    if !resume {
        let mut csv = File::create(&path).what(|| "cannot create episodes.csv".to_owned())?;
        writeln!(csv, "{CSV_HEADER}")?;
        return Ok((csv, Vec::new()));
    }
    let text = std::fs::read_to_string(&path).what(|| format!("cannot read {}", path.display()))?;
    let whole = text.rfind('\n').map_or(0, |i| i + 1);
    let mut rows = Vec::new();
    for (n, line) in text[..whole].lines().enumerate() {
        if n == 0 {
            ensure!(
                line == CSV_HEADER,
                "{} has another header than this alfd writes",
                path.display()
            );
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let field = |i: usize| fields.get(i).copied().unwrap_or("");
        let parsed = (
            field(1).parse::<f64>(),
            field(3).parse::<u32>(),
            field(2).parse::<u64>(),
            field(8).parse::<u16>(),
        );
        let (Ok(ret), Ok(demos_used), Ok(length), Ok(actor)) = parsed else {
            bail!("{} line {}: not an episode row", path.display(), n + 1);
        };
        rows.push(Row {
            ret,
            demos_used,
            length,
            actor,
        });
    }
    ensure!(whole > 0, "{} has no header", path.display());
    let csv = std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .what(|| format!("cannot open {}", path.display()))?;
    csv.set_len(whole as u64)?;
    let mut csv = csv;
    use std::io::Seek as _;
    csv.seek(std::io::SeekFrom::End(0))?;
    Ok((csv, rows))
}

/// `episodes.csv` as the launcher appends to it: rows in the order of their episodes, each
/// whole. A row that cannot be written (a full disk) is kept in memory with those after it and
/// written when the disk has room again (tried at every tick), so a full disk costs the run
/// nothing unless it is still full when the run ends.
pub(super) struct EpisodeLog {
    file: File,
    path: std::path::PathBuf,
    /// Rows not written yet, oldest first, with their episode numbers.
    pending: std::collections::VecDeque<(u64, String)>,
    /// Whether the current streak of failures was said (once per streak).
    warned: bool,
}

impl EpisodeLog {
    pub(super) fn new(file: File, path: std::path::PathBuf) -> Self {
        Self {
            file,
            path,
            pending: std::collections::VecDeque::new(),
            warned: false,
        }
    }

    /// Appends the row of `episode` (with its newline) after every row before it.
    pub(super) fn append(&mut self, episode: u64, row: String) {
        self.pending.push_back((episode, row));
        self.flush();
    }

    /// Writes what is pending, in order, as far as the disk lets it; the first failure of a
    /// streak is logged. Whether everything is written.
    pub(super) fn flush(&mut self) -> bool {
        while let Some((episode, row)) = self.pending.front() {
            if let Err(e) = alfd_harness::append_whole(&mut self.file, row.as_bytes(), false) {
                if !self.warned {
                    tracing::warn!(
                        "cannot append episode {episode} to {}: {e}; the rows from it on are \
                         kept in memory and written when there is room",
                        self.path.display()
                    );
                    self.warned = true;
                }
                return false;
            }
            self.pending.pop_front();
        }
        if self.warned {
            tracing::info!("{} is written up to date again", self.path.display());
            self.warned = false;
        }
        true
    }

    /// [`EpisodeLog::flush`], tried every 200 ms until `deadline`; an error naming the first
    /// row not written if the disk stays full.
    pub(super) fn flush_by(&mut self, deadline: std::time::Instant) -> Result<()> {
        while !self.flush() {
            if std::time::Instant::now() >= deadline {
                let first = self.pending.front().map_or(0, |p| p.0);
                bail!(
                    "cannot append episode {first} (and {} after it) to {}: the disk stayed full",
                    self.pending.len() - 1,
                    self.path.display()
                );
            }
            std::thread::sleep(std::time::Duration::from_millis(200));
        }
        Ok(())
    }
}

/// Which episode records never reached the launcher. An actor's incarnation sends its records
/// in order on one publisher, numbered 0, 1, 2… (the progress message's sequence number), and
/// one publisher's messages arrive in the order sent: a number past the next one expected means
/// the records in between were lost on the way (an actor waits for room in a full buffer for a
/// while, then drops). A lost last record leaves no gap; the SHARE_PLAYED message that follows
/// the records says how many were sent.
#[derive(Debug, Default)]
pub(super) struct Arrivals {
    /// Per (actor id, incarnation).
    streams: std::collections::HashMap<(u16, u64), Stream>,
}

/// One actor incarnation's records as they arrived.
#[derive(Debug, Default)]
struct Stream {
    /// The sequence number expected next.
    next: u64,
    received: u64,
    lost: u64,
    /// Its share played: the numbers after it are SHARE_PLAYED messages, not records.
    played: bool,
}

impl Arrivals {
    /// Takes in record `seq` of actor `id`'s `incarnation`; how many records of it before this
    /// one were lost (0 in a sound run). A number below one already seen (a repeat) loses
    /// nothing.
    pub(super) fn arrive(&mut self, id: u16, incarnation: u64, seq: u64) -> u64 {
        let s = self.streams.entry((id, incarnation)).or_default();
        let lost = if s.played {
            0
        } else {
            seq.saturating_sub(s.next)
        };
        s.next = s.next.max(seq + 1);
        s.received += 1;
        s.lost += lost;
        lost
    }

    /// Actor `id`'s `incarnation` played its share after sending `sent` records; how many of
    /// them are newly known lost (those not received: every record came before this message).
    pub(super) fn played(&mut self, id: u16, incarnation: u64, sent: u64) -> u64 {
        let s = self.streams.entry((id, incarnation)).or_default();
        s.played = true;
        let lost = sent.saturating_sub(s.received).saturating_sub(s.lost);
        s.lost += lost;
        lost
    }

    /// Records of actor `id` lost so far (all its incarnations).
    pub(super) fn lost_by(&self, id: u16) -> u32 {
        let lost: u64 = self
            .streams
            .iter()
            .filter(|((a, _), _)| *a == id)
            .map(|(_, s)| s.lost)
            .sum();
        u32::try_from(lost).unwrap_or(u32::MAX)
    }

    /// Records lost so far, all actors.
    pub(super) fn lost(&self) -> u64 {
        self.streams.values().map(|s| s.lost).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_whose_number_skips_ahead_counts_those_in_between_lost_per_actor_and_incarnation() {
        let mut a = Arrivals::default();
        assert_eq!(a.arrive(0, 1, 0), 0);
        assert_eq!(a.arrive(0, 1, 1), 0);
        // Records 2, 3 and 4 of actor 0 never came.
        assert_eq!(a.arrive(0, 1, 5), 3);
        assert_eq!(a.arrive(0, 1, 6), 0);
        // Another actor, and a new incarnation of actor 0, count from 0: a first record
        // numbered 2 means its first two were lost.
        assert_eq!(a.arrive(1, 1, 0), 0);
        assert_eq!(a.arrive(0, 2, 2), 2);
        // A repeat (or an older number) loses nothing and moves nothing back.
        assert_eq!(a.arrive(0, 2, 1), 0);
        assert_eq!(a.arrive(0, 2, 3), 0);
        assert_eq!((a.lost_by(0), a.lost_by(1), a.lost_by(7)), (5, 0, 0));
        assert_eq!(a.lost(), 5);
    }

    #[test]
    fn a_share_played_after_more_records_than_came_counts_the_last_ones_lost_once() {
        let mut a = Arrivals::default();
        for seq in [0, 1, 3] {
            a.arrive(4, 1, seq);
        }
        assert_eq!(a.lost(), 1, "record 2");
        // Six records sent: 4 and 5 (the last) never came; 2 is counted already.
        assert_eq!(a.played(4, 1, 6), 2);
        // The same message again, and its own numbers skipping (one of them dropped), lose
        // no record more.
        assert_eq!(a.played(4, 1, 6), 0);
        assert_eq!(a.arrive(4, 1, 9), 0);
        assert_eq!((a.lost_by(4), a.lost()), (3, 3));
        // A share played with every record received loses nothing.
        a.arrive(5, 1, 0);
        assert_eq!(a.played(5, 1, 1), 0);
    }

    /// A log on a file that refuses writes (`/dev/full`) until it is swapped for a real one.
    #[test]
    fn rows_a_full_disk_refuses_are_kept_in_order_and_written_when_there_is_room() {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let mut log = EpisodeLog::new(full, "/dev/full".into());
        log.append(0, "0,a\n".into());
        log.append(1, "1,b\n".into());
        assert!(!log.flush());
        assert_eq!(log.pending.len(), 2);
        let e = log
            .flush_by(std::time::Instant::now())
            .unwrap_err()
            .to_string();
        assert!(e.contains("episode 0 (and 1 after it)"), "{e}");
        // Room again: both rows go out, in order, and later ones after them.
        let dir = alfd_harness::test_dir("episode-log");
        let path = dir.path().join("episodes.csv");
        log.file = File::create(&path).unwrap();
        log.append(2, "2,c\n".into());
        assert!(log.flush());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "0,a\n1,b\n2,c\n");
    }

    #[test]
    fn a_resumed_launcher_reads_each_row_s_actor_and_length_and_drops_a_cut_line() {
        let dir = alfd_harness::test_dir("episode-rows");
        let path = dir.path().join("episodes.csv");
        let row = |ep: u32, len: u32, actor: u32| {
            format!(
                "{ep},{}.0,{len},3,0.1,2,{len},{},{actor},\n",
                len,
                (ep + 1) * 100
            )
        };
        let text = format!(
            "{CSV_HEADER}\n{}{}{}1,17",
            row(0, 120, 1),
            row(1, 80, 0),
            row(2, 200, 1)
        );
        std::fs::write(&path, text).unwrap();
        let (_file, rows) = open_episodes(dir.path(), true).unwrap();
        let got: Vec<(u16, u64)> = rows.iter().map(|r| (r.actor, r.length)).collect();
        assert_eq!(got, vec![(1, 120), (0, 80), (1, 200)]);
        // The line cut short by a crash is gone from the file.
        assert!(std::fs::read_to_string(&path)
            .unwrap()
            .ends_with(&row(2, 200, 1)));
        // Each id's steps so far: ε's clock for an incarnation that takes over.
        let steps = crate::explored_steps(&rows);
        assert_eq!((steps[0], steps[1], steps[2]), (80, 320, 0));
    }
}
