//! Checkpoints of the `federated` monitor ([`crate::monitor::checkpoint`]): what it saves,
//! and how a saved state is checked against the monitor built from the spec.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use super::{Convergence, FederatedMonitor, FederatedSolution, FrontState};
use crate::epoch::Aid;
use crate::filter::federated::{FederatedState, MAX_AIDS};
use crate::monitor::guards::InnovationGuards;
use crate::monitor::{CheckpointError, MonitorKind, Outputs, TestBank, checkpoint};

/// What a checkpoint of a `federated` monitor holds (borrowed to write, owned when read):
/// the filter's current state, the tests and guards, the convergence, the HPL terms, the
/// time of the last INS epoch and the outputs repeated on epochs without INS (`isolated`
/// as aids); with `input: imu` the strapdown front end (absent from checkpoints of
/// monitors without it, which still load). Not the λ_det cache: its values are
/// recomputed bit for bit when needed.
#[derive(Serialize, Deserialize)]
struct FederatedSaved<'a> {
    filter: Cow<'a, FederatedState>,
    bank: Cow<'a, TestBank>,
    guards: Cow<'a, [InnovationGuards]>,
    convergence: Convergence,
    hpl2: [Option<f64>; MAX_AIDS],
    last_t: Option<f64>,
    solution: Option<FederatedSolution>,
    hpl: Option<f64>,
    isolated: Vec<Aid>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    front: Option<Cow<'a, FrontState>>,
}

impl FederatedMonitor {
    /// [`Monitor::checkpoint`](crate::monitor::Monitor::checkpoint).
    pub(super) fn save(&self) -> Result<Vec<u8>, CheckpointError> {
        let Outputs::Federated {
            solution,
            hpl,
            isolated,
            ..
        } = &self.outputs
        else {
            return Err(CheckpointError::Encode(
                "federated monitor without federated outputs".into(),
            ));
        };
        let isolated = isolated
            .iter()
            .map(|name| Aid::parse(name).ok_or_else(|| CheckpointError::Encode(name.to_string())))
            .collect::<Result<_, _>>()?;
        checkpoint::encode(
            MonitorKind::Federated,
            &FederatedSaved {
                filter: Cow::Borrowed(self.filter.state()),
                bank: Cow::Borrowed(&self.bank),
                guards: Cow::Borrowed(&self.guards),
                convergence: self.convergence,
                hpl2: self.hpl2,
                last_t: self.last_t,
                solution: *solution,
                hpl: *hpl,
                isolated,
                front: self.front.as_ref().map(Cow::Borrowed),
            },
        )
    }

    /// [`Monitor::restore`](crate::monitor::Monitor::restore): the saved filter state (no
    /// estimate for an aid the monitor lacks), the tests, each aid's guards, the
    /// convergence cap, HPL terms only for configured aids and isolated aids among the
    /// configured ones, all checked before anything is replaced.
    pub(super) fn load(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: FederatedSaved = checkpoint::decode(MonitorKind::Federated, bytes)?;
        let mismatch = CheckpointError::Mismatch;
        let filter = self
            .filter
            .with_state(saved.filter.into_owned())
            .map_err(mismatch)?;
        let bank = self
            .bank
            .restored(saved.bank.into_owned())
            .map_err(mismatch)?;
        if saved.guards.len() != self.guards.len() {
            return Err(CheckpointError::mismatch(format!(
                "guards of {} aids, the monitor has {}",
                saved.guards.len(),
                self.guards.len()
            )));
        }
        let guards = self
            .guards
            .iter()
            .zip(saved.guards.into_owned())
            .map(|(mine, theirs)| mine.restored(theirs))
            .collect::<Result<Vec<_>, _>>()
            .map_err(mismatch)?;
        let convergence = self
            .convergence
            .restored(saved.convergence)
            .map_err(mismatch)?;
        let n = self.config.aids.len();
        if saved.hpl2[n..].iter().any(Option::is_some) {
            return Err(CheckpointError::mismatch(
                "an HPL term for an aid the monitor does not have",
            ));
        }
        let isolated = saved
            .isolated
            .iter()
            .map(|a| {
                self.config
                    .aids
                    .contains(a)
                    .then_some(a.as_str())
                    .ok_or_else(|| {
                        CheckpointError::mismatch(format!("aid {} is not configured", a.as_str()))
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let front = match (saved.front, self.config.strapdown.is_some()) {
            (Some(f), true) => Some(f.into_owned()),
            (None, false) => None,
            (Some(_), false) => {
                return Err(CheckpointError::mismatch(
                    "a strapdown state, the monitor's input is ins",
                ));
            }
            (None, true) => {
                return Err(CheckpointError::mismatch(
                    "no strapdown state, the monitor's input is imu",
                ));
            }
        };
        self.filter = filter;
        self.bank = bank;
        self.guards = guards;
        self.convergence = convergence;
        self.hpl2 = saved.hpl2;
        self.last_t = saved.last_t;
        self.outputs = Outputs::Federated {
            solution: saved.solution,
            hpl: saved.hpl,
            isolated,
            alignment: front.as_ref().map(FrontState::alignment),
        };
        self.front = front;
        Ok(())
    }
}
