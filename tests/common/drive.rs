//! The car drive of `tests/data/drive` as `navguard experiment drive` reads it, for the
//! tests and the bench (`tests/drive.rs`, `benches/imu_step.rs`): the IMU put on GPS time
//! through its tag with the logger's 0.125 s latency removed, and the RTK solution as
//! the reference.

use std::path::Path;

use nalgebra::Vector3;
use navguard_formats::imu_csv::{self, ImuCsvLayout};
use navguard_formats::{rtklib_pos, timetag};
use navguard_sim::experiment::drive::{DriveData, RefFix};

/// Reads the drive from the repository's `tests/data/drive`.
pub(crate) fn read_drive() -> DriveData {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/drive");
    let samples = imu_csv::read_imu_csv(&dir.join("imu_1934.csv"), &ImuCsvLayout::default())
        .expect("the drive's IMU CSV");
    let tag = timetag::read_tag(&dir.join("imu_1934.csv.tag")).expect("its time tag");
    let imu = imu_csv::to_epochs_tagged(&samples, &tag, -0.125);
    let reference = rtklib_pos::read_pos(&dir.join("gnss_1934_sf.pos"))
        .expect("the drive's RTK solution")
        .iter()
        .map(|f| RefFix {
            t: f.t,
            lla: f.lla,
            vel: Vector3::from(f.vel.expect("the RTK solution carries velocities")),
        })
        .collect();
    DriveData { imu, reference }
}
