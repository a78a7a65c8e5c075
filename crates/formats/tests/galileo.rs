//! Galileo broadcast navigation from real RINEX 3 files (tests/data/gnss/rinex3, its
//! README.md): the DLR/TUM merged broadcast of 2023-03-14 (E01 and E02, three
//! consecutive I/NAV batches each, and GPS G01/G02), and the IGS merged broadcast of
//! 2020-05-15 (E24, one batch as F/NAV and three I/NAV records, with BGDs of 45 and
//! 51 ns). Checked against an independent Python transcription of the OS SIS ICD
//! (crates/formats/reference/galileo_reference.py), against each other (consecutive
//! batches; the two messages' clocks) and against the orbit's size.

use std::path::PathBuf;

use navguard_core::epoch::{Constellation, SatId};
use navguard_formats::ephemeris::{C_LIGHT, ClockFor, Ephemeris, GalileoMessage};
use navguard_formats::gpstime;
use navguard_formats::rinex::nav::{NavFile, read_nav};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/gnss/rinex3")
        .join(rel)
}

fn dlr() -> NavFile {
    read_nav(&data("BRDM00DLR_S_20230730000_01D_MN_GE.rnx")).unwrap()
}

fn sat(constellation: Constellation, prn: u8) -> SatId {
    SatId { constellation, prn }
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn the_dlr_file_has_six_galileo_and_six_gps_records() {
    let nav = dlr();
    assert_eq!(nav.ephemerides.len(), 12);
    assert_eq!(nav.other_systems_skipped, 0);
    for prn in [1, 2] {
        assert_eq!(nav.ephemerides.of(sat(Constellation::Gps, prn)).len(), 3);
        let gal = nav.ephemerides.of(sat(Constellation::Galileo, prn));
        let iods: Vec<f64> = gal.iter().map(|e| e.iode).collect();
        assert_eq!(iods, [32.0, 33.0, 34.0]);
        for e in gal {
            let g = e.galileo.unwrap();
            assert_eq!(g.message, GalileoMessage::INav);
            assert_eq!((g.sisa_m, e.health), (3.12, 0.0));
            // GAL week 2253 (GST week 1229 + 1024) is GPS week 2253: 2023-03-12.
            assert_eq!(e.week, 2253);
        }
    }
    let e02 = &nav.ephemerides.of(sat(Constellation::Galileo, 2))[0];
    let g = e02.galileo.unwrap();
    assert_eq!(
        (g.bgd_e1_e5a, g.bgd_e1_e5b),
        (-1.396_983_861_923e-9, -2.095_475_792_885e-9)
    );
    assert_eq!(g.data_sources, 516);
    // t_oe 172 800 s of week 2253 is 2023-03-14 00:00 GST.
    assert_eq!(e02.toe, gpstime::from_week_tow(2253, 172_800.0));
}

#[test]
fn a_galileo_orbit_matches_an_independent_os_sis_icd_computation() {
    // Reference: crates/formats/reference/galileo_reference.py (OS SIS ICD Table 58,
    // §5.1.4–5.1.5 transcribed separately), E01's IODnav 32 record at t_oe + 1800 s.
    let nav = dlr();
    let e = &nav.ephemerides.of(sat(Constellation::Galileo, 1))[0];
    let t = e.toe + 1800.0;
    let p = e.position(t);
    let want = [-8_354_938.170_1, -28_358_994.497_5, 1_569_348.040_6];
    assert!(dist(p, want) < 1e-3, "{p:?}");
    // E1 with the I/NAV clock: − BGD(E1,E5b); E1/E5a: − BGD(E1,E5b) + BGD(E1,E5a).
    let e1 = C_LIGHT * e.clock_s(t, ClockFor::L1);
    let e1e5a = C_LIGHT * e.clock_s(t, ClockFor::IonoFree);
    assert!((e1 - -4_932.664_813).abs() < 1e-5, "{e1}");
    assert!((e1e5a - -4_932.595_012).abs() < 1e-5, "{e1e5a}");
    // With GPS's μ (5.8e-8 larger) the position 30 min from t_oe moves by 0.48 m (the
    // Python reference with GPS's μ): the 1 mm check tells the constants apart.
    let as_gps = Ephemeris {
        sat: sat(Constellation::Gps, 1),
        galileo: None,
        ..e.clone()
    };
    let off = dist(as_gps.position(t), want);
    assert!(off > 0.4, "{off}");
}

#[test]
fn galileo_orbits_are_29600_km() {
    let nav = dlr();
    for prn in [1, 2] {
        for e in nav.ephemerides.of(sat(Constellation::Galileo, prn)) {
            let a = e.sqrt_a * e.sqrt_a;
            assert!((a - 29_600e3).abs() < 10e3, "E{prn:02} A {a}");
            let r = e.position(e.toe);
            let radius = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            let kepler_r = a * (1.0 - e.e * e.eccentric_anomaly(e.toe).cos());
            assert!(
                (radius - kepler_r).abs() < 1e3,
                "E{prn:02} {radius} vs {kepler_r}"
            );
        }
    }
}

#[test]
fn consecutive_galileo_batches_agree_where_both_apply() {
    // Each pair of consecutive batches (IODnav n and n + 1, 10 min apart) evaluated at
    // the same instants, every 30 s from the first t_oe to 10 min past the second.
    let nav = dlr();
    let (mut worst_pos, mut worst_clk, mut pairs): (f64, f64, usize) = (0.0, 0.0, 0);
    for prn in [1, 2] {
        for w in nav
            .ephemerides
            .of(sat(Constellation::Galileo, prn))
            .windows(2)
        {
            assert_eq!(w[1].iode, w[0].iode + 1.0);
            assert_eq!(w[1].toe - w[0].toe, 600.0);
            for k in 0..=40 {
                let t = w[0].toe + 30.0 * f64::from(k);
                worst_pos = worst_pos.max(dist(w[0].position(t), w[1].position(t)));
                let dc = w[0].clock_s(t, ClockFor::L1) - w[1].clock_s(t, ClockFor::L1);
                worst_clk = worst_clk.max(dc.abs());
            }
            pairs += 1;
        }
    }
    eprintln!(
        "consecutive Galileo batches: {pairs} pairs, worst position {worst_pos:.3} m, clock {:.3} ns",
        worst_clk * 1e9
    );
    assert_eq!(pairs, 4);
    // Measured: 0.279 m and 0.086 ns.
    assert!(worst_pos < 1.0, "{worst_pos}");
    assert!(worst_clk < 1e-9, "{worst_clk}");
}

#[test]
fn fnav_and_inav_give_the_same_e1_clock_through_their_bgds() {
    // E24 on 2020-05-15: one batch (IODnav 80) as F/NAV (clock for E1/E5a) and as I/NAV
    // (E1/E5b), a_f0 5.94 ns apart, BGD(E1,E5a) 45.40 ns, BGD(E1,E5b) 50.99 ns.
    let nav = read_nav(&data("BRDC00IGS_R_20201360000_01D_MN_E24.rnx")).unwrap();
    let e24 = sat(Constellation::Galileo, 24);
    let recs = nav.ephemerides.of(e24);
    assert_eq!(recs.len(), 4);
    let fnav = recs
        .iter()
        .find(|e| e.galileo.unwrap().message == GalileoMessage::FNav);
    let fnav = fnav.unwrap();
    assert_eq!(fnav.galileo.unwrap().data_sources, 258);
    let t = fnav.toe + 900.0;
    for inav in recs
        .iter()
        .filter(|e| e.galileo.unwrap().message == GalileoMessage::INav)
    {
        for signal in [ClockFor::L1, ClockFor::IonoFree] {
            let d = inav.clock_s(t, signal) - fnav.clock_s(t, signal);
            // Measured: 0.35 ns for both (the messages' clocks are fitted separately).
            assert!(d.abs() < 0.5e-9, "{signal:?}: {d}");
        }
        // Without the BGDs they differ by the 5.6 ns between them.
        let raw = inav.clock_s(t, ClockFor::L1) + inav.galileo.unwrap().bgd_e1_e5b
            - fnav.clock_s(t, ClockFor::L1)
            - fnav.galileo.unwrap().bgd_e1_e5a;
        assert!(raw.abs() > 5e-9, "{raw}");
        assert!(dist(inav.position(t), fnav.position(t)) < 1e-3);
    }
    // I/NAV is preferred: the E1 message.
    let chosen = nav.ephemerides.select(e24, t).unwrap();
    assert_eq!(chosen.galileo.unwrap().message, GalileoMessage::INav);
}

#[test]
fn gps_records_of_the_mixed_file_are_gps_orbits() {
    let nav = dlr();
    let mut worst: f64 = 0.0;
    for prn in [1, 2] {
        let recs = nav.ephemerides.of(sat(Constellation::Gps, prn));
        for w in recs.windows(2) {
            assert!(w[0].galileo.is_none());
            let a = w[0].sqrt_a * w[0].sqrt_a;
            assert!((a - 26_560e3).abs() < 100e3);
            let t = 0.5 * (w[0].toe + w[1].toe);
            worst = worst.max(dist(w[0].position(t), w[1].position(t)));
        }
    }
    // Measured: 0.74 m between 2-hour GPS batches at their midpoint.
    assert!(worst < 5.0, "{worst}");
    eprintln!("consecutive GPS batches: worst position {worst:.2} m");
}

#[test]
fn galileo_data_sources_naming_no_clock_are_an_error_at_their_line() {
    let text = std::fs::read_to_string(data("BRDM00DLR_S_20230730000_01D_MN_GE.rnx")).unwrap();
    // E01's first record starts at line 75; its data sources (516) are on line 80.
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[74].starts_with("E01 2023 03 14 00 00 00"));
    for (bad, why) in [
        ("0.000000000000e+00", "names no single clock"),
        ("7.680000000000e+02", "names no single clock"),
        ("5.165000000000e+02", "not a 10-bit integer"),
    ] {
        let edited = text.replacen("5.160000000000e+02", bad, 1);
        let e = navguard_formats::rinex::nav::parse_nav(&edited, "e.rnx")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("e.rnx:80: Galileo data sources"), "{e}");
        assert!(e.contains(why), "{e}");
    }
}
