//! Checkpoints of the `channel` monitor ([`crate::monitor::checkpoint`]): what each channel
//! saves, and how a saved channel is checked against the one built from the spec.

use std::borrow::Cow;
use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use super::{ChannelMonitor, ChannelState, MainTest, Predictor};
use crate::detect::stuck::StuckTest;
use crate::detect::window::WindowTest;
use crate::learn::online::OnlineLsSvm;
use crate::learn::outlier::OutlierFilter;
use crate::monitor::{CheckpointError, MonitorKind, TestBank, checkpoint};

/// What a checkpoint saves of one channel (borrowed to write, owned when read): the online
/// windows (`None` for stored models, which the monitor built from the spec holds), the
/// outlier filters, the history, the tests' running states and the learning counters.
#[derive(Serialize, Deserialize)]
struct ChannelSaved<'a> {
    online: Option<Cow<'a, [OnlineLsSvm]>>,
    filters: Option<Cow<'a, [OutlierFilter]>>,
    history: Cow<'a, VecDeque<Vec<f64>>>,
    main: Cow<'a, MainTest>,
    stuck: Option<Cow<'a, StuckTest>>,
    drift: Option<Cow<'a, WindowTest>>,
    quiet: usize,
    frozen: usize,
    relearning: bool,
}

/// What a checkpoint of a `channel` monitor holds: each channel in config order, and the
/// tests.
#[derive(Serialize, Deserialize)]
struct ChannelMonitorSaved<'a> {
    channels: Vec<ChannelSaved<'a>>,
    bank: Cow<'a, TestBank>,
}

impl ChannelState {
    /// The channel's evolving state, borrowed for a checkpoint.
    fn saved(&self) -> ChannelSaved<'_> {
        ChannelSaved {
            online: match &self.predictor {
                Predictor::Online(w) => Some(Cow::Borrowed(w)),
                Predictor::Stored(_) => None,
            },
            filters: self.filters.as_deref().map(Cow::Borrowed),
            history: Cow::Borrowed(&self.history),
            main: Cow::Borrowed(&self.main),
            stuck: self.stuck.as_ref().map(Cow::Borrowed),
            drift: self.drift.as_ref().map(Cow::Borrowed),
            quiet: self.quiet,
            frozen: self.frozen,
            relearning: self.relearning,
        }
    }

    /// This channel (its config, stored models and test indices) with the evolving state
    /// `saved`, each piece checked against this one's: the same predictor kind with one
    /// window per component of the embedding's input dimension, outlier filters and
    /// stuck and drift tests where this channel has them, a history of at most
    /// `embedding` values of `dim` components. The reason otherwise.
    fn restored(&self, saved: ChannelSaved<'_>) -> Result<ChannelState, String> {
        let (dim, m) = (self.config.dim, self.config.embedding);
        let predictor = match (&self.predictor, saved.online) {
            (Predictor::Stored(models), None) => Predictor::Stored(models.clone()),
            (Predictor::Online(mine), Some(theirs)) if theirs.len() == mine.len() => {
                let input = m * dim;
                Predictor::Online(
                    mine.iter()
                        .zip(theirs.into_owned())
                        .map(|(w, saved)| {
                            if saved.input_dim() != 0 && saved.input_dim() != input {
                                return Err(format!(
                                    "an online window over {} inputs, the channel's takes {input}",
                                    saved.input_dim()
                                ));
                            }
                            w.restored(saved)
                        })
                        .collect::<Result<_, _>>()?,
                )
            }
            _ => return Err("another predictor".into()),
        };
        let filters = match (&self.filters, saved.filters) {
            (None, None) => None,
            (Some(mine), Some(theirs)) if theirs.len() == mine.len() => Some(
                mine.iter()
                    .zip(theirs.into_owned())
                    .map(|(f, saved)| f.restored(saved))
                    .collect::<Result<_, _>>()?,
            ),
            _ => return Err("another outlier filter".into()),
        };
        let mut history = saved.history.into_owned();
        if history.len() > m || history.iter().any(|v| v.len() != dim) {
            return Err(format!(
                "a history that does not fit {m} values of {dim} components"
            ));
        }
        history.reserve(m.saturating_sub(history.len()));
        let stuck = match (&self.stuck, saved.stuck) {
            (None, None) => None,
            (Some(mine), Some(theirs)) => Some(mine.restored(theirs.into_owned())?),
            _ => return Err("another stuck test".into()),
        };
        let drift = match (&self.drift, saved.drift) {
            (None, None) => None,
            (Some(mine), Some(theirs)) => Some(mine.restored(theirs.into_owned())?),
            _ => return Err("another drift test".into()),
        };
        Ok(ChannelState {
            config: self.config.clone(),
            predictor,
            filters,
            history,
            main: self.main.restored(saved.main.into_owned())?,
            stuck,
            drift,
            tests: self.tests,
            quiet: saved.quiet,
            frozen: saved.frozen,
            relearning: saved.relearning,
            terms: self.terms.clone(),
        })
    }
}

impl MainTest {
    /// `saved` (from a checkpoint) as the running state of this test: the same variance
    /// kind, its state fitting this one's parameters.
    fn restored(&self, saved: MainTest) -> Result<MainTest, String> {
        match (self, saved) {
            (MainTest::BatchMeans(mine), MainTest::BatchMeans(theirs)) => {
                mine.restored(theirs).map(MainTest::BatchMeans)
            }
            (MainTest::SuccessiveDifference(mine), MainTest::SuccessiveDifference(theirs)) => {
                mine.restored(theirs).map(MainTest::SuccessiveDifference)
            }
            _ => Err("a main test of another variance kind".into()),
        }
    }
}

impl ChannelMonitor {
    /// [`Monitor::checkpoint`](super::Monitor::checkpoint).
    pub(super) fn save(&self) -> Result<Vec<u8>, CheckpointError> {
        checkpoint::encode(
            MonitorKind::Channel,
            &ChannelMonitorSaved {
                channels: self.channels.iter().map(ChannelState::saved).collect(),
                bank: Cow::Borrowed(&self.bank),
            },
        )
    }

    /// [`Monitor::restore`](super::Monitor::restore): every channel's state (in config
    /// order) and the tests checked against this monitor's before anything is replaced.
    pub(super) fn load(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: ChannelMonitorSaved = checkpoint::decode(MonitorKind::Channel, bytes)?;
        if saved.channels.len() != self.channels.len() {
            return Err(CheckpointError::mismatch(format!(
                "{} channels, the monitor has {}",
                saved.channels.len(),
                self.channels.len()
            )));
        }
        let channels = self
            .channels
            .iter()
            .zip(saved.channels)
            .map(|(mine, theirs)| {
                mine.restored(theirs)
                    .map_err(|e| format!("channel '{}': {e}", mine.config.name))
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(CheckpointError::Mismatch)?;
        let bank = self
            .bank
            .restored(saved.bank.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        self.channels = channels;
        self.bank = bank;
        Ok(())
    }
}
