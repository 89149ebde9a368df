//! The human expert's page in a build without the `page` feature: starting it says how to
//! build it (exit code 2 in the expert process).

use std::net::SocketAddr;

use super::{Decision, HumanError, PageState, ShownQuery};

/// The page, which this build cannot serve.
#[derive(Debug)]
pub struct HumanPage {
    never: std::convert::Infallible,
}

impl HumanPage {
    /// Refused: this build has no page server.
    pub fn start(_port: u16, _initial: PageState) -> Result<Self, HumanError> {
        Err(HumanError::Unavailable)
    }

    pub fn url(&self) -> String {
        match self.never {}
    }

    pub fn addr(&self) -> SocketAddr {
        match self.never {}
    }

    pub fn update(&self, _change: impl FnOnce(&mut PageState)) {
        match self.never {}
    }

    pub fn set_waiting(&self, _waiting: &[ShownQuery]) {
        match self.never {}
    }

    pub fn show(&self, _sync: &super::link::PageSync) {
        match self.never {}
    }

    pub fn decisions(&self) -> Vec<Decision> {
        match self.never {}
    }
}
