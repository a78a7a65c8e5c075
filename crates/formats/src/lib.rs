//! navguard-formats: real receiver files → domain [`Epoch`](navguard_core::epoch::Epoch)s
//! with raw pseudoranges (`gnss_raw`), GNSS fixes with σ (`gnss`) and raw IMU samples
//! (`imu`), at the edge of navguard like the wire: files are
//! parsed and validated once here, and the core only sees SI units and radians.
//! Every epoch's `t` is seconds since the GPS epoch 1980-01-06 00:00:00 GPST, so
//! files of one drive merge in time.
//!
//! # Layout
//!
//! In the order data flows through them:
//! - [`error`]: one error enum; every malformed line is named by file and 1-based line.
//! - [`gpstime`]: GPS week/seconds, calendar and UTC ↔ GPS seconds.
//! - [`ephemeris`]: IS-GPS-200 (and Galileo OS SIS ICD) broadcast orbits and satellite
//!   clocks, at transmit time.
//! - [`sp3`]: SP3-c/d precise orbits and clocks, interpolated to the same states.
//! - [`orbits`]: the one door to either source for the observation readers.
//! - [`klobuchar`]: the IS-GPS-200 single-frequency ionospheric model.
//! - [`geometry`]: look angles from an a-priori position, and truths.
//! - [`rinex`]: RINEX 2.10/2.11 and 3.0x observation and navigation files (GPS; RINEX 3
//!   also Galileo; the version on the first line decides), and their conversion.
//! - [`gnsslogger`]: Android GnssLogger `Raw` records with a RINEX navigation file.
//! - [`gsdc`]: the Google Smartphone Decimeter Challenge 2021 and 2023 CSVs.
//! - [`fix`]: GNSS fixes (the solution readers' output) and the σ policy that makes
//!   them `gnss` blocks: reported σ or σ by solution quality.
//! - [`rtklib_pos`]: RTKLIB `.pos` solutions.
//! - [`nmea`]: NMEA 0183 GGA, RMC, VTG and GST sentences.
//! - [`kfgins`]: KF-GINS GNSS and IMU text files.
//! - [`imu_csv`]: IMU CSVs by a column and unit map, rates in SI, sensor frame.
//! - [`timetag`]: RTKLIB `.tag` files, which put a logger's counter on GPS time.
//! - [`merge`]: IMU samples and GNSS fixes into one time-ordered epoch stream.
//!
//! # Why our own RINEX parser
//!
//! The `rinex` crate (0.24, MPL-2.0, licence acceptable) was weighed and not taken:
//! its `nav` feature, needed for ephemerides, pulls `anise` (a SPICE toolkit),
//! `hifitime`, `hyperdual` and a second `nalgebra` (0.34 beside our 0.33), about 200
//! crates in `cargo tree`, far over the budget of about a minute of clean build on two
//! cores; and we need our own IS-GPS-200 orbit and clock code anyway (to document and
//! test the equations), so the crate would only have saved the fixed-column reading,
//! about 300 lines here (about 250 more for RINEX 3). RINEX 2's columns are simple and
//! the two traps in our data (event-flag-4 records with blank dates, time tags with
//! receiver-clock offsets) are handled and tested explicitly; RINEX 3 is tested against
//! the same real files rewritten as 3.04 (tests/rinex3.rs).

pub mod ephemeris;
pub mod error;
pub mod fix;
pub mod geometry;
pub mod gnsslogger;
pub mod gpstime;
pub mod gsdc;
pub mod imu_csv;
pub mod kfgins;
pub mod klobuchar;
pub mod merge;
pub mod nmea;
pub mod orbits;
pub mod rinex;
pub mod rtklib_pos;
pub mod sp3;
pub mod timetag;

pub use error::FormatError;
