//! The drive and solution readers on real files: the car drive of tests/data/drive
//! (RTKLIB `.pos` at 4 Hz, a 100 Hz IMU CSV, its RTKLIB time tag; README.md there), the
//! NMEA sample beside them, and the KF-GINS GNSS file of the shared data (read when
//! `../shared/data` is beside the repository, as on CI).

use std::path::PathBuf;

use approx::assert_abs_diff_eq;
use navguard_core::epoch::Epoch;
use navguard_formats::fix::{Quality, SigmaPolicy};
use navguard_formats::gpstime::days_from_civil;
use navguard_formats::imu_csv::{self, ImuCsvLayout};
use navguard_formats::kfgins;
use navguard_formats::merge::merge;
use navguard_formats::nmea::{NmeaParams, read_nmea};
use navguard_formats::rtklib_pos::{read_pos, to_epochs};
use navguard_formats::timetag::read_tag;

fn drive(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/drive")
        .join(rel)
}

/// GPS seconds of a GPST calendar instant, counted here from the days since 1980-01-06.
fn gpst(y: i64, mo: u32, d: u32, h: u32, mi: u32, s: f64) -> f64 {
    let days = days_from_civil(y, mo, d) - days_from_civil(1980, 1, 6);
    (days * 86_400 + i64::from(h) * 3600 + i64::from(mi) * 60) as f64 + s
}

#[test]
fn the_pos_file_has_2197_solutions_2189_fixed_and_8_float() {
    let fixes = read_pos(&drive("gnss_1934_sf.pos")).unwrap();
    assert_eq!(fixes.len(), 2197);
    let count = |q| fixes.iter().filter(|f| f.quality == Some(q)).count();
    assert_eq!((count(Quality::Fixed), count(Quality::Float)), (2189, 8));
    // First line: 2025/07/08 19:34:18.499 40.0966268 -105.1474483 1601.4740000 1 21
    // sdn 0.0098995 sde 0.0098995 sdu 0.0100000 … vn 0.0100000 ve -0.0020000 vu 0.0090000
    // sdvn sdve sdvu 0.0586899.
    let f = fixes[0];
    assert_abs_diff_eq!(f.t, gpst(2025, 7, 8, 19, 34, 18.499), epsilon = 1e-6);
    assert_abs_diff_eq!(f.lla.lat.to_degrees(), 40.0966268, epsilon = 1e-12);
    assert_abs_diff_eq!(f.lla.lon.to_degrees(), -105.1474483, epsilon = 1e-12);
    assert_eq!(f.lla.h, 1601.474);
    assert_eq!(f.ns, Some(21));
    assert_eq!(f.vel, Some([-0.002, 0.01, 0.009]));
    assert_eq!(f.pos_sigma, Some([0.0098995, 0.0098995, 0.01]));
    assert_eq!(f.vel_sigma, Some([0.0586899; 3]));
    let e = &to_epochs(&fixes, &SigmaPolicy::default())[0];
    assert_eq!(e.gnss.as_ref().unwrap().pos_sigma, Some([0.01; 3]));
    let last = fixes[2196];
    assert_abs_diff_eq!(last.t, gpst(2025, 7, 8, 19, 43, 27.499), epsilon = 1e-6);
}

#[test]
fn the_tag_starts_at_19_34_21_854_gpst_with_37632_records() {
    let tag = read_tag(&drive("imu_1934.csv.tag")).unwrap();
    assert!(tag.header.starts_with("TIMETAG RTKLIB demo5"));
    assert_abs_diff_eq!(
        tag.start_gps_s,
        gpst(2025, 7, 8, 19, 34, 21.854),
        epsilon = 1e-6
    );
    assert_eq!(tag.ticks_ms.len(), 37_632);
    assert_eq!(tag.span_s(), 548.731);
}

fn imu_samples() -> Vec<imu_csv::ImuSample> {
    imu_csv::read_imu_csv(&drive("imu_1934.csv"), &ImuCsvLayout::default()).unwrap()
}

#[test]
fn the_imu_csv_has_54860_rows_in_si() {
    let s = imu_samples();
    assert_eq!(s.len(), 54_860);
    // First row: 0.119,0.027,1.013,-0.671,3.082,0.198,261906 (g, °/s, ms).
    let a = s[0].imu.accel;
    assert_abs_diff_eq!(a[0], 1.16699, epsilon = 1e-5);
    assert_abs_diff_eq!(a[2], 1.013 * 9.80665, epsilon = 1e-12);
    assert_abs_diff_eq!(s[0].imu.gyro[0], -0.671_f64.to_radians(), epsilon = 1e-15);
    assert_eq!(s[0].imu.dt, None);
    assert_eq!((s[0].t, s[54_859].t), (261.906, 810.496));
}

#[test]
fn the_mapped_imu_times_span_the_tag_from_its_start() {
    let tag = read_tag(&drive("imu_1934.csv.tag")).unwrap();
    let s = imu_samples();
    let map = tag.mapping(s[0].t, s[s.len() - 1].t, 0.0);
    let start = gpst(2025, 7, 8, 19, 34, 21.854);
    assert_abs_diff_eq!(map.gps(s[0].t), start, epsilon = 1e-6);
    assert_abs_diff_eq!(map.gps(s[s.len() - 1].t), start + 548.731, epsilon = 1e-6);
    let late = tag.mapping(s[0].t, s[s.len() - 1].t, -0.125);
    assert_abs_diff_eq!(late.gps(s[0].t), start - 0.125, epsilon = 1e-6);
}

/// The drive merged: IMU on GPS time with the −0.125 s latency, fixes from the `.pos`
/// (every `step`-th).
fn merged_drive(step: usize) -> (navguard_formats::merge::Merged, usize, usize) {
    let tag = read_tag(&drive("imu_1934.csv.tag")).unwrap();
    let s = imu_samples();
    let map = tag.mapping(s[0].t, s[s.len() - 1].t, -0.125);
    let imu = imu_csv::to_epochs(&s, |t| map.gps(t));
    let (t0, t1) = (imu[0].t, imu[imu.len() - 1].t);
    let fixes: Vec<_> = read_pos(&drive("gnss_1934_sf.pos"))
        .unwrap()
        .into_iter()
        .step_by(step)
        .collect();
    let inside = fixes.iter().filter(|f| f.t >= t0 && f.t <= t1).count();
    let n = fixes.len();
    (
        merge(imu, to_epochs(&fixes, &SigmaPolicy::default())),
        inside,
        n,
    )
}

fn non_decreasing(e: &[Epoch]) -> bool {
    e.windows(2).all(|w| w[0].t <= w[1].t)
}

#[test]
fn every_fix_within_the_imu_span_rides_on_an_imu_epoch() {
    for step in [1, 4] {
        let (m, inside, n) = merged_drive(step);
        // The GNSS starts 3.2 s before the IMU: those fixes stand alone, all others ride.
        assert_eq!(m.attached, inside, "step {step}");
        assert_eq!(m.standalone, n - inside, "step {step}");
        assert_eq!(m.epochs.len(), 54_860 + m.standalone);
        assert!(non_decreasing(&m.epochs));
        let with_both = m
            .epochs
            .iter()
            .filter(|e| e.imu.is_some() && e.gnss.is_some());
        assert_eq!(with_both.count(), inside);
        assert_abs_diff_eq!(m.tolerance_s, 0.005, epsilon = 2e-5);
        assert!(
            m.epochs
                .iter()
                .all(|e| e.imu.is_some() || e.t < m.epochs[13].t)
        );
    }
    assert_eq!(merged_drive(1).2 - merged_drive(1).1, 13);
}

#[test]
fn the_nmea_sample_gives_three_fixes_with_gst_sigma_and_velocity() {
    let log = read_nmea(&drive("sample.nmea"), NmeaParams::default()).unwrap();
    let c = log.counts;
    assert_eq!(
        (c.gga, c.rmc, c.vtg, c.gst, c.other, c.bad),
        (4, 2, 2, 2, 1, 0)
    );
    assert_eq!(c.no_fix, 1);
    let f = &log.fixes;
    assert_eq!(f.len(), 3);
    // 2025-07-08 12:35:19 UTC, 18 s of leap seconds.
    assert_abs_diff_eq!(f[0].t, gpst(2025, 7, 8, 12, 35, 37.0), epsilon = 1e-9);
    assert_abs_diff_eq!(f[2].t - f[0].t, 2.0, epsilon = 1e-9);
    assert_abs_diff_eq!(f[0].lla.lat.to_degrees(), 40.0966268, epsilon = 1e-9);
    assert_abs_diff_eq!(f[0].lla.lon.to_degrees(), -105.1474483, epsilon = 1e-9);
    // Ellipsoidal height = altitude 1584.123 + geoid separation 17.351 (f32 in the crate).
    assert_abs_diff_eq!(f[0].lla.h, 1601.474, epsilon = 1e-3);
    assert_eq!(f[0].quality, Some(Quality::Fixed));
    assert_eq!(f[2].quality, Some(Quality::Float));
    assert_eq!(f[0].ns, Some(21));
    // GST σ lat 0.012, lon 0.011, alt 0.025 → ENU (0.011, 0.012, 0.025).
    let s = f[0].pos_sigma.unwrap();
    assert_abs_diff_eq!(s[0], 0.011, epsilon = 1e-6);
    assert_abs_diff_eq!(s[1], 0.012, epsilon = 1e-6);
    assert_abs_diff_eq!(s[2], 0.025, epsilon = 1e-6);
    // RMC 10 kn at course 90° → east 5.144 m/s; VTG 5 kn at 0° → north 2.572 m/s.
    assert_eq!(f[0].vel, Some([0.0; 3]));
    let v = f[1].vel.unwrap();
    assert_abs_diff_eq!(v[0], 10.0 * 1852.0 / 3600.0, epsilon = 1e-9);
    assert_abs_diff_eq!(v[1], 0.0, epsilon = 1e-9);
    let v = f[2].vel.unwrap();
    assert_abs_diff_eq!(v[1], 5.0 * 1852.0 / 3600.0, epsilon = 1e-9);
    // No GST on the float fix: σ from the quality table.
    assert_eq!(f[2].pos_sigma, None);
    let b = SigmaPolicy::default().block(&f[2]);
    assert_eq!(b.pos_sigma, Some([0.5, 0.5, 1.0]));
}

#[test]
fn the_kf_gins_gnss_file_has_3413_epochs() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/kf-gins-gnss-rtk.txt");
    if !path.exists() {
        eprintln!("skipped: {} is not beside the repository", path.display());
        return;
    }
    let f = kfgins::read_gnss(&path, None).unwrap();
    assert_eq!(f.len(), 3413);
    // 456250.000 30.4447858054 114.4718661162 21.095 0.010 0.009 0.019
    assert_eq!(f[0].t, 456_250.0);
    assert_abs_diff_eq!(f[0].lla.lat.to_degrees(), 30.4447858054, epsilon = 1e-12);
    assert_abs_diff_eq!(f[0].lla.lon.to_degrees(), 114.4718661162, epsilon = 1e-12);
    assert_eq!(f[0].lla.h, 21.095);
    assert_eq!(f[0].pos_sigma, Some([0.009, 0.010, 0.019]));
}
