//! Frames through the actor (docs/architecture.md §A2 step 3): each frame checked as a
//! whole, stepped a slice at a time (on the actor's task when cheap, else on the compute
//! pool), each slice's epochs committed in order; the next queued frame stepped while
//! this one's last epochs commit.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use tokio::sync::mpsc;

use super::{Actor, Flow, seats};
use crate::service::compute::{ComputeError, SLICE_BUDGET};
use crate::service::now_ms;
use crate::service::session::build_monitors;
use crate::service::session::handle::{ControlCommand, FrameCommand};
use crate::service::wire::{FrameError, FrameErrorCode};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{EpochError, MonitorReport};
use navguard_core::session::{FrameRefusal, Slice, step_slice};

/// A frame whose epochs are expected to take at most this much compute (from the
/// session's last measured cost per epoch) is stepped on the actor's own task instead of
/// the compute pool. The hop to the pool and back (a queue, a thread wake-up, a task
/// wake-up) costs more than a 10 Hz single-epoch federated step, and at 1,000 sessions it
/// is 10,000 hops a second competing for the same cores; a runtime worker held for at
/// most this long delays no other task noticeably. Anything heavier (large models, long
/// batches, a session's first frame) still goes to the pool, so a heavy session cannot
/// hold a runtime worker (docs/architecture.md §A2).
pub(super) const INLINE_BUDGET: Duration = Duration::from_micros(100);

/// A frame the actor handles next (see [`Actor::frame`]).
pub(super) enum Next {
    /// Not stepped yet: handled as a frame from the queue.
    Queued(FrameCommand),
    /// Checked, and its first slice stepped while the previous frame's last epochs were
    /// committed; `frame.epochs` went with the step and come back in `slice`.
    Stepped {
        frame: FrameCommand,
        total: usize,
        slice: Result<Slice, ComputeError>,
    },
}

/// What [`Actor::prefetch`] found in the queue.
enum Prefetch {
    /// Nothing, or a control command waits.
    None,
    /// A frame to handle after this one, as if it had stayed in the queue.
    Queued(FrameCommand),
    /// A frame to step now.
    Step(FrameCommand),
}

/// The frame being handled, as its commits, recording and metrics need it.
struct Current {
    received: Instant,
    stream: u64,
    text: Option<Arc<str>>,
    first_epoch: u64,
    recording_stream: u64,
    changed: bool,
}

/// What happens after control commands served between two slices.
enum Between {
    /// Step the next slice.
    Go,
    /// The actor stops.
    Stop,
    /// A new stream attached: the frame's later epochs belong to the old one.
    End,
}

impl Actor {
    /// Handles `frame` and any frame taken from the queue with it (see
    /// [`Actor::frame`]). A frame taken early but not stepped waits behind the control
    /// commands that came meanwhile, as it would have in the queue; one already stepped
    /// is committed first.
    pub(super) async fn frames(
        &mut self,
        frame: FrameCommand,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mut mpsc::Receiver<ControlCommand>,
    ) -> Flow {
        let mut next = Some(Next::Queued(frame));
        while let Some(frame) = next.take() {
            if self.fenced() {
                break; // the run loop stops
            }
            if matches!(frame, Next::Queued(_)) {
                while let Ok(command) = control.try_recv() {
                    if self.command(command).await == Flow::Stop {
                        return Flow::Stop;
                    }
                }
            }
            // Boxed, allocated per frame: a frame's future is large (its commits' store
            // and send futures, the step overlapping a commit), and held inline it would
            // be part of every session's task, idle or not (about 1.5 kB).
            let (flow, carry) = Box::pin(self.frame(frame, frames, control)).await;
            if flow == Flow::Stop {
                return Flow::Stop;
            }
            next = carry;
        }
        Flow::Continue
    }

    /// One frame: checked as a whole, then stepped a slice at a time, each slice's epochs
    /// committed in order. An epoch on which a monitor fails numerically is still
    /// committed for the monitors that stepped it (their results, state changes and
    /// alarms are stored and announced; the failing monitor's state is unchanged), then
    /// refused as `numerical`, and the rest of the frame is not used.
    ///
    /// When the frame's last slice has stepped and the next frame is already queued, the
    /// next frame's first slice is stepped on the pool while this frame's last epochs are
    /// committed ([`Actor::prefetch`]); that frame comes back with the answer and must be
    /// handled next, before anything else.
    async fn frame(
        &mut self,
        next: Next,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mut mpsc::Receiver<ControlCommand>,
    ) -> (Flow, Option<Next>) {
        let Some((frame, total, mut first)) = self.begin(next).await else {
            return (Flow::Continue, None);
        };
        let (mut epochs, mut current) = self.open(frame, total);
        let (mut from, mut carry) = (0, None);
        while from < total {
            let slice = match first.take() {
                Some(slice) => slice,
                None => self.step(epochs, from).await,
            };
            let Ok(slice) = slice else {
                self.lost_monitors(from).await;
                break;
            };
            let Slice {
                engines,
                epochs: returned,
                stepped,
                failure,
                elapsed: _,
            } = slice;
            self.core.put_engines(engines);
            epochs = returned;
            let end = from + stepped.len();
            let last = end == total && failure.is_none();
            let committing = &epochs[from..end];
            current.changed |= self
                .commit_stepped(committing, &stepped, last, frames, control, &mut carry)
                .await;
            from = end;
            if failure.is_none() && from < total {
                match self.between_slices(control, current.stream).await {
                    Between::Go => {}
                    Between::Stop => return (Flow::Stop, None),
                    Between::End => {
                        self.close(current, from, from).await;
                        return (Flow::Continue, None);
                    }
                }
            }
            if let Some((index, monitor, e)) = failure {
                self.refuse_numerical(&epochs, index, monitor, &e).await;
                break;
            }
        }
        let committed = (self.core.stream_epochs() - current.first_epoch) as usize;
        self.close(current, committed, total).await;
        (Flow::Continue, carry)
    }

    /// The frame to handle and its first slice when already stepped; `None` when a queued
    /// frame is of an old stream (dropped) or refused (answered).
    async fn begin(
        &mut self,
        next: Next,
    ) -> Option<(FrameCommand, usize, Option<Result<Slice, ComputeError>>)> {
        match next {
            Next::Queued(frame) => {
                if frame.stream != self.stream {
                    return None; // from a stream that has since been replaced
                }
                if let Err(error) = self.check(&frame.epochs, self.core.last_t()) {
                    self.reject(error).await;
                    return None;
                }
                let total = frame.epochs.len();
                Some((frame, total, None))
            }
            Next::Stepped {
                frame,
                total,
                slice,
            } => {
                self.note_cost(&slice);
                Some((frame, total, Some(slice)))
            }
        }
    }

    /// Counts an accepted frame and makes room for its results.
    fn open(&mut self, frame: FrameCommand, total: usize) -> (Vec<Epoch>, Current) {
        let stats = self.core.stats_mut();
        stats.frames += 1;
        stats.last_frame_at_ms = Some(now_ms());
        self.deps.metrics.frames.fetch_add(1, Ordering::Relaxed);
        if self.echo {
            // One buffer for the frame's results, with some room for longer ones.
            self.results
                .reserve(total * (self.result_len + self.result_len / 8));
        }
        self.frame_events.clear();
        let current = Current {
            received: frame.received,
            stream: frame.stream,
            text: frame.text,
            first_epoch: self.core.stream_epochs(),
            recording_stream: self.recording_stream,
            changed: false,
        };
        (frame.epochs, current)
    }

    /// Commits a stepped slice; on the frame's last slice the next queued frame may step
    /// meanwhile ([`Actor::prefetch`]), and is left in `carry`. True if a state changed.
    async fn commit_stepped(
        &mut self,
        committing: &[Epoch],
        stepped: &[Vec<Option<MonitorReport>>],
        last: bool,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mpsc::Receiver<ControlCommand>,
        carry: &mut Option<Next>,
    ) -> bool {
        let prefetch = match (last, committing.last()) {
            (true, Some(epoch)) => self.prefetch(frames, control, epoch.t),
            _ => Prefetch::None,
        };
        match prefetch {
            Prefetch::Step(mut next) => {
                self.deps
                    .metrics
                    .frames_prestepped
                    .fetch_add(1, Ordering::Relaxed);
                // The statistics published when this frame ends must not see the next
                // frame's epochs: what they read of the monitors is read now.
                self.core.refresh_consistency();
                let total = next.epochs.len();
                let engines = self.core.take_engines();
                let epochs = std::mem::take(&mut next.epochs);
                let compute = self.deps.compute.clone();
                let job = async move {
                    compute
                        .run(move || step_slice(engines, epochs, 0, SLICE_BUDGET))
                        .await
                };
                let (slice, changed) = tokio::join!(job, self.commit_slice(committing, stepped));
                *carry = Some(Next::Stepped {
                    frame: next,
                    total,
                    slice,
                });
                changed
            }
            Prefetch::Queued(next) => {
                *carry = Some(Next::Queued(next));
                self.commit_slice(committing, stepped).await
            }
            Prefetch::None => self.commit_slice(committing, stepped).await,
        }
    }

    /// Between slices: observers see progress, and control commands are served (a
    /// threshold change applies from the next epoch). A new stream or a delete ends this
    /// frame: its later epochs belong to the old stream.
    async fn between_slices(
        &mut self,
        control: &mut mpsc::Receiver<ControlCommand>,
        stream: u64,
    ) -> Between {
        self.publish(false);
        while let Ok(command) = control.try_recv() {
            let new_stream = matches!(command, ControlCommand::Attach { .. });
            if self.command(command).await == Flow::Stop {
                return Between::Stop;
            }
            if new_stream || stream != self.stream {
                return Between::End;
            }
        }
        Between::Go
    }

    /// The frame is done: recorded with its `committed` epochs, the rate counted over
    /// `epochs`, its latency observed, the statistics published (at once if a state
    /// changed).
    async fn close(&mut self, current: Current, committed: usize, epochs: usize) {
        self.record_frame(
            current.text,
            current.recording_stream,
            current.first_epoch,
            committed,
        )
        .await;
        // The frame's results are queued; what is left of their buffer goes with it.
        self.results = BytesMut::new();
        self.changed();
        let now = Instant::now();
        self.rate_window.1 += epochs as u64;
        let elapsed = now.duration_since(self.rate_window.0);
        if elapsed >= Duration::from_secs(1) {
            self.core.stats_mut().epochs_per_s = self.rate_window.1 as f64 / elapsed.as_secs_f64();
            self.rate_window = (now, 0);
        }
        self.deps
            .metrics
            .observe_frame_latency(now.duration_since(current.received));
        // A fenced actor stops: its statistics (which counted entries the store refused)
        // are not published.
        if !self.fenced() {
            self.publish(current.changed);
        }
    }

    /// A step job lost the monitors (it panicked): they are built afresh from the spec,
    /// and the frame is refused from `from` as `internal`.
    async fn lost_monitors(&mut self, from: usize) {
        tracing::error!(session = %self.id, "stepping failed; monitors rebuilt");
        let stored = self.stored();
        match build_monitors(&stored, &*self.deps.models) {
            Ok(monitors) => self.core.rebuild(seats(monitors, &stored)),
            Err(e) => {
                tracing::error!(session = %self.id, error = %e, "could not rebuild the monitors");
            }
        }
        let error = FrameError::new(
            FrameErrorCode::Internal,
            "the session's monitors could not process this frame; they were restarted from their configuration",
        );
        self.reject(error.at(from)).await;
    }

    /// Refuses epoch `index` of the frame, on which monitor `monitor` failed.
    async fn refuse_numerical(
        &mut self,
        epochs: &[Epoch],
        index: usize,
        monitor: usize,
        e: &navguard_core::monitor::StepError,
    ) {
        let t = epochs[index].t;
        let monitor = &self.core.roster()[monitor].name;
        let error = FrameError::new(
            FrameErrorCode::Numerical,
            format!(
                "monitor '{monitor}' could not process t = {t}: {e}; the other monitors took this epoch, later epochs of the frame were not used"
            ),
        );
        self.reject(error.at(index)).await;
    }

    /// Checks a whole frame against the session before anything changes.
    fn check(&self, epochs: &[Epoch], last_t: Option<f64>) -> Result<(), FrameError> {
        self.core
            .check_frame(epochs, last_t)
            .map_err(|refusal| match refusal {
                FrameRefusal::TimeBackwards { .. } => {
                    FrameError::new(FrameErrorCode::TimeBackwards, refusal.to_string()).at(0)
                }
                FrameRefusal::Epoch { index, error } => {
                    let code = match error {
                        EpochError::WrongLength { .. } => FrameErrorCode::WrongLength,
                        EpochError::UnknownInput(_) => FrameErrorCode::UnknownInput,
                    };
                    FrameError::new(code, error.to_string()).at(index)
                }
            })
    }

    /// Steps the session's monitors through `epochs[from..]` (one slice): on this task
    /// when the session's measured cost says it fits in [`INLINE_BUDGET`], else on the
    /// compute pool. A panic is caught either way (the monitors are then lost, as on the
    /// pool).
    async fn step(&mut self, epochs: Vec<Epoch>, from: usize) -> Result<Slice, ComputeError> {
        let engines = self.core.take_engines();
        let slice = if self.inline(epochs.len() - from) {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                step_slice(engines, epochs, from, SLICE_BUDGET)
            }))
            .map_err(|_| ComputeError::Panicked)
        } else {
            self.deps
                .compute
                .run(move || step_slice(engines, epochs, from, SLICE_BUDGET))
                .await
        };
        self.note_cost(&slice);
        slice
    }

    /// Whether `epochs` epochs fit in [`INLINE_BUDGET`] at the session's last measured
    /// cost (never before the first measure).
    fn inline(&self, epochs: usize) -> bool {
        let epochs = u32::try_from(epochs).unwrap_or(u32::MAX);
        self.epoch_cost
            .is_some_and(|cost| cost.saturating_mul(epochs) <= INLINE_BUDGET)
    }

    /// Keeps a stepped slice's compute time per epoch (see [`Actor::inline`]).
    fn note_cost(&mut self, slice: &Result<Slice, ComputeError>) {
        if let Ok(slice) = slice
            && let Ok(n) = u32::try_from(slice.stepped.len())
            && n > 0
        {
            self.epoch_cost = Some(slice.elapsed / n);
        }
    }

    /// At the end of a frame whose epochs all stepped (their commit still to come): takes
    /// the next frame from the queue, if there is one, and says whether it may be stepped
    /// now, on the compute pool, while those epochs are committed
    /// ([`Prefetch::Step`], docs/architecture.md §A2). It may not ([`Prefetch::Queued`]:
    /// it is handled after this frame as if it had stayed in the queue) when it would be
    /// stepped on this task anyway, belongs to another stream, or would be refused.
    /// Committing needs only the session core's roster and statistics, never the
    /// monitors. Nothing is taken while a control command waits, so a command waits at
    /// most one frame more.
    fn prefetch(
        &self,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mpsc::Receiver<ControlCommand>,
        last_t: f64,
    ) -> Prefetch {
        if !control.is_empty() {
            return Prefetch::None;
        }
        let Ok(frame) = frames.try_recv() else {
            return Prefetch::None;
        };
        // (An empty frame never gets here, the edge refuses it; it is not stepped early
        // either, since no slice of it would bring the monitors back.)
        if frame.stream != self.stream
            || frame.epochs.is_empty()
            || self.inline(frame.epochs.len())
            || self.check(&frame.epochs, Some(last_t)).is_err()
        {
            return Prefetch::Queued(frame);
        }
        Prefetch::Step(frame)
    }
}
