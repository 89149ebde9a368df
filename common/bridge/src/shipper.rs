//! An expert host's `demos.jsonl` shipped to the run line by line, as a state machine with no
//! I/O: every complete line the host's expert appends goes up in order, whether or not its
//! answer is still awaited, so that the run's copy and the host's cannot diverge. The host's
//! thread reads the file's new bytes and sends the frames [`DemoShipper::ship`] makes; the hub
//! asks for lines again from a line it lacks ([`DemoShipper::rewind`]); the run's file, sent when
//! an expert of this host becomes active, replaces the host's and says what the host held that
//! the run never got ([`DemoShipper::activated`]).

use crate::frame::Frame;

/// Where the host's file stands against the run's.
#[derive(Debug, Default, PartialEq, Eq)]
pub(crate) struct DemoShipper {
    /// The generation whose demonstrations go up (the one the run made active on this host).
    generation: Option<u16>,
    /// Lines of the host's file the run holds or has been sent.
    lines: usize,
    /// Bytes of the host's file those lines take.
    bytes: u64,
}

/// The complete lines (each ending in `\n`) at the start of `text`, without their newlines.
fn complete_lines(text: &str) -> impl Iterator<Item = &str> {
    text.split_inclusive('\n')
        .filter_map(|l| l.strip_suffix('\n'))
}

impl DemoShipper {
    /// The byte offset in the host's file from which new lines are read.
    pub(crate) fn offset(&self) -> u64 {
        self.bytes
    }

    /// Whether a generation of this host ships its lines.
    pub(crate) fn shipping(&self) -> bool {
        self.generation.is_some()
    }

    /// The run's `demos.jsonl` (`run`) replaces the host's (`host`) as `generation` becomes
    /// active. Returns how many complete lines of the host's file the run's does not hold (a host
    /// that died before they went up): they are dropped with the host's file, and reported.
    pub(crate) fn activated(&mut self, generation: u16, run: &str, host: &str) -> usize {
        let common = complete_lines(host)
            .zip(complete_lines(run))
            .take_while(|(h, r)| h == r)
            .count();
        self.generation = Some(generation);
        self.lines = complete_lines(run).count();
        self.bytes = run.len() as u64;
        complete_lines(host).count() - common
    }

    /// The host's file from [`DemoShipper::offset`] on (`tail`): a frame with its complete lines,
    /// if it has any, and the offset moves past them (a line still being written waits).
    pub(crate) fn ship(&mut self, tail: &str) -> Option<Frame> {
        let generation = self.generation?;
        let lines: Vec<String> = complete_lines(tail).map(str::to_owned).collect();
        if lines.is_empty() {
            return None;
        }
        let first = self.lines as u32;
        self.lines += lines.len();
        self.bytes += lines.iter().map(|l| l.len() as u64 + 1).sum::<u64>();
        Some(Frame::ExpertDemos {
            generation,
            first,
            lines,
        })
    }

    /// The run asks `generation`'s lines again from line `from` (it did not take what followed);
    /// `host` is the host's file. Ignored for another generation, or a line the file does not
    /// have.
    pub(crate) fn rewind(&mut self, generation: u16, from: usize, host: &str) {
        if self.generation != Some(generation) || from > self.lines {
            return;
        }
        let bytes: usize = complete_lines(host).take(from).map(|l| l.len() + 1).sum();
        self.lines = from;
        self.bytes = bytes as u64;
    }

    /// `generation` ended: once what it wrote has gone up, nothing more is shipped for it.
    pub(crate) fn exited(&mut self, generation: u16) {
        if self.generation == Some(generation) {
            self.generation = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(f: Option<Frame>) -> Option<(u16, u32, Vec<String>)> {
        f.map(|f| match f {
            Frame::ExpertDemos {
                generation,
                first,
                lines,
            } => (generation, first, lines),
            other => panic!("{other:?}"),
        })
    }

    fn lines(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn nothing_goes_up_before_a_generation_of_this_host_is_active() {
        let mut s = DemoShipper::default();
        assert!(!s.shipping());
        assert_eq!(s.ship("a\n"), None);
        assert_eq!(s.offset(), 0);
    }

    #[test]
    fn every_complete_line_goes_up_once_in_order_and_a_partial_one_waits() {
        let mut s = DemoShipper::default();
        assert_eq!(s.activated(2, "r0\nr1\n", ""), 0);
        assert_eq!(s.offset(), 6);
        // The file's tail from the offset: one whole line and one being written.
        assert_eq!(shipped(s.ship("d2\nd3-half")), Some((2, 2, lines(&["d2"]))));
        assert_eq!(s.offset(), 9);
        assert_eq!(s.ship("d3-half"), None, "nothing whole yet");
        assert_eq!(
            shipped(s.ship("d3-half-done\nd4\n")),
            Some((2, 3, lines(&["d3-half-done", "d4"])))
        );
        assert_eq!(s.offset(), 9 + 13 + 3);
        assert_eq!(s.ship(""), None);
    }

    #[test]
    fn a_rewind_sends_the_lines_again_from_where_the_run_stopped_taking_them() {
        let mut s = DemoShipper::default();
        s.activated(3, "", "");
        let file = "a\nbb\nccc\n";
        assert_eq!(shipped(s.ship(file)).unwrap().1, 0);
        // The hub took line 0 only: it asks again from line 1, which starts at byte 2.
        s.rewind(3, 1, file);
        assert_eq!(s.offset(), 2);
        assert_eq!(
            shipped(s.ship(&file[2..])),
            Some((3, 1, lines(&["bb", "ccc"])))
        );
        // Another generation's request, or a line beyond what went up: ignored.
        s.rewind(4, 0, file);
        s.rewind(3, 9, file);
        assert_eq!(s.offset(), file.len() as u64);
    }

    #[test]
    fn an_activation_reports_what_the_host_held_that_the_run_never_got() {
        let mut s = DemoShipper::default();
        // The host died after writing two lines the run never took (and half of a third).
        assert_eq!(s.activated(5, "a\nb\n", "a\nb\nc\nd\ne-ha"), 2);
        assert_eq!(s.offset(), 4);
        // The same file, or one the run has grown past: nothing lost.
        assert_eq!(s.activated(6, "a\nb\n", "a\nb\n"), 0);
        assert_eq!(s.activated(7, "a\nb\nc\n", "a\n"), 0);
        // A host whose copy went another way from line 1 on: its lines from there are lost.
        assert_eq!(s.activated(8, "a\nb\nc\n", "a\nx\ny\n"), 2);
    }

    #[test]
    fn an_exited_generation_ships_nothing_more() {
        let mut s = DemoShipper::default();
        s.activated(2, "", "");
        s.exited(3);
        assert!(s.shipping(), "another generation's exit");
        s.exited(2);
        assert_eq!(s.ship("a\n"), None);
    }
}
