//! Geodesy (WGS84, LLA ↔ ECEF ↔ ENU, radii of curvature, Earth and transport
//! rates, normal gravity, attitude matrices): the bottom of the core, used by
//! the INS error model and federated filters (`filter::ins`, `filter::aiding`)
//! and by the simulator (`sim`). Pure maths: no I/O, no allocation.
//!
//! Conventions (docs/architecture.md §A6): angles in radians, lengths in
//! metres, the navigation frame is ENU (x east, y north, z up), the body frame
//! is RFU (x right, y forward, z up).
//!
//! - [`wgs84`]: the ellipsoid, LLA ↔ ECEF, radii, Earth/transport rates, gravity.
//! - [`frames`]: ECEF ↔ local ENU, and the small-offset LLA differences the
//!   filters use as position errors.
//! - [`attitude`]: body-to-navigation direction cosine matrices, Euler angles,
//!   skew-symmetric matrices.

pub mod attitude;
pub mod frames;
pub mod wgs84;

pub use attitude::{dcm_body_to_nav, euler_from_dcm, skew};
pub use frames::{apply_offset, ecef_to_enu, ecef_to_enu_rotation, enu_to_ecef, local_offset};
pub use wgs84::{
    Lla, OMEGA_IE, Radii, WGS84_A, WGS84_B, WGS84_E2, WGS84_F, earth_rate_enu, ecef_to_lla,
    lla_to_ecef, normal_gravity, radii, transport_rate_enu,
};
