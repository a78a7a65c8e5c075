//! The `federated` monitor's raw-IMU input (docs/methods.md §M31): with `input: imu` the
//! monitor runs its own strapdown mechanization ([`crate::strapdown`]) on the epochs' `imu`
//! blocks instead of reading a client's `ins` solution, aligns it (levelling while static,
//! heading from GNSS velocity once moving or from the config), and after every fusion feeds
//! the estimated errors back into it (closed loop).
//!
//! This file holds the `strapdown` config section, its validation, and the front end's
//! state machine: sensor-to-body rotation, rates turned into increments, bias removal,
//! alignment, the mechanization step and the feedback. The filter, tests and integrity
//! stay the monitor's, the same code as for a client's INS.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::epoch::{Epoch, GnssBlock, ImuBlock};
use crate::filter::ins::{ACC, ATT, ErrorVector, GYRO, NavSolution, POS, VEL};
use crate::geo::{self, Lla};
use crate::monitor::ConfigError;
use crate::strapdown::{Increments, Strapdown, align};

/// Where the federated monitor's INS solution comes from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputKind {
    /// Each epoch's `ins` block: a client's navigation solution (open loop).
    #[default]
    Ins,
    /// Each epoch's `imu` block, mechanized by the monitor (closed loop).
    Imu,
}

/// The `align` part of the `strapdown` section.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AlignSection {
    /// Static time levelling needs, s.
    pub static_s: f64,
    /// Largest `|‖f‖ − g|` of a static sample, m/s².
    pub max_accel_dev_mps2: f64,
    /// Largest `‖ω‖` of a static sample, °/s.
    pub max_rate_dps: f64,
    /// Heading of the body's forward axis, degrees clockwise from north, when known; absent:
    /// taken from the GNSS velocity once the speed reaches `min_speed_mps`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_deg: Option<f64>,
    /// Speed from which the GNSS velocity gives the heading, m/s.
    pub min_speed_mps: f64,
    /// Attitude uncertainty once aligned (roll, pitch, yaw), degrees.
    pub att_sigma_deg: [f64; 3],
}

impl Default for AlignSection {
    fn default() -> Self {
        AlignSection {
            static_s: 5.0,
            max_accel_dev_mps2: 0.3,
            max_rate_dps: 2.0,
            heading_deg: None,
            min_speed_mps: 3.0,
            att_sigma_deg: [1.0, 1.0, 5.0],
        }
    }
}

/// The `strapdown` section (with `input: imu`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StrapdownSection {
    /// The sensor frame's orientation in the body frame (right, forward, up) as roll,
    /// pitch, yaw in degrees, by the convention of the body's in ENU:
    /// `C_sᵇ = dcm_body_to_nav(roll, pitch, yaw)` and `x_b = C_sᵇ x_s`.
    pub mounting_deg: [f64; 3],
    /// The GNSS antenna's position from the IMU, body frame (right, forward, up), m.
    pub gnss_lever_arm_m: [f64; 3],
    /// Longest gap between IMU samples integrated across, s; a longer one restarts the
    /// alignment.
    pub max_gap_s: f64,
    /// Seconds every aid may stay isolated before the mechanization is re-placed on the
    /// next GNSS fix (position and velocity; the filter restarts, integrity converges
    /// again); `null`: never. A MEMS INS coasting longer is no reference to test GNSS
    /// against.
    pub reinit_after_s: Option<f64>,
    /// Alignment.
    pub align: AlignSection,
}

impl Default for StrapdownSection {
    fn default() -> Self {
        StrapdownSection {
            mounting_deg: [0.0; 3],
            gnss_lever_arm_m: [0.0; 3],
            max_gap_s: 1.0,
            reinit_after_s: Some(DEFAULT_REINIT_AFTER_S),
            align: AlignSection::default(),
        }
    }
}

/// Default `reinit_after_s`, s: a MEMS INS coasting 20 s is tens of metres off, more
/// than any GNSS fix it would be tested against.
pub const DEFAULT_REINIT_AFTER_S: f64 = 20.0;

/// The validated `strapdown` section.
#[derive(Debug, Clone, PartialEq)]
pub struct StrapdownConfig {
    /// As given (echoed back by the spec).
    pub section: StrapdownSection,
    /// `C_sᵇ`.
    pub c_sb: Matrix3<f64>,
    /// The antenna lever arm, body frame, m.
    pub lever_b: Vector3<f64>,
}

fn check(field: &str, ok: bool, what: &str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::new(format!("strapdown.{field}"), what))
    }
}

impl StrapdownConfig {
    /// Validates the section; errors name the field (`strapdown.align.static_s`).
    pub fn new(section: StrapdownSection) -> Result<Self, ConfigError> {
        let s = &section;
        let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        check("mounting_deg", finite3(&s.mounting_deg), "must be finite")?;
        check(
            "gnss_lever_arm_m",
            finite3(&s.gnss_lever_arm_m),
            "must be finite",
        )?;
        check(
            "gnss_lever_arm_m",
            s.gnss_lever_arm_m.iter().all(|x| x.abs() <= 100.0),
            "must be within ±100 m",
        )?;
        check(
            "max_gap_s",
            s.max_gap_s.is_finite() && s.max_gap_s > 0.0 && s.max_gap_s <= 10.0,
            "must be in (0, 10] s",
        )?;
        let a = &s.align;
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if let Some(r) = s.reinit_after_s {
            check(
                "reinit_after_s",
                positive(r),
                "must be a finite number > 0 (or null)",
            )?;
        }
        check(
            "align.static_s",
            positive(a.static_s),
            "must be a finite number > 0",
        )?;
        check(
            "align.max_accel_dev_mps2",
            positive(a.max_accel_dev_mps2),
            "must be a finite number > 0",
        )?;
        check(
            "align.max_rate_dps",
            positive(a.max_rate_dps),
            "must be a finite number > 0",
        )?;
        check(
            "align.min_speed_mps",
            positive(a.min_speed_mps),
            "must be a finite number > 0",
        )?;
        check(
            "align.att_sigma_deg",
            a.att_sigma_deg.iter().all(|&x| positive(x) && x <= 180.0),
            "each must be in (0, 180]",
        )?;
        if let Some(h) = a.heading_deg {
            check(
                "align.heading_deg",
                h.is_finite() && (-360.0..=360.0).contains(&h),
                "must be in [-360, 360]",
            )?;
        }
        let [r, p, y] = s.mounting_deg.map(f64::to_radians);
        Ok(StrapdownConfig {
            section,
            c_sb: geo::dcm_body_to_nav(r, p, y),
            lever_b: Vector3::from(s.gnss_lever_arm_m),
        })
    }
}

/// The alignment state, reported with the outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Alignment {
    /// Waiting for a static period long enough to level (or for a GNSS fix to place it).
    Levelling,
    /// Levelled, mechanizing roll and pitch, waiting for the heading (GNSS speed).
    Heading,
    /// Aligned: the filter runs on the mechanized solution.
    Aligned,
}

/// One IMU sample in the body frame as rates (m/s², rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct BodyRates {
    f: [f64; 3],
    w: [f64; 3],
}

/// The front end's state (a checkpoint saves it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrontState {
    /// Time of the last IMU sample.
    last_t: Option<f64>,
    /// The last sample as rates (for the trapezoid of rate inputs, the lever arm's ω).
    last_rates: Option<BodyRates>,
    /// Levelling's accumulator.
    levelling: align::Levelling,
    /// The mechanization, from levelling on.
    mech: Option<Strapdown>,
    /// The heading is known and the filter runs.
    aligned: bool,
    /// Estimated gyro biases (body, rad/s) and accelerometer biases (m/s²), fed back.
    gyro_bias: [f64; 3],
    accel_bias: [f64; 3],
    /// The last GNSS fix seen while aligning, with its time (position and velocity source).
    last_fix: Option<(f64, Fix)>,
    /// Levelling's low-passed specific force and rate (body), against vibration.
    lowpass: Option<([f64; 3], [f64; 3])>,
    /// Since when every aid has been isolated (s), while aligned.
    #[serde(default)]
    isolated_since: Option<f64>,
}

/// Time constant of the low-pass before the static detector, s: an idling car's vibration
/// reaches several °/s and 0.04 g per sample.
const LEVELLING_LOWPASS_S: f64 = 0.25;

/// A GNSS speed from which the vehicle is not static, m/s (levelling restarts).
const STATIC_SPEED_MPS: f64 = 0.3;

/// A GNSS fix as alignment keeps it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct Fix {
    lat: f64,
    lon: f64,
    h: f64,
    vel: Option<[f64; 3]>,
}

impl Fix {
    fn lla(&self) -> Lla {
        Lla {
            lat: self.lat,
            lon: self.lon,
            h: self.h,
        }
    }
}

impl From<&GnssBlock> for Fix {
    fn from(g: &GnssBlock) -> Self {
        Fix {
            lat: g.lat,
            lon: g.lon,
            h: g.h,
            vel: g.vel,
        }
    }
}

/// What one IMU epoch did to the front end.
pub(super) enum Advance {
    /// Still aligning: no navigation solution yet.
    Aligning,
    /// A navigation solution for the filter; `restart`: the first after alignment.
    Nav {
        /// The mechanized solution the filter linearises about.
        nav: NavSolution,
        /// The filter (re)starts at this epoch.
        restart: bool,
        /// Seconds since the previous IMU epoch.
        dt: f64,
    },
}

impl FrontState {
    /// Before any sample.
    pub fn new(cfg: &StrapdownConfig) -> Self {
        let a = &cfg.section.align;
        FrontState {
            last_t: None,
            last_rates: None,
            levelling: align::Levelling::new(
                a.static_s,
                a.max_accel_dev_mps2,
                a.max_rate_dps.to_radians(),
            ),
            mech: None,
            aligned: false,
            gyro_bias: [0.0; 3],
            accel_bias: [0.0; 3],
            last_fix: None,
            lowpass: None,
            isolated_since: None,
        }
    }

    /// Notes whether every aid is isolated after the epoch at `t` (for `reinit_after_s`).
    pub(super) fn note_isolation(&mut self, t: f64, all_isolated: bool) {
        self.isolated_since = match (all_isolated, self.isolated_since) {
            (true, Some(since)) => Some(since),
            (true, None) => Some(t),
            (false, _) => None,
        };
    }

    /// The alignment state.
    pub fn alignment(&self) -> Alignment {
        match (&self.mech, self.aligned) {
            (Some(_), true) => Alignment::Aligned,
            (Some(_), false) => Alignment::Heading,
            (None, _) => Alignment::Levelling,
        }
    }

    /// The mechanization, once levelled.
    pub fn mech(&self) -> Option<&Strapdown> {
        self.mech.as_ref()
    }

    /// Estimated biases (gyro rad/s, accelerometer m/s², body frame).
    pub fn biases(&self) -> ([f64; 3], [f64; 3]) {
        (self.gyro_bias, self.accel_bias)
    }

    /// The epoch's sample in the body frame as rates, bias-corrected, and its increments
    /// over `dt` (rates: the trapezoid with the previous sample; increments as given).
    fn body_sample(
        &self,
        cfg: &StrapdownConfig,
        imu: &ImuBlock,
        dt: f64,
    ) -> (BodyRates, Increments) {
        let rot = |v: [f64; 3]| cfg.c_sb * Vector3::from(v);
        let (bg, ba) = (
            Vector3::from(self.gyro_bias),
            Vector3::from(self.accel_bias),
        );
        let (f, w, dv, dtheta) = match imu.dt {
            Some(span) => {
                let dv = rot(imu.accel) - ba * span;
                let dth = rot(imu.gyro) - bg * span;
                (dv / span, dth / span, dv * (dt / span), dth * (dt / span))
            }
            None => {
                let f = rot(imu.accel) - ba;
                let w = rot(imu.gyro) - bg;
                let (pf, pw) = match &self.last_rates {
                    Some(p) => (Vector3::from(p.f), Vector3::from(p.w)),
                    None => (f, w),
                };
                (f, w, (f + pf) * (0.5 * dt), (w + pw) * (0.5 * dt))
            }
        };
        let rates = BodyRates {
            f: f.into(),
            w: w.into(),
        };
        (
            rates,
            Increments {
                dtheta: dtheta.into(),
                dv: dv.into(),
                dt,
            },
        )
    }

    /// Moves the front end by one epoch that carries `imu`.
    pub(super) fn advance(
        &mut self,
        cfg: &StrapdownConfig,
        epoch: &Epoch,
        imu: &ImuBlock,
    ) -> Advance {
        let dt = self.last_t.map(|last| epoch.t - last);
        if let Some(g) = &epoch.gnss {
            self.last_fix = Some((epoch.t, Fix::from(g)));
        }
        let gap = !matches!(dt, Some(d) if d > 0.0 && d <= cfg.section.max_gap_s);
        if gap && self.last_t.is_some() {
            // A gap (or time standing still or going back): the history is void; the
            // bias estimates are kept (levelling refines the gyros' again).
            *self = FrontState {
                last_fix: self.last_fix.take(),
                gyro_bias: self.gyro_bias,
                accel_bias: self.accel_bias,
                ..FrontState::new(cfg)
            };
        }
        let dt = if gap { 0.0 } else { dt.unwrap_or(0.0) };
        let (rates, inc) = self.body_sample(cfg, imu, dt);
        self.last_t = Some(epoch.t);
        self.last_rates = Some(rates);
        if dt == 0.0 {
            return Advance::Aligning;
        }
        let reinit = match (cfg.section.reinit_after_s, self.isolated_since) {
            (Some(after), Some(since)) => epoch.t - since >= after,
            _ => false,
        };
        match (&mut self.mech, self.aligned) {
            (Some(mech), true) => {
                mech.step(&inc);
                if let (true, Some(g)) = (reinit, &epoch.gnss) {
                    // Re-placed on the fix, attitude kept: the filter restarts.
                    let lla = antenna_to_imu(Fix::from(g).lla(), &mech.c_bn(), &cfg.lever_b);
                    let vel = g.vel.map_or_else(|| mech.vel(), Vector3::from);
                    mech.set_position_velocity(lla, vel);
                    self.isolated_since = None;
                    return self.started();
                }
                Advance::Nav {
                    nav: nav_solution(mech),
                    restart: false,
                    dt,
                }
            }
            (Some(mech), false) => {
                mech.step(&inc);
                self.try_heading(cfg, epoch.t)
            }
            (None, _) => self.level(cfg, epoch.t, &rates, dt),
        }
    }

    /// Levelling (docs/methods.md §M31): the sample, low-passed, goes to the static
    /// detector unless the last GNSS fix says the vehicle moves. With a configured heading
    /// the mechanization starts aligned once levelling has its static time; without one it
    /// starts, levelled, when the static run that was long enough ends (the vehicle moves
    /// off), with the gyro biases set to the run's mean rate less the Earth rate's
    /// vertical part.
    fn level(&mut self, cfg: &StrapdownConfig, t: f64, rates: &BodyRates, dt: f64) -> Advance {
        let before = self.levelling.attitude().zip(self.levelling.mean_rate());
        let k = dt / (dt + LEVELLING_LOWPASS_S);
        let (f, w) = (Vector3::from(rates.f), Vector3::from(rates.w));
        let (lf, lw) = match self.lowpass {
            Some((lf, lw)) => {
                let (lf, lw) = (Vector3::from(lf), Vector3::from(lw));
                (lf + (f - lf) * k, lw + (w - lw) * k)
            }
            None => (f, w),
        };
        self.lowpass = Some((lf.into(), lw.into()));
        let fix = self.last_fix;
        let moving = fix.is_some_and(|(fix_t, fix)| {
            t - fix_t <= 2.0
                && fix
                    .vel
                    .is_some_and(|v| v[0].hypot(v[1]) >= STATIC_SPEED_MPS)
        });
        if moving {
            self.levelling.restart();
        } else {
            let g = fix.map_or(geo::normal_gravity(0.0, 0.0), |(_, f)| {
                geo::normal_gravity(f.lat, f.h)
            });
            self.levelling.add(&lf, &lw, dt, g);
        }
        let now = self.levelling.attitude().zip(self.levelling.mean_rate());
        match (cfg.section.align.heading_deg, now, before) {
            (Some(heading), Some(level), _) => self.start(cfg, level, Some(heading.to_radians())),
            (None, None, Some(level)) => self.start(cfg, level, None),
            _ => Advance::Aligning,
        }
    }

    /// The mechanization starts, at rest at the last fix, levelled by `((roll, pitch),
    /// mean rate)`, with `heading` (aligned at once) or a provisional one; `Aligning`
    /// without a fix yet.
    fn start(
        &mut self,
        cfg: &StrapdownConfig,
        ((roll, pitch), rate): ((f64, f64), Vector3<f64>),
        heading: Option<f64>,
    ) -> Advance {
        let Some((_, fix)) = self.last_fix else {
            return Advance::Aligning;
        };
        let c_bn = geo::dcm_body_to_nav(roll, pitch, heading.unwrap_or(0.0));
        // The Earth rate's vertical part is known without the heading.
        let earth_up = c_bn.transpose() * Vector3::new(0.0, 0.0, geo::OMEGA_IE * fix.lat.sin());
        self.gyro_bias = (Vector3::from(self.gyro_bias) + rate - earth_up).into();
        let lla = antenna_to_imu(fix.lla(), &c_bn, &cfg.lever_b);
        self.mech = Some(Strapdown::new(lla, Vector3::zeros(), c_bn));
        self.lowpass = None;
        if heading.is_some() {
            self.aligned = true;
            return self.started();
        }
        Advance::Aligning
    }

    /// Levelled and moving: the heading from a fresh GNSS velocity (at most `max_gap_s`
    /// old) once the horizontal speed reaches `min_speed_mps`: the body's forward axis is
    /// taken along the course (no sideslip); position and velocity from that fix.
    fn try_heading(&mut self, cfg: &StrapdownConfig, t: f64) -> Advance {
        let Some((fix_t, fix)) = &self.last_fix else {
            return Advance::Aligning;
        };
        let Some(vel) = fix.vel.map(Vector3::from) else {
            return Advance::Aligning;
        };
        if t - fix_t > cfg.section.max_gap_s || vel.xy().norm() < cfg.section.align.min_speed_mps {
            return Advance::Aligning;
        }
        let Some(mech) = &mut self.mech else {
            return Advance::Aligning;
        };
        let [roll, pitch, _] = mech.att();
        let c_bn = geo::dcm_body_to_nav(roll, pitch, align::heading_from_velocity(&vel));
        let lla = antenna_to_imu(fix.lla(), &c_bn, &cfg.lever_b);
        mech.set_attitude(c_bn);
        mech.set_position_velocity(lla, vel);
        self.aligned = true;
        self.started()
    }

    /// The first navigation solution after alignment: the filter restarts on it.
    fn started(&self) -> Advance {
        match &self.mech {
            Some(mech) => Advance::Nav {
                nav: nav_solution(mech),
                restart: true,
                dt: 0.0,
            },
            None => Advance::Aligning,
        }
    }

    /// Closed-loop feedback of the fused error estimate `dx` (errors are INS − true).
    pub fn feed_back(&mut self, dx: &ErrorVector) {
        let Some(mech) = &mut self.mech else {
            return;
        };
        let part = |at: usize| Vector3::new(dx[at], dx[at + 1], dx[at + 2]);
        mech.correct(&part(ATT), &part(VEL), &part(POS));
        for i in 0..3 {
            self.gyro_bias[i] += dx[GYRO + i];
            self.accel_bias[i] += dx[ACC + i];
        }
    }

    /// The body angular rate of the last sample, rad/s (bias-corrected).
    pub fn last_rate(&self) -> Vector3<f64> {
        self.last_rates
            .map_or_else(Vector3::zeros, |r| Vector3::from(r.w))
    }
}

/// The mechanization as the error model's linearisation point.
pub(super) fn nav_solution(mech: &Strapdown) -> NavSolution {
    NavSolution {
        lla: mech.lla(),
        vel: mech.vel(),
        c_bn: mech.c_bn(),
        f_n: mech.f_n(),
    }
}

/// The IMU's position from an antenna position: `p_imu = p_ant − C_bⁿ l_b`.
fn antenna_to_imu(ant: Lla, c_bn: &Matrix3<f64>, lever_b: &Vector3<f64>) -> Lla {
    geo::apply_offset(&ant, &-(c_bn * lever_b))
}

/// A GNSS fix moved from the antenna to the IMU with the mechanized attitude and body rate:
/// `p_imu = p_ant − C_bⁿ l_b`, `v_imu = v_ant − C_bⁿ (ω_b × l_b)` (Earth rate left out:
/// ~5e-5 m/s for a metre of lever arm).
pub(super) fn fix_at_imu(
    fix: &GnssBlock,
    nav: &NavSolution,
    w_b: &Vector3<f64>,
    lever_b: &Vector3<f64>,
) -> GnssBlock {
    if *lever_b == Vector3::zeros() {
        return fix.clone();
    }
    let ant = Lla {
        lat: fix.lat,
        lon: fix.lon,
        h: fix.h,
    };
    let lla = antenna_to_imu(ant, &nav.c_bn, lever_b);
    let vel = fix
        .vel
        .map(|v| (Vector3::from(v) - nav.c_bn * w_b.cross(lever_b)).into());
    GnssBlock {
        lat: lla.lat,
        lon: lla.lon,
        h: lla.h,
        vel,
        ..fix.clone()
    }
}
