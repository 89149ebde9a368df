//! `RUN_DIR/episodes.csv` as the launcher writes it, and each actor's share of an episode limit.

use std::fs::File;
use std::io::Write as _;
use std::path::Path;

use crate::error::{bail, ensure, What as _};
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

/// `RUN_DIR/episodes.csv` opened for this launcher, and the (return, demonstrations used) of
/// the rows already in it: a new run creates it with its header; a resumed run appends to it,
/// after dropping a last line cut short by a crash.
pub(super) fn open_episodes(run_dir: &Path, resume: bool) -> Result<(File, Vec<(f64, u32)>)> {
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
        let parsed = (
            fields.get(1).and_then(|f| f.parse::<f64>().ok()),
            fields.get(3).and_then(|f| f.parse::<u32>().ok()),
        );
        let (Some(ret), Some(demos)) = parsed else {
            bail!("{} line {}: not an episode row", path.display(), n + 1);
        };
        rows.push((ret, demos));
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
