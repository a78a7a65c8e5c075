//! A session's checkpoint (docs/deployment.md, Failover): every monitor's evolving state
//! (`Monitor::checkpoint`), its availability, the session's statistics, the stream's
//! position (last epoch time, epoch count) and its recording stream id, as MessagePack
//! (exact for every f64). The 1 Hz statistics history is not carried: a resumed session's
//! history chart starts at the resume.
//!
//! Thresholds and policies are part of the spec, which the store holds apart: after a
//! restore, each monitor's tests take the configuration of the monitors built from the
//! stored spec, so a threshold changed after the last checkpoint is not undone.

use serde::{Deserialize, Serialize};

use super::Actor;
use crate::monitor::{Availability, TestBank};
use crate::service::session::stats::{SessionStats, TestRunning};
use crate::service::store::Checkpoint;

/// The checkpoint format this server writes and reads.
const FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
struct Envelope {
    format: u32,
    monitors: Vec<MonitorState>,
    stats: SessionStats,
    /// The statistics' running values the wire form leaves out: per monitor and test,
    /// and per monitor the integrity timeline's last epoch time.
    running: Vec<(String, String, TestRunning)>,
    integrity_t: Vec<(String, f64)>,
    last_t: Option<f64>,
    stream_epochs: u64,
    recording_stream: u64,
}

#[derive(Serialize, Deserialize)]
struct MonitorState {
    name: String,
    availability: Option<Availability>,
    state: Vec<u8>,
}

/// The actor's state as checkpoint bytes.
pub(super) fn encode(actor: &Actor) -> Result<Vec<u8>, String> {
    let mut monitors = Vec::with_capacity(actor.monitors.len());
    for (m, engine) in actor.monitors.iter().zip(&actor.engines) {
        monitors.push(MonitorState {
            name: m.name.clone(),
            availability: m.availability,
            state: engine
                .checkpoint()
                .map_err(|e| format!("monitor '{}': {e}", m.name))?,
        });
    }
    let mut running = Vec::new();
    let mut integrity_t = Vec::new();
    for (monitor, m) in &actor.stats.monitors {
        for (test, t) in &m.tests {
            running.push((monitor.clone(), test.to_string(), t.running()));
        }
        if let Some(i) = &m.integrity {
            integrity_t.push((monitor.clone(), i.running_t()));
        }
    }
    let envelope = Envelope {
        format: FORMAT,
        monitors,
        stats: actor.stats.clone(),
        running,
        integrity_t,
        last_t: actor.last_t,
        stream_epochs: actor.stream_epochs,
        recording_stream: actor.recording_stream,
    };
    rmp_serde::to_vec_named(&envelope).map_err(|e| e.to_string())
}

/// Restores `checkpoint` into a freshly built actor. On `Err` the actor is as built.
pub(super) fn restore(actor: &mut Actor, checkpoint: &Checkpoint) -> Result<(), String> {
    let envelope: Envelope = rmp_serde::from_slice(&checkpoint.state).map_err(|e| e.to_string())?;
    if envelope.format != FORMAT {
        return Err(format!(
            "checkpoint format {} (this server reads {FORMAT})",
            envelope.format
        ));
    }
    let names: Vec<&str> = actor.monitors.iter().map(|m| m.name.as_str()).collect();
    let saved: Vec<&str> = envelope.monitors.iter().map(|m| m.name.as_str()).collect();
    if names != saved {
        return Err(format!(
            "checkpoint monitors {saved:?}, the session has {names:?}"
        ));
    }
    for (k, saved) in envelope.monitors.iter().enumerate() {
        let engine = &mut actor.engines[k];
        let configured = engine.tests().clone();
        if let Err(e) = engine.restore(&saved.state) {
            for (m, engine) in actor.monitors[..k].iter_mut().zip(&mut actor.engines) {
                engine.reset();
                m.availability = None;
            }
            return Err(format!("monitor '{}': {e}", saved.name));
        }
        reapply_configuration(engine.tests_mut(), &configured);
        actor.monitors[k].availability = saved.availability;
    }
    let mut stats = envelope.stats;
    for (monitor, test, r) in &envelope.running {
        if let Some(t) = stats
            .monitors
            .get_mut(monitor)
            .and_then(|m| m.tests.get_mut(test.as_str()))
        {
            t.set_running(*r);
        }
    }
    for (monitor, t) in &envelope.integrity_t {
        if let Some(i) = stats
            .monitors
            .get_mut(monitor)
            .and_then(|m| m.integrity.as_mut())
        {
            i.set_running_t(*t);
        }
    }
    stats.connected = false;
    stats.epochs_per_s = 0.0;
    for (m, engine) in actor.monitors.iter().zip(&actor.engines) {
        if let Some(ms) = stats.monitors.get_mut(&m.name) {
            for slot in engine.tests().slots() {
                if let Some(t) = ms.tests.get_mut(&slot.name) {
                    t.threshold = slot.threshold;
                    t.state = slot.policy.health();
                }
            }
        }
    }
    actor.stats = stats;
    actor.last_t = envelope.last_t;
    actor.stream_epochs = envelope.stream_epochs;
    actor.recording_stream = envelope.recording_stream;
    Ok(())
}

/// Gives `restored` the thresholds and policies of `configured` (built from the stored
/// spec) where they differ, as a `PUT …/threshold` would, keeping the restored counters
/// where the configuration did not change.
fn reapply_configuration(restored: &mut TestBank, configured: &TestBank) {
    if restored.policy() != configured.policy() {
        restored.set_policy(configured.policy());
    }
    if restored.spec() != configured.spec() {
        // The configured spec was valid when it was built from; it stays valid here.
        let _ = restored.set_spec(configured.spec());
    }
    for (i, slot) in configured.slots().iter().enumerate() {
        let differs = restored
            .slots()
            .get(i)
            .is_some_and(|r| r.own_spec != slot.own_spec);
        if differs {
            let _ = restored.set_test_spec(i, slot.own_spec);
        }
    }
}
