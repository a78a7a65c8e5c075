//! Test support for the `gnss` layer (tests only): the GSDC CSVs of tests/data/gnss/
//! parsed with std, an independent WLS reference (Bancroft start, then Gauss–Newton by
//! QR of the whitened Jacobian, its own Sagnac rotation iterated to convergence), and
//! seeded synthetic geometries.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector, Matrix4, Vector3, Vector4};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use crate::epoch::{Constellation, SatId, SatObs};
use crate::geo::{Lla, ecef_to_enu_rotation, lla_to_ecef};

const C: f64 = 299_792_458.0;
const OMEGA: f64 = 7.292_115_146_7e-5;

/// One epoch of phone data.
pub(crate) struct PhoneEpoch {
    pub(crate) millis: u64,
    pub(crate) obs: Vec<SatObs>,
    /// Google's WLS fix (GSDC 2023 only).
    pub(crate) google_wls: Option<Vector3<f64>>,
}

fn data_path(name: &str) -> String {
    format!(
        "{}/../../tests/data/gnss/gsdc/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Rows of a CSV as name → value maps.
fn read_csv(name: &str) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(data_path(name)).expect("GSDC test file");
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(str::to_owned))
                .collect()
        })
        .collect()
}

fn num(row: &BTreeMap<String, String>, key: &str) -> f64 {
    row[key]
        .parse()
        .unwrap_or_else(|_| panic!("{key}: {}", row[key]))
}

fn constellation(code: &str) -> Option<Constellation> {
    match code {
        "1" => Some(Constellation::Gps),
        "3" => Some(Constellation::Glonass),
        "6" => Some(Constellation::Galileo),
        _ => None,
    }
}

/// GSDC 2023 Pixel 7 Pro: the L1-band signal of every GPS, GLONASS and Galileo satellite
/// (one per satellite), `clk = SvClockBias − Isrb`.
pub(crate) fn gsdc2023() -> Vec<PhoneEpoch> {
    let mut epochs: BTreeMap<u64, PhoneEpoch> = BTreeMap::new();
    for row in read_csv("gsdc2023_pixel7pro_device_gnss.csv") {
        let l1 = ["GPS_L1_CA", "GLO_G1_CA", "GAL_E1_C_P"];
        if row["MessageType"] != "Raw" || !l1.contains(&row["SignalType"].as_str()) {
            continue;
        }
        let Some(c) = constellation(&row["ConstellationType"]) else {
            continue;
        };
        let millis: u64 = row["utcTimeMillis"].parse().unwrap();
        let e = epochs.entry(millis).or_insert_with(|| PhoneEpoch {
            millis,
            obs: Vec::new(),
            google_wls: Some(Vector3::new(
                num(&row, "WlsPositionXEcefMeters"),
                num(&row, "WlsPositionYEcefMeters"),
                num(&row, "WlsPositionZEcefMeters"),
            )),
        });
        e.obs.push(SatObs {
            id: SatId {
                constellation: c,
                prn: row["Svid"].parse().unwrap(),
            },
            pr: num(&row, "RawPseudorangeMeters"),
            pos: [
                num(&row, "SvPositionXEcefMeters"),
                num(&row, "SvPositionYEcefMeters"),
                num(&row, "SvPositionZEcefMeters"),
            ],
            clk: num(&row, "SvClockBiasMeters") - num(&row, "IsrbMeters"),
            iono: Some(num(&row, "IonosphericDelayMeters")),
            tropo: Some(num(&row, "TroposphericDelayMeters")),
            sigma: Some(num(&row, "RawPseudorangeUncertaintyMeters")),
            cn0: Some(num(&row, "Cn0DbHz")),
            el: None,
            az: None,
        });
    }
    epochs.into_values().collect()
}

/// The GSDC 2023 truth (README): 37.692231°, −122.0884199°, 20.9736 m.
pub(crate) fn gsdc2023_truth() -> Lla {
    Lla {
        lat: 37.692231_f64.to_radians(),
        lon: (-122.0884199_f64).to_radians(),
        h: 20.9736,
    }
}

/// GSDC 2021 Pixel 4, with the README's quirks: rows whose transit time is outside
/// (0, 300) ms of the previous (truth) epoch dropped, each epoch labelled with that
/// previous epoch, and the first epoch dropped. L1-band signals only (one per satellite).
pub(crate) fn gsdc2021() -> Vec<PhoneEpoch> {
    let mut epochs: BTreeMap<u64, PhoneEpoch> = BTreeMap::new();
    for row in read_csv("gsdc2021_Pixel4_derived.csv") {
        if !["GPS_L1", "GLO_G1", "GAL_E1"].contains(&row["signalType"].as_str()) {
            continue;
        }
        let Some(c) = constellation(&row["constellationType"]) else {
            continue;
        };
        // Quirk 1: the derived epoch belongs to the previous raw epoch; quirk 2 is then
        // checked against that epoch's time.
        let millis = row["millisSinceGpsEpoch"].parse::<u64>().unwrap() - 1000;
        let transit_ms = millis as f64 - num(&row, "receivedSvTimeInGpsNanos") / 1e6;
        if !(transit_ms > 0.0 && transit_ms < 300.0) {
            continue;
        }
        let e = epochs.entry(millis).or_insert_with(|| PhoneEpoch {
            millis,
            obs: Vec::new(),
            google_wls: None,
        });
        e.obs.push(SatObs {
            id: SatId {
                constellation: c,
                prn: row["svid"].parse().unwrap(),
            },
            pr: num(&row, "rawPrM"),
            pos: [
                num(&row, "xSatPosM"),
                num(&row, "ySatPosM"),
                num(&row, "zSatPosM"),
            ],
            clk: num(&row, "satClkBiasM") - num(&row, "isrbM"),
            iono: Some(num(&row, "ionoDelayM")),
            tropo: Some(num(&row, "tropoDelayM")),
            sigma: Some(num(&row, "rawPrUncM")),
            cn0: None,
            el: None,
            az: None,
        });
    }
    let mut out: Vec<PhoneEpoch> = epochs.into_values().collect();
    out.remove(0);
    out
}

/// The GSDC 2021 truth at `millis` (the README's −61 m height correction applied).
pub(crate) fn gsdc2021_truth(millis: u64) -> Lla {
    let row = read_csv("gsdc2021_Pixel4_ground_truth.csv")
        .into_iter()
        .find(|r| r["millisSinceGpsEpoch"].parse::<u64>().unwrap() == millis)
        .expect("truth epoch");
    Lla {
        lat: num(&row, "latDeg").to_radians(),
        lon: num(&row, "lngDeg").to_radians(),
        h: num(&row, "heightAboveWgs84EllipsoidM") - 61.0,
    }
}

/// Satellite `s` (transmit-time ECEF) in the receive-time frame seen from `rx`, τ
/// iterated to a fixed point (the reference's own Sagnac code).
pub(crate) fn reference_rotate(s: &Vector3<f64>, rx: &Vector3<f64>) -> Vector3<f64> {
    let mut tau = 0.0_f64;
    for _ in 0..20 {
        let th = OMEGA * tau;
        let r = Vector3::new(
            s.x * th.cos() + s.y * th.sin(),
            s.y * th.cos() - s.x * th.sin(),
            s.z,
        );
        let next = (r - rx).norm() / C;
        if (next - tau).abs() < 1e-16 {
            return r;
        }
        tau = next;
    }
    panic!("reference Sagnac did not converge")
}

/// Bancroft's closed form (one clock, no Sagnac): a start for the reference.
fn bancroft(sats: &[Vector3<f64>], y: &[f64]) -> Vector3<f64> {
    let lorentz =
        |a: &Vector4<f64>, b: &Vector4<f64>| a.x * b.x + a.y * b.y + a.z * b.z - a.w * b.w;
    let b = DMatrix::from_fn(sats.len(), 4, |i, j| if j < 3 { sats[i][j] } else { y[i] });
    let rows: Vec<Vector4<f64>> = (0..sats.len())
        .map(|i| Vector4::new(b[(i, 0)], b[(i, 1)], b[(i, 2)], b[(i, 3)]))
        .collect();
    let alpha = DVector::from_iterator(rows.len(), rows.iter().map(|r| 0.5 * lorentz(r, r)));
    let ones = DVector::from_element(rows.len(), 1.0);
    let btb: Matrix4<f64> = (b.transpose() * &b).fixed_view::<4, 4>(0, 0).into_owned();
    let binv = btb.try_inverse().unwrap();
    let bt = b.transpose();
    let u4 = binv * Vector4::from_iterator((&bt * &ones).iter().copied());
    let v4 = binv * Vector4::from_iterator((&bt * &alpha).iter().copied());
    let (e, f, g) = (
        lorentz(&u4, &u4),
        lorentz(&u4, &v4) - 1.0,
        lorentz(&v4, &v4),
    );
    let disc = (f * f - e * g).max(0.0).sqrt();
    let best = [(-f + disc) / e, (-f - disc) / e]
        .into_iter()
        .map(|l| l * u4 + v4)
        .min_by(|p, q| {
            let r = |p: &Vector4<f64>| (p.xyz().norm() - 6.371e6).abs();
            r(p).total_cmp(&r(q))
        })
        .unwrap();
    best.xyz()
}

/// The reference WLS: position and one clock per constellation (by the order of first
/// appearance), σ from `SatObs::sigma` times `scale`, given tropo and iono. Returns the
/// position and the clocks.
pub(crate) fn reference_wls(
    obs: &[SatObs],
    scale: f64,
) -> (Vector3<f64>, Vec<(Constellation, f64)>) {
    let mut systems: Vec<Constellation> = Vec::new();
    for o in obs {
        if !systems.contains(&o.id.constellation) {
            systems.push(o.id.constellation);
        }
    }
    let y: Vec<f64> = obs
        .iter()
        .map(|o| o.pr + o.clk - o.iono.unwrap_or(0.0) - o.tropo.unwrap_or(0.0))
        .collect();
    let sats: Vec<Vector3<f64>> = obs.iter().map(|o| Vector3::from(o.pos)).collect();
    let m = 3 + systems.len();
    let mut x = DVector::zeros(m);
    x.fixed_rows_mut::<3>(0).copy_from(&bancroft(&sats, &y));
    for _ in 0..50 {
        let rx = x.fixed_rows::<3>(0).into_owned();
        let mut j = DMatrix::zeros(obs.len(), m);
        let mut r = DVector::zeros(obs.len());
        for (i, o) in obs.iter().enumerate() {
            let s = reference_rotate(&sats[i], &rx);
            let d = (s - rx).norm();
            let k = systems
                .iter()
                .position(|c| *c == o.id.constellation)
                .unwrap();
            let w = 1.0 / (o.sigma.unwrap() * scale);
            r[i] = (y[i] - d - x[3 + k]) * w;
            for a in 0..3 {
                j[(i, a)] = -(s[a] - rx[a]) / d * w;
            }
            j[(i, 3 + k)] = w;
        }
        let qr = j.qr();
        let dx = qr
            .r()
            .solve_upper_triangular(&(qr.q().transpose() * r))
            .unwrap();
        x += &dx;
        if dx.norm() < 1e-10 {
            break;
        }
    }
    let clocks = systems
        .iter()
        .enumerate()
        .map(|(k, &c)| (c, x[3 + k]))
        .collect();
    (x.fixed_rows::<3>(0).into_owned(), clocks)
}

/// A satellite on the 26 560 km sphere in direction (az, el) from `rx` (ENU at `rx_lla`).
pub(crate) fn satellite_at(rx: &Vector3<f64>, rx_lla: &Lla, az: f64, el: f64) -> Vector3<f64> {
    let enu = Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin());
    let dir = ecef_to_enu_rotation(rx_lla.lat, rx_lla.lon).transpose() * enu;
    let b = rx.dot(&dir);
    let c = rx.norm_squared() - 26_560_000.0_f64.powi(2);
    rx + dir * (-b + (b * b - c).sqrt())
}

/// Noise-free observations of satellites in the given `(constellation, az, el)`
/// directions, seen from `truth` with receiver clocks `clock_m(constellation)`, σ given.
/// The positions are expressed in the transmit-time frame (un-rotated) so that the
/// solver's Sagnac rotation recovers the geometry.
pub(crate) fn synthetic(
    truth: &Lla,
    dirs: &[(Constellation, f64, f64)],
    clock_m: impl Fn(Constellation) -> f64,
    sigma_m: impl Fn(usize) -> f64,
) -> Vec<SatObs> {
    let rx = lla_to_ecef(truth);
    dirs.iter()
        .enumerate()
        .map(|(i, &(c, az, el))| {
            let s_rx = satellite_at(&rx, truth, az, el);
            let tau = (s_rx - rx).norm() / C;
            // Undo the frame rotation: transmit-frame = rotate back by ωτ, then refine.
            let th = -OMEGA * tau;
            let s_tx = Vector3::new(
                s_rx.x * th.cos() + s_rx.y * th.sin(),
                s_rx.y * th.cos() - s_rx.x * th.sin(),
                s_rx.z,
            );
            let range = (reference_rotate(&s_tx, &rx) - rx).norm();
            SatObs {
                id: SatId {
                    constellation: c,
                    prn: (i + 1) as u8,
                },
                pr: range + clock_m(c),
                pos: [s_tx.x, s_tx.y, s_tx.z],
                clk: 0.0,
                iono: Some(0.0),
                tropo: Some(0.0),
                sigma: Some(sigma_m(i)),
                cn0: None,
                el: None,
                az: None,
            }
        })
        .collect()
}

/// `n` random sky directions above 10° for GPS then Galileo (alternating), seeded.
pub(crate) fn random_sky(seed: u64, n: usize) -> Vec<(Constellation, f64, f64)> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|i| {
            let c = if i % 2 == 0 {
                Constellation::Gps
            } else {
                Constellation::Galileo
            };
            let az = rng.random_range(0.0..std::f64::consts::TAU);
            let el = rng
                .random_range(0.0_f64..1.0)
                .asin()
                .max(10f64.to_radians());
            (c, az, el)
        })
        .collect()
}

/// Adds seeded N(0, σ_i²) noise to every pseudorange.
pub(crate) fn add_noise(obs: &mut [SatObs], rng: &mut StdRng) {
    let n = Normal::new(0.0, 1.0).unwrap();
    for o in obs {
        o.pr += o.sigma.unwrap() * n.sample(rng);
    }
}

/// Horizontal and vertical error (m) of `ecef` against `truth`.
pub(crate) fn errors(ecef: &Vector3<f64>, truth: &Lla) -> (f64, f64) {
    let d = ecef_to_enu_rotation(truth.lat, truth.lon) * (ecef - lla_to_ecef(truth));
    (d.x.hypot(d.y), d.z.abs())
}
