//! Checkpoints of a monitor's evolving state ([`super::Monitor::checkpoint`] and
//! [`super::Monitor::restore`]), so a session's monitors can move to another node and
//! go on exactly where they were: the same reports, bit for bit.
//!
//! # Format
//! A 6-byte header, then the state as MessagePack (`rmp-serde`, structs as maps):
//!
//! | bytes | content |
//! |---|---|
//! | 0–3 | `NGCP` |
//! | 4 | format version ([`FORMAT_VERSION`]) |
//! | 5 | monitor kind (1 linear, 2 federated, 3 channel, 4 rimu, 5 tacan) |
//! | 6– | the kind's state, nothing after it |
//!
//! MessagePack writes every f64 as its 8 bytes, so NaN (its payload too) and ±inf come
//! back bit for bit (JSON would write them as `null`). Bytes that are not a checkpoint,
//! or of another format version, are refused with [`CheckpointError::Decode`]; a
//! checkpoint of another kind, or one whose state does not fit the monitor (another
//! state dimension, other tests, channels or windows), with
//! [`CheckpointError::Mismatch`], before anything changes.
//!
//! # What is saved
//! The state that evolves with the epochs: filter estimates, detector windows and
//! variances, policies and their counters, test health and consistency diagnostics,
//! learned windows, outlier filters, the last outputs a monitor repeats. Not saved,
//! because the monitor built from the same spec already holds them: configurations,
//! trained models, classifiers, matrices derived from the config, pure caches (the
//! federated monitor's λ_det cache) and scratch buffers. Each saved piece is checked
//! against the freshly built monitor's (`restored` methods of the state types) and the
//! non-state parts are kept from it.
//!
//! The [`super::TestBank`]'s thresholds, threshold specs and policies are saved and
//! restored with the counters (a counter is only meaningful under its policy): a
//! change made after the checkpoint is re-applied by the service through
//! [`super::Monitor::tests_mut`].

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::MonitorKind;

/// The first bytes of every checkpoint.
const MAGIC: [u8; 4] = *b"NGCP";

/// The checkpoint format this build writes and reads. Bump it when a saved type changes
/// in a way an older checkpoint cannot be read as (a new field without a default, a
/// changed meaning); older checkpoints are then refused with [`CheckpointError::Decode`].
pub const FORMAT_VERSION: u8 = 1;

/// Header length: magic, version, kind.
pub(crate) const HEADER: usize = MAGIC.len() + 2;

/// Why a checkpoint could not be written or restored. A failed restore changes nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckpointError {
    /// The state could not be encoded.
    #[error("checkpoint encode: {0}")]
    Encode(String),
    /// The bytes are not a checkpoint this build reads: too short, not a checkpoint,
    /// another format version, or a state that does not decode.
    #[error("checkpoint decode: {0}")]
    Decode(String),
    /// A well-formed checkpoint that does not fit the monitor: of another kind, or a
    /// state of another shape (state dimension, tests, channels, windows).
    #[error("checkpoint mismatch: {0}")]
    Mismatch(String),
}

impl CheckpointError {
    /// A [`CheckpointError::Mismatch`] with `reason`.
    pub fn mismatch(reason: impl Into<String>) -> Self {
        CheckpointError::Mismatch(reason.into())
    }
}

/// The kind's byte in the header.
fn kind_code(kind: MonitorKind) -> u8 {
    match kind {
        MonitorKind::Linear => 1,
        MonitorKind::Federated => 2,
        MonitorKind::Channel => 3,
        MonitorKind::Rimu => 4,
        MonitorKind::Tacan => 5,
        MonitorKind::Gnss => 6,
    }
}

/// The kind a checkpoint holds, from its header alone (the service can check it before
/// it picks the monitor to restore).
pub fn checkpoint_kind(bytes: &[u8]) -> Result<MonitorKind, CheckpointError> {
    if bytes.len() < HEADER || bytes[..MAGIC.len()] != MAGIC {
        return Err(CheckpointError::Decode(
            "not a navguard monitor checkpoint".into(),
        ));
    }
    let version = bytes[MAGIC.len()];
    if version != FORMAT_VERSION {
        return Err(CheckpointError::Decode(format!(
            "checkpoint format version {version}, this build reads version {FORMAT_VERSION}"
        )));
    }
    let code = bytes[MAGIC.len() + 1];
    [
        MonitorKind::Linear,
        MonitorKind::Federated,
        MonitorKind::Channel,
        MonitorKind::Rimu,
        MonitorKind::Tacan,
        MonitorKind::Gnss,
    ]
    .into_iter()
    .find(|&k| kind_code(k) == code)
    .ok_or_else(|| CheckpointError::Decode(format!("unknown monitor kind {code}")))
}

/// The checkpoint of a `kind` monitor whose state is `state`.
pub(crate) fn encode<T: Serialize>(
    kind: MonitorKind,
    state: &T,
) -> Result<Vec<u8>, CheckpointError> {
    let mut out = Vec::with_capacity(4096);
    out.extend_from_slice(&MAGIC);
    out.push(FORMAT_VERSION);
    out.push(kind_code(kind));
    rmp_serde::encode::write_named(&mut out, state)
        .map_err(|e| CheckpointError::Encode(e.to_string()))?;
    Ok(out)
}

/// The state of a `kind` checkpoint: its header checked, the whole body decoded.
pub(crate) fn decode<T: DeserializeOwned>(
    kind: MonitorKind,
    bytes: &[u8],
) -> Result<T, CheckpointError> {
    let found = checkpoint_kind(bytes)?;
    if found != kind {
        return Err(CheckpointError::mismatch(format!(
            "a {} checkpoint, the monitor is {}",
            found.as_str(),
            kind.as_str()
        )));
    }
    let body = &bytes[HEADER..];
    // A cursor, not a borrowed slice: its position tells whether bytes are left over.
    let mut de = rmp_serde::Deserializer::new(std::io::Cursor::new(body));
    let state = T::deserialize(&mut de).map_err(|e| CheckpointError::Decode(e.to_string()))?;
    let used = de.position();
    if used != body.len() as u64 {
        return Err(CheckpointError::Decode(format!(
            "{} bytes after the state",
            body.len() as u64 - used
        )));
    }
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_f64_comes_back_bit_for_bit() {
        let values = vec![
            f64::NAN,
            -f64::NAN,
            f64::from_bits(0x7ff4_dead_beef_0001), // a signalling NaN with a payload
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.0,
            f64::MIN_POSITIVE / 3.0, // subnormal
            f64::MAX,
            0.1 + 0.2,
        ];
        let bytes = encode(MonitorKind::Linear, &values).unwrap();
        let back: Vec<f64> = decode(MonitorKind::Linear, &bytes).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&values));
    }
}
