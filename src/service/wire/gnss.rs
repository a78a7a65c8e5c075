//! The `gnss_raw` block of an ingest epoch: per satellite a pseudorange and what is
//! needed to use it (docs/methods.md §M26), parsed and checked here into
//! [`GnssRawBlock`]; and the block written back as a frame (`navguard convert`).
//! Angles are degrees on the wire, radians inside.

use serde::{Deserialize, Serialize};

use navguard_core::epoch::{GnssRawBlock, SatId, SatIdError, SatObs};

use super::ingest::{FrameError, FrameErrorCode};

/// Most satellites one epoch may carry (every constellation in view, with room).
pub const MAX_SATELLITES: usize = 200;

/// Satellite orbit radii accepted, m: from below GLONASS's (25,500 km) and Galileo's
/// MEO to above the geostationary ring and QZSS's apogee (42,164 km; ~46,000 km).
pub const ORBIT_RADIUS_M: std::ops::RangeInclusive<f64> = 20.0e6..=50.0e6;

/// Pseudoranges accepted, m: positive and below 1,000 km beyond any orbit (a receiver
/// clock offset of a few ms adds up to ~1,000 km).
pub const PSEUDORANGE_M: std::ops::RangeInclusive<f64> = 1.0e6..=1.0e9;

/// One satellite as it arrives.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WireSat {
    id: String,
    pr: f64,
    pos: [f64; 3],
    clk: f64,
    #[serde(default)]
    iono: Option<f64>,
    #[serde(default)]
    tropo: Option<f64>,
    #[serde(default)]
    sigma: Option<f64>,
    #[serde(default)]
    cn0: Option<f64>,
    #[serde(default)]
    el: Option<f64>,
    #[serde(default)]
    az: Option<f64>,
}

/// The true position, degrees and metres.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WireTruth {
    lat: f64,
    lon: f64,
    h: f64,
}

/// The `gnss_raw` block as it arrives.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WireGnssRaw {
    sats: Vec<WireSat>,
    #[serde(default)]
    truth: Option<WireTruth>,
}

fn refused(code: FrameErrorCode, message: String) -> FrameError {
    FrameError::new(code, message)
}

fn finite(what: &str, values: &[f64]) -> Result<(), FrameError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(refused(
            FrameErrorCode::NonFinite,
            format!("{what} holds a non-finite number"),
        ))
    }
}

fn within(what: &str, v: f64, range: std::ops::RangeInclusive<f64>) -> Result<(), FrameError> {
    if range.contains(&v) {
        Ok(())
    } else {
        Err(refused(
            FrameErrorCode::InvalidEpoch,
            format!(
                "{what} = {v} is outside [{}, {}]",
                range.start(),
                range.end()
            ),
        ))
    }
}

fn sat_id(i: usize, id: &str) -> Result<SatId, FrameError> {
    SatId::parse(id).map_err(|e| match e {
        SatIdError::UnknownConstellation(_) => refused(
            FrameErrorCode::UnknownConstellation,
            format!("gnss_raw.sats[{i}].id '{id}': {e}"),
        ),
        SatIdError::Malformed => refused(
            FrameErrorCode::InvalidEpoch,
            format!("gnss_raw.sats[{i}].id '{id}': {e}"),
        ),
    })
}

fn satellite(i: usize, s: WireSat) -> Result<SatObs, FrameError> {
    let at = |field: &str| format!("gnss_raw.sats[{i}].{field}");
    let id = sat_id(i, &s.id)?;
    let optional = [s.iono, s.tropo, s.sigma, s.cn0, s.el, s.az];
    finite(&format!("gnss_raw.sats[{i}] ({})", s.id), &[s.pr, s.clk])?;
    finite(&at("pos"), &s.pos)?;
    finite(
        &format!("gnss_raw.sats[{i}] ({})", s.id),
        &optional.map(|v| v.unwrap_or(0.0)),
    )?;
    within(&at("pr"), s.pr, PSEUDORANGE_M)?;
    let radius = s.pos.iter().map(|x| x * x).sum::<f64>().sqrt();
    if !ORBIT_RADIUS_M.contains(&radius) {
        return Err(refused(
            FrameErrorCode::SatellitePosition,
            format!(
                "{} ({}) is {:.0} km from the Earth's centre, not on a GNSS orbit \
                 (20,000-50,000 km); positions are ECEF metres",
                at("pos"),
                s.id,
                radius / 1e3
            ),
        ));
    }
    for (field, value, range) in [
        ("iono", s.iono, -100.0..=1_000.0),
        ("tropo", s.tropo, -10.0..=1_000.0),
        ("sigma", s.sigma, 1e-4..=1e5),
        ("cn0", s.cn0, 0.0..=100.0),
        ("el", s.el, -90.0..=90.0),
        ("az", s.az, -360.0..=360.0),
    ] {
        if let Some(v) = value {
            within(&at(field), v, range)?;
        }
    }
    Ok(SatObs {
        id,
        pr: s.pr,
        pos: s.pos,
        clk: s.clk,
        iono: s.iono,
        tropo: s.tropo,
        sigma: s.sigma,
        cn0: s.cn0,
        el: s.el.map(f64::to_radians),
        az: s.az.map(f64::to_radians),
    })
}

impl TryFrom<WireGnssRaw> for GnssRawBlock {
    type Error = FrameError;

    fn try_from(w: WireGnssRaw) -> Result<Self, FrameError> {
        if w.sats.len() > MAX_SATELLITES {
            return Err(refused(
                FrameErrorCode::InvalidEpoch,
                format!(
                    "gnss_raw.sats holds {} satellites, at most {MAX_SATELLITES}",
                    w.sats.len()
                ),
            ));
        }
        let mut sats: Vec<SatObs> = Vec::with_capacity(w.sats.len());
        for (i, s) in w.sats.into_iter().enumerate() {
            let sat = satellite(i, s)?;
            if sats.iter().any(|o| o.id == sat.id) {
                return Err(refused(
                    FrameErrorCode::DuplicateSatellite,
                    format!("gnss_raw.sats[{i}]: satellite {} appears twice", sat.id),
                ));
            }
            sats.push(sat);
        }
        let truth = match w.truth {
            Some(t) => {
                finite("gnss_raw.truth", &[t.lat, t.lon, t.h])?;
                within("gnss_raw.truth.lat", t.lat, -90.0..=90.0)?;
                within("gnss_raw.truth.lon", t.lon, -360.0..=360.0)?;
                Some([t.lat.to_radians(), t.lon.to_radians(), t.h])
            }
            None => None,
        };
        Ok(GnssRawBlock { sats, truth })
    }
}

/// One satellite written back.
#[derive(Debug, Serialize)]
struct OutSat {
    id: String,
    pr: f64,
    pos: [f64; 3],
    clk: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    iono: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tropo: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sigma: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cn0: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    el: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    az: Option<f64>,
}

/// The `gnss_raw` block written back (degrees on the wire).
#[derive(Debug, Serialize)]
pub(super) struct OutGnssRaw {
    sats: Vec<OutSat>,
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<WireTruth>,
}

impl From<&GnssRawBlock> for OutGnssRaw {
    fn from(b: &GnssRawBlock) -> Self {
        let sats = b
            .sats
            .iter()
            .map(|s| OutSat {
                id: s.id.to_string(),
                pr: s.pr,
                pos: s.pos,
                clk: s.clk,
                iono: s.iono,
                tropo: s.tropo,
                sigma: s.sigma,
                cn0: s.cn0,
                el: s.el.map(f64::to_degrees),
                az: s.az.map(f64::to_degrees),
            })
            .collect();
        let truth = b.truth.map(|[lat, lon, h]| WireTruth {
            lat: lat.to_degrees(),
            lon: lon.to_degrees(),
            h,
        });
        OutGnssRaw { sats, truth }
    }
}

/// Every number of the block, for the finiteness check before writing.
pub(super) fn numbers(b: &GnssRawBlock, out: &mut Vec<f64>) {
    for s in &b.sats {
        out.extend([s.pr, s.clk]);
        out.extend(s.pos);
        out.extend(
            [s.iono, s.tropo, s.sigma, s.cn0, s.el, s.az]
                .into_iter()
                .flatten(),
        );
    }
    out.extend(b.truth.iter().flatten());
}

#[cfg(test)]
mod tests {
    use super::super::ingest::parse_frame;
    use super::*;

    const SAT: &str =
        r#"{"id":"G05","pr":21000000.5,"pos":[15600000.0,7540000.0,20140000.0],"clk":12.5}"#;

    fn frame(sats: &[&str]) -> String {
        format!(r#"{{"t":1,"gnss_raw":{{"sats":[{}]}}}}"#, sats.join(","))
    }

    fn code(text: &str) -> FrameErrorCode {
        parse_frame(text, 10).unwrap_err().code
    }

    #[test]
    fn a_block_parses_into_radians_and_ids() {
        let sat = r#"{"id":"E11","pr":23000000,"pos":[0,0,29600000],"clk":-3,"iono":4.5,"sigma":3,"cn0":41,"el":30,"az":270}"#;
        let text = format!(
            r#"{{"t":1,"gnss_raw":{{"sats":[{SAT},{sat}],"truth":{{"lat":37.5,"lon":-122,"h":-28}}}}}}"#
        );
        let e = parse_frame(&text, 10).unwrap().remove(0);
        let b = e.gnss_raw.unwrap();
        assert_eq!(b.sats.len(), 2);
        assert_eq!(b.sats[0].id.to_string(), "G05");
        assert_eq!(b.sats[1].id.to_string(), "E11");
        assert_eq!(b.sats[1].el, Some(30f64.to_radians()));
        assert_eq!(b.sats[1].az, Some(270f64.to_radians()));
        assert_eq!(b.sats[0].iono, None);
        assert_eq!(
            b.truth,
            Some([37.5f64.to_radians(), -122f64.to_radians(), -28.0])
        );
    }

    #[test]
    fn bad_satellites_get_their_stable_codes() {
        let unknown = SAT.replace("G05", "X05");
        assert_eq!(
            code(&frame(&[&unknown])),
            FrameErrorCode::UnknownConstellation
        );
        assert_eq!(
            code(&frame(&[SAT, SAT])),
            FrameErrorCode::DuplicateSatellite
        );
        let on_ground = SAT.replace("[15600000.0,7540000.0,20140000.0]", "[6378137,0,0]");
        assert_eq!(
            code(&frame(&[&on_ground])),
            FrameErrorCode::SatellitePosition
        );
        let km = SAT.replace("[15600000.0,7540000.0,20140000.0]", "[15600,7540,20140]");
        let e = parse_frame(&frame(&[&km]), 10).unwrap_err();
        assert!(e.message.contains("ECEF metres"), "{}", e.message);
        for bad in ["G0", "G", "G100", "05", "Gx5"] {
            let s = SAT.replace("G05", bad);
            assert_eq!(code(&frame(&[&s])), FrameErrorCode::InvalidEpoch, "{bad}");
        }
        let no_clk = SAT.replace(r#","clk":12.5"#, "");
        assert_eq!(code(&frame(&[&no_clk])), FrameErrorCode::InvalidEpoch);
        let negative = SAT.replace("21000000.5", "-21000000.5");
        assert_eq!(code(&frame(&[&negative])), FrameErrorCode::InvalidEpoch);
        let sigma = SAT.replace(r#""clk":12.5"#, r#""clk":12.5,"sigma":0"#);
        assert_eq!(code(&frame(&[&sigma])), FrameErrorCode::InvalidEpoch);
        let extra = SAT.replace(r#""clk":12.5"#, r#""clk":12.5,"snr":3"#);
        assert_eq!(code(&frame(&[&extra])), FrameErrorCode::UnknownInput);
        let nan = SAT.replace("12.5", "NaN");
        assert_eq!(code(&frame(&[&nan])), FrameErrorCode::NonFinite);
    }

    #[test]
    fn the_refusal_names_the_satellite_and_its_index() {
        let e = parse_frame(&frame(&[SAT, &SAT.replace("G05", "Z07")]), 10).unwrap_err();
        assert!(
            e.message.contains("sats[1]") && e.message.contains("Z07"),
            "{}",
            e.message
        );
    }

    #[test]
    fn too_many_satellites_are_refused() {
        let sats: Vec<String> = (0..=MAX_SATELLITES)
            .map(|i| SAT.replace("G05", &format!("G{:02}", i % 99 + 1)))
            .collect();
        let refs: Vec<&str> = sats.iter().map(String::as_str).collect();
        assert_eq!(code(&frame(&refs)), FrameErrorCode::InvalidEpoch);
    }
}
