//! A launcher built without the `hosts` feature (`alfd` for the main job alone): runs on this
//! host only. No [`Endpoint`] can be made, so no run listens and no hub exists; the launcher's
//! calls into the remote side find nothing to do.

use std::convert::Infallible;

use crate::Result;

use super::{Launcher, SwapRequest};

/// An endpoint to listen on: none can be made in this build.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    never: Infallible,
}

/// The bridge to other hosts: none can be made in this build.
#[derive(Debug)]
pub struct Hub {
    never: Infallible,
}

impl Hub {
    pub(super) fn remote_actors(&self) -> usize {
        match self.never {}
    }

    pub(super) fn demos_refused(&self) -> u64 {
        match self.never {}
    }

    pub(super) fn answers_late(&self) -> u64 {
        match self.never {}
    }

    pub(super) fn stop(self) -> Result<()> {
        match self.never {}
    }
}

/// Expert generations served by remote hosts: none in this build.
#[derive(Debug, Default)]
pub(super) struct RemoteExperts {}

impl RemoteExperts {
    pub(super) fn serving(&self) -> usize {
        0
    }
}

impl Launcher<'_, '_> {
    pub(super) fn start_hub(&self, endpoint: &Endpoint) -> Result<Hub> {
        match endpoint.never {}
    }

    pub(super) fn check_hub(&mut self) -> Result<()> {
        Ok(())
    }

    pub(super) fn spawn_remote_expert(&mut self, _generation: u16, _name: &str) -> bool {
        false
    }

    pub(super) fn kill_remote_expert(&mut self, _generation: u16) {}

    pub(super) fn answer_remote_expert(&mut self, _: &SwapRequest, _: bool, _: &str) -> bool {
        false
    }
}
