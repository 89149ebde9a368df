//! The watch page in a build without the `pages` feature: serving it says how to build it.

use std::path::Path;

/// The page, which this build cannot serve.
#[derive(Debug)]
pub struct WatchPage {
    never: std::convert::Infallible,
}

impl WatchPage {
    pub fn url(&self) -> String {
        match self.never {}
    }
}

/// Refused with exit code 2: this build has no page server.
pub fn serve(_run_dir: &Path, _port: u16) -> anyhow::Result<WatchPage> {
    Err(crate::usage::usage(
        "the watch page is a web page, and this alfd was built without them (the `pages` \
         feature; deploy/run.sh builds the main job so): build every feature with \
         `cargo build --release --workspace`",
    ))
}
