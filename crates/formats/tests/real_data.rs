//! The readers on the real files of tests/data/gnss (see its README.md for each
//! file's traps and truth), and the end-to-end check that needs no solver: in one
//! epoch, every satellite's corrected pseudorange minus its geometric range from the
//! truth is the same receiver clock, up to the measurement and model errors.

use std::path::PathBuf;

use approx::assert_abs_diff_eq;
use navguard_core::epoch::{Constellation, Epoch, SatId};
use navguard_core::geo::{Lla, lla_to_ecef};
use navguard_formats::ephemeris::{C_LIGHT, ClockFor};
use navguard_formats::gsdc::{self, Band};
use navguard_formats::rinex::convert::{RinexParams, convert};
use navguard_formats::rinex::nav::{NavFile, read_nav};
use navguard_formats::rinex::obs::read_obs;
use navguard_formats::{gnsslogger, gpstime};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/gnss")
        .join(rel)
}

fn nav2005() -> NavFile {
    read_nav(&data("rtklib/07590920.05n")).unwrap()
}

const G3: SatId = SatId {
    constellation: Constellation::Gps,
    prn: 3,
};

/// Simple tropospheric mapping for the test only: 2.4 m zenith delay over
/// sin(el) with a flattening term (the shape of RTCA DO-229's mapping).
fn tropo_test_model(el: f64) -> f64 {
    2.4 * 1.001 / (0.002001 + el.sin().powi(2)).sqrt()
}

/// Per epoch, max − min over satellites of `pr + clk − iono − tropo − range`, with
/// the satellite rotated by ω_E·τ (Sagnac) into the reception frame.
fn clock_spreads(epochs: &[Epoch], default_tropo: bool) -> Vec<f64> {
    epochs
        .iter()
        .map(|e| {
            let b = e.gnss_raw.as_ref().unwrap();
            let [lat, lon, h] = b.truth.expect("truth");
            let rx = lla_to_ecef(&Lla { lat, lon, h });
            let res: Vec<f64> = b
                .sats
                .iter()
                .map(|s| {
                    let d0 = ((s.pos[0] - rx.x).powi(2)
                        + (s.pos[1] - rx.y).powi(2)
                        + (s.pos[2] - rx.z).powi(2))
                    .sqrt();
                    let th = 7.292_115_146_7e-5 * d0 / C_LIGHT;
                    let (x, y) = (
                        s.pos[0] * th.cos() + s.pos[1] * th.sin(),
                        -s.pos[0] * th.sin() + s.pos[1] * th.cos(),
                    );
                    let range =
                        ((x - rx.x).powi(2) + (y - rx.y).powi(2) + (s.pos[2] - rx.z).powi(2))
                            .sqrt();
                    let tropo = s.tropo.unwrap_or(if default_tropo {
                        tropo_test_model(s.el.unwrap())
                    } else {
                        0.0
                    });
                    s.pr + s.clk - s.iono.unwrap_or(0.0) - tropo - range
                })
                .collect();
            let max = res.iter().cloned().fold(f64::MIN, f64::max);
            let min = res.iter().cloned().fold(f64::MAX, f64::min);
            max - min
        })
        .collect()
}

fn worst(v: &[f64]) -> f64 {
    v.iter().cloned().fold(0.0, f64::max)
}

/// The epochs with only the satellites whose reported σ is below `max_sigma`.
fn only_sigma_below(epochs: &[Epoch], max_sigma: f64) -> Vec<Epoch> {
    epochs
        .iter()
        .map(|e| {
            let mut e = e.clone();
            e.gnss_raw
                .as_mut()
                .unwrap()
                .sats
                .retain(|s| s.sigma.unwrap() < max_sigma);
            e
        })
        .filter(|e| e.gnss_raw.as_ref().unwrap().sats.len() >= 4)
        .collect()
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

#[test]
fn broadcast_orbit_matches_an_independent_isgps200_computation() {
    // Reference: crates/formats/reference/isgps200_reference.py (pure Python,
    // IS-GPS-200 Table 20-IV and §20.3.3.3.3.1 transcribed separately), PRN 3's
    // t_oe = 518 400 s record of 07590920.05n, at t_oe + 1800 s.
    let nav = nav2005();
    let eph = nav
        .ephemerides
        .of(G3)
        .iter()
        .find(|e| e.toe == gpstime::from_week_tow(1316, 518_400.0))
        .unwrap();
    let t = eph.toe + 1800.0;
    let p = eph.position(t);
    assert_abs_diff_eq!(p[0], -24_058_459.563_0, epsilon = 1e-3);
    assert_abs_diff_eq!(p[1], -10_824_671.638_6, epsilon = 1e-3);
    assert_abs_diff_eq!(p[2], -4_274_659.085_4, epsilon = 1e-3);
    assert_abs_diff_eq!(
        C_LIGHT * eph.clock_s(t, ClockFor::L1),
        29_000.280_450,
        epsilon = 1e-5
    );
}

#[test]
fn orbits_are_26560_km_and_consecutive_ephemerides_agree_at_their_boundary() {
    let nav = nav2005();
    let mut worst_gap: f64 = 0.0;
    let mut pairs = 0;
    for prn in 1..=32 {
        let sat = SatId {
            constellation: Constellation::Gps,
            prn,
        };
        for w in nav.ephemerides.of(sat).windows(2) {
            let r = w[0].position(w[0].toe);
            let radius = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            let a = w[0].sqrt_a * w[0].sqrt_a;
            assert!((a - 26_560e3).abs() < 100e3, "{sat} semi-major axis {a}");
            // r = A(1 − e cos E) + δr, |δr| of a few hundred metres.
            let kepler_r = a * (1.0 - w[0].e * w[0].eccentric_anomaly(w[0].toe).cos());
            assert!(
                (radius - kepler_r).abs() < 1e3,
                "{sat} radius {radius} vs {kepler_r}"
            );
            if w[1].toe - w[0].toe > 0.0 && w[1].toe - w[0].toe <= 7_200.0 {
                let t = 0.5 * (w[0].toe + w[1].toe);
                let (a, b) = (w[0].position(t), w[1].position(t));
                let gap =
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
                worst_gap = worst_gap.max(gap);
                pairs += 1;
            }
        }
    }
    eprintln!(
        "consecutive ephemerides: {pairs} pairs, worst position gap at the boundary {worst_gap:.2} m"
    );
    assert!(pairs > 20);
    // Measured: 6.7 m (G15 across a 16-s-offset upload cut-over); fit errors of
    // broadcast orbits are metres.
    assert!(worst_gap < 10.0, "{worst_gap}");
}

#[test]
fn rinex_2005_parses_120_epochs_and_skips_the_three_splice_events() {
    let obs = read_obs(&data("rtklib/07590920.05o")).unwrap();
    assert_eq!(obs.epochs.len(), 120);
    assert_eq!(obs.events_skipped, 3);
    assert_eq!(obs.types, ["L1", "C1", "L2", "P2"]);
    assert!(obs.epochs.iter().all(|e| (7..=9).contains(&e.sats.len())));
    // The time tag keeps the receiver clock offset (0 58 30.0050000).
    let tag = obs
        .epochs
        .iter()
        .find(|e| (e.t % 60.0 - 30.005).abs() < 1e-6);
    assert!(tag.is_some());
    let nav = nav2005();
    assert_eq!(nav.ephemerides.len(), 162);
    assert_eq!(nav.leap_seconds, Some(13.0));
    assert!(nav.klobuchar.is_some());
}

#[test]
fn rinex_iono_free_epochs_share_one_receiver_clock_to_a_few_metres() {
    let obs = read_obs(&data("rtklib/07590920.05o")).unwrap();
    let p = RinexParams {
        iono_free: true,
        truth_approx_position: true,
    };
    let conv = convert(&obs, &nav2005(), "07590920.05o", p).unwrap();
    assert_eq!(conv.epochs.len(), 120);
    let s = clock_spreads(&conv.epochs, true);
    eprintln!(
        "RINEX iono-free: dropped {}, clock spread median {:.2} m, worst {:.2} m",
        conv.dropped,
        median(&s),
        worst(&s)
    );
    assert!(worst(&s) < 8.0);
}

#[test]
fn rinex_single_frequency_with_klobuchar_shares_one_clock_within_metres() {
    let obs = read_obs(&data("rtklib/07590920.05o")).unwrap();
    let p = RinexParams {
        iono_free: false,
        truth_approx_position: true,
    };
    let conv = convert(&obs, &nav2005(), "07590920.05o", p).unwrap();
    let s = clock_spreads(&conv.epochs, true);
    eprintln!(
        "RINEX C1+Klobuchar: clock spread median {:.2} m, worst {:.2} m",
        median(&s),
        worst(&s)
    );
    assert!(worst(&s) < 15.0);
}

#[test]
fn gnsslogger_keeps_1379_records_in_223_epochs_near_one_clock() {
    let log =
        gnsslogger::read_log(&data("gnsslogger/pseudoranges_log_2016_06_30_21_26_07.txt")).unwrap();
    assert_eq!(log.records.len(), 1379);
    assert_eq!(log.dropped, 0);
    let nav = read_nav(&data("gnsslogger/hour1820.16n")).unwrap();
    assert_eq!(nav.leap_seconds, Some(17.0));
    let truth = Lla {
        lat: 37.422_578_f64.to_radians(),
        lon: (-122.081_678_f64).to_radians(),
        h: -28.0,
    };
    let p = gnsslogger::GnssLoggerParams {
        truth: Some(truth),
        apriori: None,
    };
    let (epochs, no_eph) = gnsslogger::convert(&log, &nav, "log", p).unwrap();
    assert_eq!(epochs.len(), 223);
    assert_eq!(no_eph, 0);
    let first = gpstime::week_tow(epochs[0].t);
    // 2016-06-30 21:26:09 UTC + 17 s is GPS week 1903, Thursday.
    assert_eq!(first.0, 1903);
    assert!(
        (first.1 - (4.0 * 86_400.0 + 21.0 * 3600.0 + 26.0 * 60.0 + 26.0)).abs() < 2.0,
        "{first:?}"
    );
    // σ-weighted phones: compare only satellites with σ < 30 m.
    let good = only_sigma_below(&epochs, 30.0);
    let s = clock_spreads(&good, true);
    eprintln!(
        "GnssLogger: {} epochs with ≥4 sats of σ<30 m, clock spread median {:.1} m, worst {:.1} m",
        good.len(),
        median(&s),
        worst(&s)
    );
    assert!(median(&s) < 60.0);
}

#[test]
fn gsdc2021_applies_the_hosts_quirks_and_shares_one_clock() {
    let truth = gsdc::y2021::read_truth(&data("gsdc/gsdc2021_Pixel4_ground_truth.csv")).unwrap();
    let epochs = gsdc::y2021::read(
        &data("gsdc/gsdc2021_Pixel4_derived.csv"),
        Band::L1,
        Some(&truth),
    )
    .unwrap();
    assert_eq!(epochs.len(), 6);
    // The first derived epoch (…465.442) maps to …464.442, the file's first stamp.
    assert_abs_diff_eq!(epochs[0].t, 1_273_529_464.442, epsilon = 1e-6);
    let b = epochs[0].gnss_raw.as_ref().unwrap();
    let [lat, lon, h] = b.truth.unwrap();
    assert_abs_diff_eq!(lat.to_degrees(), 37.423_575_954_3, epsilon = 1e-9);
    assert_abs_diff_eq!(lon.to_degrees(), -122.094_132_036_7, epsilon = 1e-9);
    assert_abs_diff_eq!(h, 33.21 - 61.0, epsilon = 1e-6);
    let counts: Vec<usize> = epochs
        .iter()
        .map(|e| e.gnss_raw.as_ref().unwrap().sats.len())
        .collect();
    assert!(counts.iter().all(|n| (18..=22).contains(n)), "{counts:?}");
    let s = clock_spreads(&epochs, false);
    let g = clock_spreads(&only_sigma_below(&epochs, 10.0), false);
    eprintln!(
        "GSDC 2021: sats/epoch {counts:?}, clock spread median {:.1} m, worst {:.1} m; σ<10 m only: median {:.1} m, worst {:.1} m",
        median(&s),
        worst(&s),
        median(&g),
        worst(&g)
    );
    assert!(worst(&s) < 120.0);
    assert!(worst(&g) < 60.0);
}

#[test]
fn gsdc2023_skips_empty_signals_keeps_l1_and_shares_one_clock() {
    let truth = gsdc::y2023::read_truth(&data("gsdc/gsdc2023_pixel7pro_ground_truth.csv")).unwrap();
    let epochs = gsdc::y2023::read(
        &data("gsdc/gsdc2023_pixel7pro_device_gnss.csv"),
        Band::L1,
        Some(&truth),
    )
    .unwrap();
    assert_eq!(epochs.len(), 5);
    // 2023-09-07 18:59:58 UTC + 18 s.
    assert_abs_diff_eq!(epochs[0].t, 1_378_148_416.0, epsilon = 1e-6);
    let [_, _, h] = epochs[0].gnss_raw.as_ref().unwrap().truth.unwrap();
    assert_abs_diff_eq!(h, 20.9736, epsilon = 1e-3);
    let counts: Vec<usize> = epochs
        .iter()
        .map(|e| e.gnss_raw.as_ref().unwrap().sats.len())
        .collect();
    assert!(counts.iter().all(|n| *n == 21), "{counts:?}");
    let s = clock_spreads(&epochs, false);
    let g = clock_spreads(&only_sigma_below(&epochs, 10.0), false);
    eprintln!(
        "GSDC 2023: sats/epoch {counts:?}, clock spread median {:.1} m, worst {:.1} m; σ<10 m only: median {:.1} m, worst {:.1} m",
        median(&s),
        worst(&s),
        median(&g),
        worst(&g)
    );
    assert!(worst(&s) < 80.0);
    assert!(worst(&g) < 40.0);
}
