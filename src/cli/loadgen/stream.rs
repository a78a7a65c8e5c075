//! One session's stream for `navguard loadgen`: passes over the shared
//! workload, each on a fresh ingest socket, with a reader that checks every
//! result against the epoch it answers and times frames and alarms.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::bail;
use futures_util::{SinkExt, StreamExt};
use tokio::sync::Notify;
use tokio::time::{Instant, MissedTickBehavior};
use tokio_tungstenite::tungstenite::Message;

use super::{DRAIN_TIMEOUT, Rate, Workload};
use crate::cli::http::{Endpoint, ServerEvent};

/// Frames sent and not yet fully answered, oldest first.
#[derive(Default)]
pub(super) struct Flight {
    /// (frame index, when it was sent).
    pub(super) queue: VecDeque<(usize, Instant)>,
    /// The last answered frames, for alarms that arrive after their frame's result.
    pub(super) recent: VecDeque<(usize, Instant)>,
}

/// What one session saw, merged into the report at the end.
#[derive(Debug, Default)]
pub(super) struct Tally {
    pub(super) frames_sent: u64,
    pub(super) epochs_sent: u64,
    pub(super) frames_answered: u64,
    pub(super) results: u64,
    pub(super) out_of_order: u64,
    pub(super) unanswered_frames: u64,
    pub(super) passes: u64,
    pub(super) frame_latency_us: Vec<u32>,
    pub(super) alarm_latency_us: Vec<u32>,
    pub(super) alarms: u64,
    pub(super) states: u64,
    pub(super) errors: BTreeMap<String, u64>,
    pub(super) failures: Vec<String>,
    pub(super) last_answer: Option<Instant>,
}

impl Tally {
    pub(super) fn merge(&mut self, other: Tally) {
        self.frames_sent += other.frames_sent;
        self.epochs_sent += other.epochs_sent;
        self.frames_answered += other.frames_answered;
        self.results += other.results;
        self.out_of_order += other.out_of_order;
        self.unanswered_frames += other.unanswered_frames;
        self.passes += other.passes;
        self.frame_latency_us.extend(other.frame_latency_us);
        self.alarm_latency_us.extend(other.alarm_latency_us);
        self.alarms += other.alarms;
        self.states += other.states;
        for (code, n) in other.errors {
            *self.errors.entry(code).or_default() += n;
        }
        if self.failures.len() < 5 {
            self.failures.extend(other.failures.into_iter().take(5));
        }
        self.last_answer = self.last_answer.max(other.last_answer);
    }
}

pub(super) fn micros(d: Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}

/// The `t` of a `result` message, read without parsing the whole message
/// (the server writes `{"type":"result","t":…,` first); `None` for other messages.
pub(super) fn result_t(text: &str) -> Option<f64> {
    let rest = text.strip_prefix(r#"{"type":"result","t":"#)?;
    let end = rest.find(',')?;
    rest[..end].parse().ok()
}

/// Reads one pass's socket: checks every result against the expected epoch,
/// times frames and alarms, counts errors. Returns when the socket closes.
pub(super) struct Reader {
    pub(super) work: Arc<Workload>,
    pub(super) flight: Arc<Mutex<Flight>>,
    pub(super) drained: Arc<Notify>,
    pub(super) next: usize,
    pub(super) tally: Tally,
}

impl Reader {
    /// Tallies every text message until the socket closes, then wakes the
    /// drain wait and hands back the tally.
    async fn read<S>(mut self, mut stream: S) -> Tally
    where
        S: futures_util::Stream<Item = Result<Message, tokio_tungstenite::tungstenite::Error>>
            + Unpin,
    {
        while let Some(message) = stream.next().await {
            match message {
                Ok(Message::Text(text)) => self.take(&text),
                Ok(Message::Close(_)) | Err(_) => break,
                Ok(_) => {}
            }
        }
        self.drained.notify_one();
        self.tally
    }

    fn answer_front(&mut self, flight: &mut Flight, now: Instant, timed: bool) {
        if let Some((frame, sent)) = flight.queue.pop_front() {
            if timed {
                self.tally.frame_latency_us.push(micros(now - sent));
            }
            self.tally.frames_answered += 1;
            self.tally.last_answer = Some(now);
            self.next = self.work.ranges[frame].end;
            flight.recent.push_back((frame, sent));
            if flight.recent.len() > 64 {
                flight.recent.pop_front();
            }
            if flight.queue.is_empty() {
                self.drained.notify_one();
            }
        }
    }

    fn take(&mut self, text: &str) {
        let now = Instant::now();
        let flight = self.flight.clone();
        let mut flight = flight.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(t) = result_t(text) {
            self.tally.results += 1;
            // serde_json's default float parser may be 1 ulp off the exact value.
            let expected = self.work.times.get(self.next).copied();
            if !expected.is_some_and(|e| (e - t).abs() <= 1e-9 * e.abs().max(1.0)) {
                self.tally.out_of_order += 1;
            }
            self.next += 1;
            if let Some(&(frame, _)) = flight.queue.front()
                && self.next >= self.work.ranges[frame].end
            {
                self.answer_front(&mut flight, now, true);
            }
            return;
        }
        let Ok(event) = serde_json::from_str::<ServerEvent>(text) else {
            *self.tally.errors.entry("unparsable".into()).or_default() += 1;
            return;
        };
        match event {
            ServerEvent::Alarm(alarm) => {
                self.tally.alarms += 1;
                let t = alarm.t;
                let times = &self.work.times;
                let holds = |&&(frame, _): &&(usize, Instant)| {
                    let r = &self.work.ranges[frame];
                    times[r.start] <= t && t <= times[r.end - 1]
                };
                let sent = flight
                    .queue
                    .iter()
                    .find(holds)
                    .or_else(|| flight.recent.iter().rev().find(holds))
                    .map(|&(_, sent)| sent);
                if let Some(sent) = sent {
                    self.tally.alarm_latency_us.push(micros(now - sent));
                }
            }
            ServerEvent::State(_) => self.tally.states += 1,
            ServerEvent::Error(e) => {
                let code = e.code;
                // Frames are handled in order: the error answers the oldest one.
                // A `numerical` failure part-way leaves earlier results counted.
                *self.tally.errors.entry(code).or_default() += 1;
                self.answer_front(&mut flight, now, false);
            }
            ServerEvent::Result | ServerEvent::Other => {}
        }
    }
}

/// Streams session `index` for the run: passes over its variant of the workload
/// until the deadline.
pub(super) async fn run_session(
    endpoint: Arc<Endpoint>,
    id: String,
    work: Arc<Workload>,
    index: usize,
    rate: Rate,
    phase: Duration,
    deadline: Instant,
) -> Tally {
    let mut total = Tally::default();
    let path = format!("/api/v1/sessions/{id}/ingest");
    let mut first = true;
    while Instant::now() < deadline {
        // Only the first pass waits for the session's phase.
        let phase = if first { phase } else { Duration::ZERO };
        let pass = run_pass(&endpoint, &path, &work, index, rate, phase, deadline);
        let tally = match pass.await {
            Ok(tally) => tally,
            Err(e) => {
                total.failures.push(format!("{id}: {e:#}"));
                break;
            }
        };
        first = false;
        total.merge(tally);
    }
    total
}

/// One pass over the workload on a fresh socket: a reader task tallies the
/// answers while frames are sent at the rate, then the pass waits for the last
/// answers (at most [`DRAIN_TIMEOUT`]) and closes.
pub(super) async fn run_pass(
    endpoint: &Endpoint,
    path: &str,
    work: &Arc<Workload>,
    index: usize,
    rate: Rate,
    phase: Duration,
    deadline: Instant,
) -> anyhow::Result<Tally> {
    let socket = endpoint.connect(path).await?;
    let (mut sink, stream) = socket.split();
    let flight = Arc::new(Mutex::new(Flight::default()));
    let drained = Arc::new(Notify::new());
    let reader = Reader {
        work: work.clone(),
        flight: flight.clone(),
        drained: drained.clone(),
        next: 0,
        tally: Tally::default(),
    };
    let reading = tokio::spawn(reader.read(stream));
    let ticks = pacing(rate, phase);
    let sent = send_frames(&mut sink, work, index, &flight, ticks, deadline).await;
    // Wait for every frame's answer, or give up after DRAIN_TIMEOUT.
    let drain_deadline = Instant::now() + DRAIN_TIMEOUT;
    loop {
        let waiting = flight.lock().unwrap_or_else(|p| p.into_inner()).queue.len();
        if waiting == 0 || reading.is_finished() || Instant::now() >= drain_deadline {
            break;
        }
        let _ = tokio::time::timeout_at(drain_deadline, drained.notified()).await;
    }
    let _ = sink.close().await;
    let mut tally = match tokio::time::timeout(Duration::from_secs(5), reading).await {
        Ok(Ok(tally)) => tally,
        _ => bail!("the socket reader did not finish"),
    };
    tally.frames_sent = sent.frames;
    tally.epochs_sent = sent.epochs;
    tally.passes = 1;
    tally.unanswered_frames = flight.lock().unwrap_or_else(|p| p.into_inner()).queue.len() as u64;
    if let Some(e) = sent.error {
        tally
            .failures
            .push(format!("the server dropped the socket: {e}"));
    }
    Ok(tally)
}

/// What one pass sent.
struct Sent {
    frames: u64,
    epochs: u64,
    /// The send that failed, ending the pass early.
    error: Option<tokio_tungstenite::tungstenite::Error>,
}

/// The send clock: `None` sends as fast as the socket takes frames.
fn pacing(rate: Rate, phase: Duration) -> Option<tokio::time::Interval> {
    match rate {
        Rate::Max => None,
        Rate::Hz(hz) => {
            let start = Instant::now() + phase;
            let mut ticks = tokio::time::interval_at(start, Duration::from_secs_f64(1.0 / hz));
            ticks.set_missed_tick_behavior(MissedTickBehavior::Delay);
            Some(ticks)
        }
    }
}

/// Sends session `index`'s frames in order on the clock, stamping each in the
/// flight queue just before it goes, until the deadline or a failed send.
async fn send_frames<S>(
    sink: &mut S,
    work: &Workload,
    index: usize,
    flight: &Mutex<Flight>,
    mut ticks: Option<tokio::time::Interval>,
    deadline: Instant,
) -> Sent
where
    S: futures_util::Sink<Message, Error = tokio_tungstenite::tungstenite::Error> + Unpin,
{
    let mut sent = Sent {
        frames: 0,
        epochs: 0,
        error: None,
    };
    for (k, frame) in work.frames_of_session(index).iter().enumerate() {
        if let Some(ticks) = &mut ticks {
            ticks.tick().await;
        }
        if Instant::now() >= deadline {
            break;
        }
        flight
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .queue
            .push_back((k, Instant::now()));
        if let Err(e) = sink.send(Message::Text(frame.clone())).await {
            sent.error = Some(e);
            break;
        }
        sent.frames += 1;
        sent.epochs += work.ranges[k].len() as u64;
    }
    sent
}
