//! Ingest frames: the epochs a client streams in, parsed and validated once into
//! [`Epoch`]s (degrees on the wire, radians inside), their error codes, and epochs
//! written back as frames.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, IgnoredAny, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use navguard_core::epoch::Epoch;
use navguard_core::epoch::{AdsBlock, CnsBlock, GnssBlock, GnssRawBlock, ImuBlock, InsBlock};

use super::gnss::{OutGnssRaw, WireGnssRaw};
use super::imu::{OutImu, WireImu};

// ---------------------------------------------------------------- ingest frames

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireIns {
    lat: f64,
    lon: f64,
    h: f64,
    vel: [f64; 3],
    att: [f64; 3],
    #[serde(default)]
    f_b: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireGnss {
    lat: f64,
    lon: f64,
    h: f64,
    #[serde(default)]
    vel: Option<[f64; 3]>,
    #[serde(default)]
    pos_sigma: Option<[f64; 3]>,
    #[serde(default)]
    vel_sigma: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireDvl {
    vel_b: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireCns {
    lat: f64,
    lon: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireAds {
    baro_h: f64,
    #[serde(default)]
    tas: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireTacan {
    range_m: f64,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum WireChannel {
    Scalar(f64),
    Vector(Vec<f64>),
}

/// One epoch as it arrives on the ingest socket.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireEpoch {
    t: f64,
    #[serde(default)]
    ins: Option<WireIns>,
    #[serde(default)]
    gnss: Option<WireGnss>,
    #[serde(default)]
    dvl: Option<WireDvl>,
    #[serde(default)]
    cns: Option<WireCns>,
    #[serde(default)]
    ads: Option<WireAds>,
    #[serde(default)]
    tacan: Option<WireTacan>,
    #[serde(default)]
    gyros: Option<Vec<f64>>,
    #[serde(default)]
    channels: Option<BTreeMap<String, WireChannel>>,
    #[serde(default)]
    z: Option<Vec<f64>>,
    #[serde(default)]
    u: Option<Vec<f64>>,
    #[serde(default)]
    gnss_raw: Option<WireGnssRaw>,
    #[serde(default)]
    imu: Option<WireImu>,
}

/// The stable machine-readable code of a refused frame, as sent in `error` events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameErrorCode {
    /// The text is not JSON, or not a frame.
    MalformedJson,
    /// A number is NaN, infinite or out of range.
    NonFinite,
    /// A field no monitor of the session (or no epoch) has.
    UnknownInput,
    /// A vector has the wrong number of elements.
    WrongLength,
    /// The epoch is well-formed JSON but invalid (range, type).
    InvalidEpoch,
    /// `t` is earlier than the previous epoch's.
    TimeBackwards,
    /// The frame is over the size limit.
    FrameTooLarge,
    /// The batch holds more epochs than allowed.
    BatchTooLarge,
    /// The batch holds no epoch.
    EmptyBatch,
    /// A monitor failed numerically on the epoch.
    Numerical,
    /// A server fault (the session's monitors were restarted).
    Internal,
    /// A `gnss_raw` satellite id names no constellation.
    UnknownConstellation,
    /// A `gnss_raw` block holds one satellite twice.
    DuplicateSatellite,
    /// A `gnss_raw` satellite position is not on a GNSS orbit.
    SatellitePosition,
}

impl FrameErrorCode {
    /// The wire string.
    pub fn as_str(self) -> &'static str {
        match self {
            FrameErrorCode::MalformedJson => "malformed_json",
            FrameErrorCode::NonFinite => "non_finite",
            FrameErrorCode::UnknownInput => "unknown_input",
            FrameErrorCode::WrongLength => "wrong_length",
            FrameErrorCode::InvalidEpoch => "invalid_epoch",
            FrameErrorCode::TimeBackwards => "time_backwards",
            FrameErrorCode::FrameTooLarge => "frame_too_large",
            FrameErrorCode::BatchTooLarge => "batch_too_large",
            FrameErrorCode::EmptyBatch => "empty_batch",
            FrameErrorCode::Numerical => "numerical",
            FrameErrorCode::Internal => "internal",
            FrameErrorCode::UnknownConstellation => "unknown_constellation",
            FrameErrorCode::DuplicateSatellite => "duplicate_satellite",
            FrameErrorCode::SatellitePosition => "satellite_position",
        }
    }
}

/// Why an ingest frame was refused. The `code` is stable for clients.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct FrameError {
    /// Machine-readable code.
    pub code: FrameErrorCode,
    /// Human-readable reason.
    pub message: String,
    /// Index of the offending epoch within a batch, when known.
    pub index: Option<usize>,
}

impl FrameError {
    /// Builds an error without an epoch index.
    pub fn new(code: FrameErrorCode, message: impl Into<String>) -> Self {
        FrameError {
            code,
            message: message.into(),
            index: None,
        }
    }

    /// Attaches the epoch index.
    pub fn at(mut self, index: usize) -> Self {
        self.index = Some(index);
        self
    }
}

/// True if the text holds a `NaN` or `Infinity` token outside strings (what
/// Python's `json.dumps` writes for non-finite floats), so the error can say so.
fn has_non_finite_token(text: &str) -> bool {
    let mut in_string = false;
    let mut escaped = false;
    let bytes = text.as_bytes();
    for (i, &c) in bytes.iter().enumerate() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
        } else if c == b'"' {
            in_string = true;
        } else if bytes[i..].starts_with(b"NaN") || bytes[i..].starts_with(b"Infinity") {
            return true;
        }
    }
    false
}

fn classify(err: serde_json::Error, text: &str) -> FrameError {
    let message = err.to_string();
    if message.contains("number out of range") || (err.is_syntax() && has_non_finite_token(text)) {
        return FrameError::new(
            FrameErrorCode::NonFinite,
            format!("non-finite number in frame: {message}"),
        );
    }
    if message.contains("unknown field") {
        return FrameError::new(FrameErrorCode::UnknownInput, message);
    }
    if message.contains("invalid length") {
        return FrameError::new(FrameErrorCode::WrongLength, message);
    }
    if err.is_data() {
        return FrameError::new(FrameErrorCode::InvalidEpoch, message);
    }
    FrameError::new(FrameErrorCode::MalformedJson, message)
}

fn finite(what: &str, values: &[f64]) -> Result<(), FrameError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(FrameError::new(
            FrameErrorCode::NonFinite,
            format!("{what} holds a non-finite number"),
        ))
    }
}

fn latitude(what: &str, lat_deg: f64) -> Result<f64, FrameError> {
    if (-90.0..=90.0).contains(&lat_deg) {
        Ok(lat_deg.to_radians())
    } else {
        Err(FrameError::new(
            FrameErrorCode::InvalidEpoch,
            format!("{what} = {lat_deg}° is outside [-90, 90]"),
        ))
    }
}

fn longitude(what: &str, lon_deg: f64) -> Result<f64, FrameError> {
    if (-360.0..=360.0).contains(&lon_deg) {
        Ok(lon_deg.to_radians())
    } else {
        Err(FrameError::new(
            FrameErrorCode::InvalidEpoch,
            format!("{what} = {lon_deg}° is outside [-360, 360]"),
        ))
    }
}

impl TryFrom<WireIns> for InsBlock {
    type Error = FrameError;

    fn try_from(i: WireIns) -> Result<Self, FrameError> {
        finite("ins", &[i.lat, i.lon, i.h])?;
        finite("ins.vel", &i.vel)?;
        finite("ins.att", &i.att)?;
        if let Some(f) = &i.f_b {
            finite("ins.f_b", f)?;
        }
        Ok(InsBlock {
            lat: latitude("ins.lat", i.lat)?,
            lon: longitude("ins.lon", i.lon)?,
            h: i.h,
            vel: i.vel,
            att: i.att.map(f64::to_radians),
            f_b: i.f_b,
        })
    }
}

impl TryFrom<WireGnss> for GnssBlock {
    type Error = FrameError;

    fn try_from(g: WireGnss) -> Result<Self, FrameError> {
        finite("gnss", &[g.lat, g.lon, g.h])?;
        if let Some(v) = &g.vel {
            finite("gnss.vel", v)?;
        }
        for (what, sigma) in [
            ("gnss.pos_sigma", &g.pos_sigma),
            ("gnss.vel_sigma", &g.vel_sigma),
        ] {
            if let Some(s) = sigma {
                finite(what, s)?;
                if s.iter().any(|&x| x <= 0.0) {
                    return Err(FrameError::new(
                        FrameErrorCode::InvalidEpoch,
                        format!("{what} components must be > 0"),
                    ));
                }
            }
        }
        Ok(GnssBlock {
            lat: latitude("gnss.lat", g.lat)?,
            lon: longitude("gnss.lon", g.lon)?,
            h: g.h,
            vel: g.vel,
            pos_sigma: g.pos_sigma,
            vel_sigma: g.vel_sigma,
        })
    }
}

impl TryFrom<WireCns> for CnsBlock {
    type Error = FrameError;

    fn try_from(c: WireCns) -> Result<Self, FrameError> {
        finite("cns", &[c.lat, c.lon])?;
        Ok(CnsBlock {
            lat: latitude("cns.lat", c.lat)?,
            lon: longitude("cns.lon", c.lon)?,
        })
    }
}

impl TryFrom<WireAds> for AdsBlock {
    type Error = FrameError;

    fn try_from(a: WireAds) -> Result<Self, FrameError> {
        finite("ads.baro_h", &[a.baro_h])?;
        if let Some(tas) = a.tas {
            finite("ads.tas", &[tas])?;
        }
        Ok(AdsBlock {
            baro_h: a.baro_h,
            tas: a.tas,
        })
    }
}

/// The named channels, each value checked finite (`channels.<name>`).
fn channels(map: BTreeMap<String, WireChannel>) -> Result<Vec<(String, Vec<f64>)>, FrameError> {
    let mut out = Vec::with_capacity(map.len());
    for (name, value) in map {
        let values = match value {
            WireChannel::Scalar(v) => vec![v],
            WireChannel::Vector(v) => v,
        };
        finite(&format!("channels.{name}"), &values)?;
        out.push((name, values));
    }
    Ok(out)
}

impl TryFrom<WireEpoch> for Epoch {
    type Error = FrameError;

    fn try_from(w: WireEpoch) -> Result<Self, FrameError> {
        finite("t", &[w.t])?;
        // Blocks are checked in frame order, so the first bad one is the one reported.
        let ins = w.ins.map(InsBlock::try_from).transpose()?;
        let gnss = w.gnss.map(GnssBlock::try_from).transpose()?;
        let dvl_vel_b = match w.dvl {
            Some(d) => {
                finite("dvl.vel_b", &d.vel_b)?;
                Some(d.vel_b)
            }
            None => None,
        };
        let cns = w.cns.map(CnsBlock::try_from).transpose()?;
        let ads = w.ads.map(AdsBlock::try_from).transpose()?;
        let tacan_range_m = match w.tacan {
            Some(t) => {
                finite("tacan.range_m", &[t.range_m])?;
                Some(t.range_m)
            }
            None => None,
        };
        for (what, values) in [("gyros", &w.gyros), ("z", &w.z), ("u", &w.u)] {
            if let Some(v) = values {
                finite(what, v)?;
            }
        }
        Ok(Epoch {
            t: w.t,
            ins,
            gnss,
            dvl_vel_b,
            cns,
            ads,
            tacan_range_m,
            gyros: w.gyros,
            channels: w.channels.map(channels).transpose()?,
            z: w.z,
            u: w.u,
            gnss_raw: w.gnss_raw.map(GnssRawBlock::try_from).transpose()?,
            imu: w.imu.map(ImuBlock::try_from).transpose()?,
        })
    }
}

/// The epochs of a batch frame, parsed one by one so that the count limit
/// stops the parse at the first epoch past it: memory stays proportional to the
/// limit, not to however many tiny epochs fit in a frame (a 1 MiB frame holds
/// 131,072 `{"t":0}`, about 48 MB once parsed).
///
/// Each element is checked and converted into an [`Epoch`] as soon as it is read (one
/// pass, no vector of wire epochs in between). The first epoch refused after parsing
/// (a range, a non-finite number, time going back) is kept in `refused` and the parse
/// goes on over the rest, so that a JSON error or the batch limit later in the frame
/// still takes precedence, as it does when the frame is parsed whole first.
struct Batch<'a> {
    max: usize,
    /// Epochs to reserve room for before the first is read.
    capacity: usize,
    /// Elements the parser has read, the one past the limit included.
    visited: &'a Cell<usize>,
    /// Set when the array holds more than `max` elements.
    over: &'a Cell<bool>,
    /// The first element refused after parsing, with its index.
    refused: &'a Cell<Option<FrameError>>,
}

/// How many epochs to reserve room for before the first is read: an epoch with an INS
/// block is over 100 bytes of JSON, so a frame of them is not grown (and copied) while it
/// is read, and the reservation is never more than the limit.
fn batch_capacity(text_len: usize, max: usize) -> usize {
    (text_len / 100 + 1).min(max)
}

impl<'de> DeserializeSeed<'de> for Batch<'_> {
    type Value = Vec<Epoch>;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

/// Element `i`, parsed, as the batch's next epoch: converted and in time order after
/// `epochs`, or the reason it is refused (with its index).
fn checked(epochs: &[Epoch], i: usize, wire: WireEpoch) -> Result<Epoch, FrameError> {
    let epoch = Epoch::try_from(wire).map_err(|e| e.at(i))?;
    match epochs.last() {
        Some(prev) if epoch.t < prev.t => Err(FrameError::new(
            FrameErrorCode::TimeBackwards,
            format!("t = {} goes back from {} within the batch", epoch.t, prev.t),
        )
        .at(i)),
        _ => Ok(epoch),
    }
}

impl<'de> Visitor<'de> for Batch<'_> {
    type Value = Vec<Epoch>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an array of epochs")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut epochs = Vec::with_capacity(self.capacity);
        let mut refused = None;
        let mut read = 0;
        while read < self.max {
            match seq.next_element::<WireEpoch>()? {
                Some(wire) => {
                    // Past a refused epoch the rest are only parsed (for JSON errors).
                    if refused.is_none() {
                        match checked(&epochs, read, wire) {
                            Ok(epoch) => epochs.push(epoch),
                            Err(e) => refused = Some(e),
                        }
                    }
                    read += 1;
                    self.visited.set(read);
                }
                None => {
                    self.refused.set(refused);
                    return Ok(epochs);
                }
            }
        }
        // One element more is enough to refuse: skip it without keeping it and stop.
        if seq.next_element::<IgnoredAny>()?.is_some() {
            self.visited.set(read + 1);
            self.over.set(true);
            return Err(de::Error::custom("batch over the epoch limit"));
        }
        self.refused.set(refused);
        Ok(epochs)
    }
}

/// Parses a batch frame's array into checked epochs; also says how many elements were
/// read. Errors in the order a whole-frame parse would give them: the JSON (or the
/// limit) first, then the first refused epoch.
fn parse_batch(text: &str, max_batch: usize) -> (Result<Vec<Epoch>, FrameError>, usize) {
    let (visited, over, refused) = (Cell::new(0), Cell::new(false), Cell::new(None));
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let result = Batch {
        max: max_batch,
        capacity: batch_capacity(text.len(), max_batch),
        visited: &visited,
        over: &over,
        refused: &refused,
    }
    .deserialize(&mut deserializer)
    .and_then(|epochs| deserializer.end().map(|()| epochs));
    let result = match (result, refused.take()) {
        (Err(_), _) if over.get() => Err(FrameError::new(
            FrameErrorCode::BatchTooLarge,
            format!("batch holds more than {max_batch} epochs, the limit"),
        )),
        (Err(e), _) => Err(classify(e, text)),
        (Ok(_), Some(refusal)) => Err(refusal),
        (Ok(epochs), None) => Ok(epochs),
    };
    (result, visited.get())
}

/// Parses an ingest frame: one epoch object or an array of them, at most
/// `max_batch` epochs. Times must not decrease within the frame.
pub fn parse_frame(text: &str, max_batch: usize) -> Result<Vec<Epoch>, FrameError> {
    let trimmed = text.trim_start();
    if !trimmed.starts_with('[') {
        let wire: WireEpoch = serde_json::from_str(text).map_err(|e| classify(e, text))?;
        return Ok(vec![Epoch::try_from(wire).map_err(|e| e.at(0))?]);
    }
    let epochs = parse_batch(text, max_batch).0?;
    if epochs.is_empty() {
        return Err(FrameError::new(
            FrameErrorCode::EmptyBatch,
            "a batch must hold at least one epoch",
        ));
    }
    Ok(epochs)
}

// ------------------------------------------------------- epochs back to the wire

#[derive(Debug, Serialize)]
struct OutIns {
    lat: f64,
    lon: f64,
    h: f64,
    vel: [f64; 3],
    att: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    f_b: Option<[f64; 3]>,
}

#[derive(Debug, Serialize)]
struct OutGnss {
    lat: f64,
    lon: f64,
    h: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    vel: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pos_sigma: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    vel_sigma: Option<[f64; 3]>,
}

#[derive(Debug, Serialize)]
struct OutDvl {
    vel_b: [f64; 3],
}

#[derive(Debug, Serialize)]
struct OutCns {
    lat: f64,
    lon: f64,
}

#[derive(Debug, Serialize)]
struct OutAds {
    baro_h: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    tas: Option<f64>,
}

#[derive(Debug, Serialize)]
struct OutTacan {
    range_m: f64,
}

#[derive(Debug, Serialize)]
#[serde(untagged)]
enum OutChannel<'a> {
    Scalar(f64),
    Vector(&'a [f64]),
}

/// One epoch in the ingest wire format, fields in the order docs/architecture.md §A6 lists them.
#[derive(Debug, Serialize)]
struct OutEpoch<'a> {
    t: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    ins: Option<OutIns>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gnss: Option<OutGnss>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dvl: Option<OutDvl>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cns: Option<OutCns>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ads: Option<OutAds>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tacan: Option<OutTacan>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gyros: Option<&'a [f64]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    channels: Option<BTreeMap<&'a str, OutChannel<'a>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    z: Option<&'a [f64]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    u: Option<&'a [f64]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gnss_raw: Option<OutGnssRaw>,
    #[serde(skip_serializing_if = "Option::is_none")]
    imu: Option<OutImu>,
}

/// Serialises a domain `Epoch` to one ingest frame (a JSON object, degrees on
/// the wire): the inverse of [`parse_frame`] for one epoch, used by
/// `navguard simulate` to write JSON lines. A one-element channel is written as
/// a scalar, which parses back to the same one-element vector. Refuses (code
/// `non_finite`) an epoch holding a non-finite number, which JSON cannot carry.
pub fn epoch_to_wire(epoch: &Epoch) -> Result<String, FrameError> {
    let mut numbers: Vec<f64> = vec![epoch.t];
    if let Some(i) = &epoch.ins {
        numbers.extend([i.lat, i.lon, i.h]);
        numbers.extend(i.vel.iter().chain(&i.att).chain(i.f_b.iter().flatten()));
    }
    if let Some(g) = &epoch.gnss {
        numbers.extend([g.lat, g.lon, g.h]);
        numbers.extend(g.vel.iter().flatten());
        numbers.extend(g.pos_sigma.iter().chain(&g.vel_sigma).flatten());
    }
    numbers.extend(epoch.dvl_vel_b.iter().flatten());
    if let Some(c) = &epoch.cns {
        numbers.extend([c.lat, c.lon]);
    }
    if let Some(a) = &epoch.ads {
        numbers.push(a.baro_h);
        numbers.extend(a.tas);
    }
    numbers.extend(epoch.tacan_range_m);
    for v in [&epoch.gyros, &epoch.z, &epoch.u].into_iter().flatten() {
        numbers.extend(v);
    }
    for (_, v) in epoch.channels.iter().flatten() {
        numbers.extend(v);
    }
    if let Some(b) = &epoch.gnss_raw {
        super::gnss::numbers(b, &mut numbers);
    }
    if let Some(b) = &epoch.imu {
        super::imu::numbers(b, &mut numbers);
    }
    finite("epoch", &numbers)?;
    let out = OutEpoch {
        t: epoch.t,
        ins: epoch.ins.as_ref().map(|i| OutIns {
            lat: i.lat.to_degrees(),
            lon: i.lon.to_degrees(),
            h: i.h,
            vel: i.vel,
            att: i.att.map(f64::to_degrees),
            f_b: i.f_b,
        }),
        gnss: epoch.gnss.as_ref().map(|g| OutGnss {
            lat: g.lat.to_degrees(),
            lon: g.lon.to_degrees(),
            h: g.h,
            vel: g.vel,
            pos_sigma: g.pos_sigma,
            vel_sigma: g.vel_sigma,
        }),
        dvl: epoch.dvl_vel_b.map(|vel_b| OutDvl { vel_b }),
        cns: epoch.cns.as_ref().map(|c| OutCns {
            lat: c.lat.to_degrees(),
            lon: c.lon.to_degrees(),
        }),
        ads: epoch.ads.as_ref().map(|a| OutAds {
            baro_h: a.baro_h,
            tas: a.tas,
        }),
        tacan: epoch.tacan_range_m.map(|range_m| OutTacan { range_m }),
        gyros: epoch.gyros.as_deref(),
        channels: epoch.channels.as_ref().map(|channels| {
            channels
                .iter()
                .map(|(name, v)| {
                    let value = match v.as_slice() {
                        [x] => OutChannel::Scalar(*x),
                        v => OutChannel::Vector(v),
                    };
                    (name.as_str(), value)
                })
                .collect()
        }),
        z: epoch.z.as_deref(),
        u: epoch.u.as_deref(),
        gnss_raw: epoch.gnss_raw.as_ref().map(OutGnssRaw::from),
        imu: epoch.imu.as_ref().map(OutImu::from),
    };
    serde_json::to_string(&out)
        .map_err(|e| FrameError::new(FrameErrorCode::InvalidEpoch, e.to_string()))
}

/// Epochs written as ingest frames and parsed back, one by one: what a server gets from
/// a file of them (`navguard replay`). Degrees on the wire do not always round-trip to the
/// same radians, so an in-process run that must match a server's bit for bit runs on
/// these.
pub fn through_the_wire(epochs: &[Epoch]) -> Result<Vec<Epoch>, FrameError> {
    let mut out = Vec::with_capacity(epochs.len());
    for e in epochs {
        out.extend(parse_frame(&epoch_to_wire(e)?, 1)?);
    }
    Ok(out)
}

#[cfg(test)]
mod batch_tests {
    use super::*;

    fn tiny_epochs(n: usize) -> String {
        format!("[{}]", vec![r#"{"t":0}"#; n].join(","))
    }

    #[test]
    fn a_batch_over_the_limit_stops_parsing_one_epoch_past_it() {
        // 131,072 tiny epochs: a 1 MiB frame. The parser reads 11 and stops.
        let text = tiny_epochs(131_072);
        let (result, visited) = parse_batch(&text, 10);
        assert_eq!(result.unwrap_err().code, FrameErrorCode::BatchTooLarge);
        assert_eq!(visited, 11);
        let e = parse_frame(&text, 10).unwrap_err();
        assert_eq!(e.code, FrameErrorCode::BatchTooLarge);
        assert!(e.message.contains("10"), "{}", e.message);
    }

    #[test]
    fn a_batch_at_the_limit_parses_whole() {
        let (result, visited) = parse_batch(&tiny_epochs(10), 10);
        assert_eq!(result.unwrap().len(), 10);
        assert_eq!(visited, 10);
        assert_eq!(parse_frame(&tiny_epochs(10), 10).unwrap().len(), 10);
    }

    #[test]
    fn batch_errors_keep_their_codes() {
        let code = |text: &str| parse_frame(text, 3).unwrap_err().code;
        assert_eq!(code("[]"), FrameErrorCode::EmptyBatch);
        assert_eq!(code(r#"[{"t":0},"#), FrameErrorCode::MalformedJson);
        assert_eq!(code(r#"[{"t":0}] x"#), FrameErrorCode::MalformedJson);
        assert_eq!(code(r#"[{"t":0,"lidar":1}]"#), FrameErrorCode::UnknownInput);
        assert_eq!(code(r#"[{"t":0,"z":[NaN]}]"#), FrameErrorCode::NonFinite);
        assert_eq!(
            code(r#"[{"t":0,"dvl":{"vel_b":[1]}}]"#),
            FrameErrorCode::WrongLength
        );
        assert_eq!(code(r#"[{"z":[1]}]"#), FrameErrorCode::InvalidEpoch);
        // The epoch past the limit is skipped, not checked; it must still be JSON.
        assert_eq!(
            code(r#"[{"t":0},{"t":0},{"t":0},{"lidar":1}]"#),
            FrameErrorCode::BatchTooLarge
        );
        assert_eq!(
            code(r#"[{"t":0},{"t":0},{"t":0},{"t":"#),
            FrameErrorCode::MalformedJson
        );
    }

    #[test]
    fn a_refused_epoch_yields_to_later_json_errors_and_the_limit() {
        // Epochs are converted as they are read; the first refusal is reported with its
        // index only if the whole frame is JSON within the limit.
        let bad_lat = r#"{"t":1,"cns":{"lat":91,"lon":0}}"#;
        let refused = parse_frame(&format!(r#"[{{"t":0}},{bad_lat},{{"t":2}}]"#), 3).unwrap_err();
        assert_eq!(
            (refused.code, refused.index),
            (FrameErrorCode::InvalidEpoch, Some(1))
        );
        let json = parse_frame(&format!(r#"[{{"t":0}},{bad_lat},{{"t":"#), 3).unwrap_err();
        assert_eq!(
            (json.code, json.index),
            (FrameErrorCode::MalformedJson, None)
        );
        let unknown = parse_frame(&format!(r#"[{bad_lat},{{"t":2,"lidar":1}}]"#), 3).unwrap_err();
        assert_eq!(unknown.code, FrameErrorCode::UnknownInput);
        let over =
            parse_frame(&format!(r#"[{bad_lat},{{"t":2}},{{"t":3}},{{"t":4}}]"#), 3).unwrap_err();
        assert_eq!(over.code, FrameErrorCode::BatchTooLarge);
        // Only the first refusal counts: time going back at 2, a bad latitude at 3.
        let back =
            parse_frame(&format!(r#"[{{"t":5}},{{"t":6}},{{"t":4}},{bad_lat}]"#), 4).unwrap_err();
        assert_eq!(
            (back.code, back.index),
            (FrameErrorCode::TimeBackwards, Some(2))
        );
        assert!(
            back.message.contains("t = 4 goes back from 6"),
            "{}",
            back.message
        );
    }

    #[test]
    fn epochs_convert_as_they_are_read() {
        let epochs = parse_frame(
            r#"[{"t":0.5,"cns":{"lat":30,"lon":-120}},{"t":0.5,"tacan":{"range_m":12.5}}]"#,
            2,
        )
        .unwrap();
        assert_eq!(epochs.len(), 2);
        let cns = epochs[0].cns.as_ref().unwrap();
        assert_eq!(
            (cns.lat, cns.lon),
            (30f64.to_radians(), (-120f64).to_radians())
        );
        assert_eq!(epochs[1].tacan_range_m, Some(12.5));
        assert_eq!(batch_capacity(0, 10), 1);
        assert_eq!(batch_capacity(1 << 20, 10), 10);
        assert_eq!(batch_capacity(1_000, 100), 11);
    }
}

#[cfg(test)]
mod epoch_to_wire_tests {
    use super::*;

    fn full_epoch() -> Epoch {
        Epoch {
            t: 1080.25,
            ins: Some(InsBlock {
                lat: 30.5f64.to_radians(),
                lon: 114.25f64.to_radians(),
                h: 12.5,
                vel: [3.0, -4.0, 0.01],
                att: [
                    0.5f64.to_radians(),
                    -1.0f64.to_radians(),
                    359.0f64.to_radians(),
                ],
                f_b: Some([0.01, 0.02, 9.79]),
            }),
            gnss: Some(GnssBlock {
                lat: 30.500_01f64.to_radians(),
                lon: 114.25f64.to_radians(),
                h: 11.0,
                vel: Some([3.1, -3.9, 0.0]),
                pos_sigma: Some([0.5, 0.6, 1.2]),
                vel_sigma: None,
            }),
            dvl_vel_b: Some([0.0, 5.0, 0.0]),
            cns: Some(CnsBlock {
                lat: 30.49f64.to_radians(),
                lon: -114.25f64.to_radians(),
            }),
            ads: Some(AdsBlock {
                baro_h: 1200.0,
                tas: None,
            }),
            tacan_range_m: Some(12_345.6),
            gyros: Some(vec![1e-3, -2e-3, 0.0, 5e-4]),
            channels: Some(vec![
                ("baro_minus_gnss".to_owned(), vec![0.25]),
                ("innov".to_owned(), vec![1.0, 2.0]),
            ]),
            z: Some(vec![1.5]),
            u: Some(vec![-0.5]),
            gnss_raw: Some(GnssRawBlock {
                sats: vec![navguard_core::epoch::SatObs {
                    id: navguard_core::epoch::SatId::parse("C30").unwrap(),
                    pr: 38_000_123.25,
                    pos: [-32e6, 27e6, 0.5e6],
                    clk: -1.5,
                    iono: Some(3.25),
                    tropo: None,
                    sigma: Some(4.0),
                    cn0: Some(38.5),
                    el: Some(0.5),
                    az: None,
                }],
                truth: Some([0.6, -2.1, -28.0]),
            }),
            imu: Some(ImuBlock {
                accel: [0.125, -0.25, 9.75],
                gyro: [0.01, -0.02, 0.5],
                dt: None,
            }),
        }
    }

    fn assert_close(a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= 1e-15 * x.abs().max(1.0), "{x} vs {y}");
        }
    }

    #[test]
    fn an_epoch_survives_the_round_trip_through_the_wire() {
        let epoch = full_epoch();
        let text = epoch_to_wire(&epoch).unwrap();
        let back = parse_frame(&text, 1).unwrap().remove(0);
        assert_eq!(back.t, epoch.t);
        let (a, b) = (back.ins.as_ref().unwrap(), epoch.ins.as_ref().unwrap());
        assert_close(&[a.lat, a.lon, a.h], &[b.lat, b.lon, b.h]);
        assert_close(&a.att, &b.att);
        assert_eq!((a.vel, a.f_b), (b.vel, b.f_b));
        let (a, b) = (back.gnss.as_ref().unwrap(), epoch.gnss.as_ref().unwrap());
        assert_close(&[a.lat, a.lon, a.h], &[b.lat, b.lon, b.h]);
        assert_eq!(
            (a.vel, a.pos_sigma, a.vel_sigma),
            (b.vel, b.pos_sigma, b.vel_sigma)
        );
        let (a, b) = (back.imu.unwrap(), epoch.imu.unwrap());
        assert_eq!((a.accel, a.dt), (b.accel, b.dt));
        assert_close(&a.gyro, &b.gyro);
        let (a, b) = (back.cns.as_ref().unwrap(), epoch.cns.as_ref().unwrap());
        assert_close(&[a.lat, a.lon], &[b.lat, b.lon]);
        assert_eq!(back.dvl_vel_b, epoch.dvl_vel_b);
        assert_eq!(back.ads, epoch.ads);
        assert_eq!(back.tacan_range_m, epoch.tacan_range_m);
        assert_eq!(back.gyros, epoch.gyros);
        assert_eq!(back.channels, epoch.channels);
        assert_eq!((back.z, back.u), (epoch.z, epoch.u));
        let (a, b) = (back.gnss_raw.unwrap(), epoch.gnss_raw.unwrap());
        assert_close(&a.truth.unwrap(), &b.truth.unwrap());
        let (a, b) = (&a.sats[0], &b.sats[0]);
        assert_close(&[a.el.unwrap()], &[b.el.unwrap()]);
        assert_eq!((a.id, a.pr, a.pos, a.clk), (b.id, b.pr, b.pos, b.clk));
        assert_eq!(
            (a.iono, a.tropo, a.sigma, a.cn0, a.az),
            (b.iono, b.tropo, b.sigma, b.cn0, b.az)
        );
    }

    #[test]
    fn the_wire_carries_degrees_and_omits_absent_blocks() {
        let epoch = Epoch {
            t: 2.0,
            cns: Some(CnsBlock {
                lat: std::f64::consts::FRAC_PI_4,
                lon: -std::f64::consts::FRAC_PI_2,
            }),
            ..Epoch::default()
        };
        let text = epoch_to_wire(&epoch).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["cns"]["lat"], 45.0);
        assert_eq!(v["cns"]["lon"], -90.0);
        assert_eq!(v.as_object().unwrap().len(), 2, "{text}");
        assert!(text.starts_with(r#"{"t":2.0"#), "{text}");
    }

    #[test]
    fn non_finite_epochs_are_refused() {
        let epoch = Epoch {
            t: 0.0,
            z: Some(vec![f64::NAN]),
            ..Epoch::default()
        };
        assert_eq!(
            epoch_to_wire(&epoch).unwrap_err().code.as_str(),
            "non_finite"
        );
    }
}
