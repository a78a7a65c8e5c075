//! Scenarios: a truth path, the simulated INS, the aid sensors and a fault list,
//! run into a sequence of [`SimEpoch`]s (domain epoch + truth). The top of the
//! simulator: the CLI writes these epochs as ingest frames, the experiments and
//! tests feed them to the monitors and score the result against the truth.
//!
//! [`ship`] is docs/methods.md §M19's seed 004 scenario (module doc of [`ship_trajectory`]
//! for the route); [`ship_with`] varies its faults and duration (the ramp
//! experiment), [`ship_fault_free`] drops the faults, [`track_scenario`] rides
//! the same sensors on a real RTK track. Every scenario is reproducible from its
//! seed (same seed and build → identical epochs; see `sim::rng`).

use super::faults::{Channel, Fault, FaultInjector, FaultKind, arcmin_to_metres};
use super::ins_truth::{InsErrorConfig, InsErrorSim};
use super::sensors::{AidSensors, SensorConfig};
use super::track::Track;
use super::trajectory::{Trajectory, TrajectoryBuilder};
use super::truth::Truth;
use super::{SimError, check_non_negative};
use navguard_core::epoch::Aid;
use navguard_core::epoch::Epoch;
use navguard_core::geo::Lla;
use navguard_core::monitor::federated::{
    CnsNoise, DvlNoise, FederatedConfigWire, GnssNoise, ImuSection, InitSigma,
};

/// The ship's start latitude, degrees (docs/methods.md §M19; the seed gives none — a
/// mid-latitude sea area, 30°N 114°E).
pub const SHIP_START_LAT_DEG: f64 = 30.0;
/// The ship's start longitude, degrees.
pub const SHIP_START_LON_DEG: f64 = 114.0;
/// The ship scenario's length, s (seed 004's figures span one hour).
pub const SHIP_DURATION_S: f64 = 3600.0;
/// The ship's INS rate, Hz.
pub const SHIP_INS_RATE_HZ: f64 = 10.0;

/// One simulated epoch: what the monitor sees, and the truth behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEpoch {
    /// The domain epoch (INS every epoch; aids when due, noisy and faulted).
    pub epoch: Epoch,
    /// The true state at `epoch.t`.
    pub truth: Truth,
}

/// Everything that defines a run besides the truth path.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioParams {
    /// Scenario name (`ship`, `track`, …).
    pub name: String,
    /// RNG seed.
    pub seed: u64,
    /// INS output rate, Hz (every aid rate must divide it).
    pub ins_rate_hz: f64,
    /// True INS error model.
    pub ins: InsErrorConfig,
    /// Aid sensors.
    pub sensors: SensorConfig,
    /// Injected faults.
    pub faults: Vec<Fault>,
}

/// A simulated run.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Scenario name.
    pub name: String,
    /// The seed it was drawn from.
    pub seed: u64,
    /// The epochs, one per INS tick, in time order.
    pub epochs: Vec<SimEpoch>,
    /// The injected faults.
    pub faults: Vec<Fault>,
    /// INS rate, Hz.
    pub ins_rate_hz: f64,
    /// Aid sensors (rates and noise).
    pub sensors: SensorConfig,
    /// True INS error model.
    pub ins: InsErrorConfig,
}

impl Scenario {
    /// Time of the last epoch, s.
    pub fn duration_s(&self) -> f64 {
        self.epochs.last().map_or(0.0, |e| e.epoch.t)
    }

    /// The aids the scenario carries.
    pub fn aids(&self) -> Vec<Aid> {
        self.sensors.aids()
    }

    /// A `federated` monitor config (docs/methods.md §M6) matching the simulation:
    /// `aids`, one noise block per aid present, `imu`, and `init` (the magnitudes
    /// of the true initial errors as 1σ; the monitor's default if any is 0, which
    /// the monitor refuses). The DVL's scale-factor error (1e-3 × ≤ 12 m/s ≈
    /// 0.01 m/s) is left inside its 0.1 m/s σ. β, HAL and P_md are the monitor's
    /// defaults.
    pub fn monitor_config(&self) -> FederatedConfigWire {
        let att = self.ins.init_att_arcsec.map(f64::abs);
        let init = if att
            .iter()
            .chain([&self.ins.init_pos_m, &self.ins.init_vel_mps])
            .all(|&x| x > 0.0)
        {
            InitSigma {
                att_sigma_arcsec: att,
                pos_sigma_m: self.ins.init_pos_m,
                vel_sigma_mps: self.ins.init_vel_mps,
            }
        } else {
            InitSigma::default()
        };
        FederatedConfigWire {
            gnss: self.sensors.gnss.map(|g| GnssNoise {
                pos_sigma_m: g.pos_sigma_m,
                vel_sigma_mps: g.vel_sigma_mps,
                ..GnssNoise::default()
            }),
            dvl: self.sensors.dvl.map(|d| DvlNoise {
                vel_sigma_mps: d.vel_sigma_mps,
                ..DvlNoise::default()
            }),
            cns: self.sensors.cns.map(|c| CnsNoise {
                pos_sigma_m: c.pos_sigma_m,
                ..CnsNoise::default()
            }),
            imu: ImuSection::from(self.ins.imu),
            init,
            ..FederatedConfigWire::new(self.aids())
        }
    }

    /// [`Scenario::monitor_config`] as the JSON a session body carries.
    pub fn default_monitor_config(&self) -> serde_json::Value {
        serde_json::to_value(self.monitor_config())
            .expect("a federated config of finite numbers serialises")
    }
}

/// Runs `params` over `truth` (sampled at `params.ins_rate_hz`): INS output with
/// the true errors, aid readings with noise and faults.
///
/// # Errors
/// [`SimError`] for an invalid INS or sensor configuration or fault.
pub fn simulate(params: ScenarioParams, truth: Vec<Truth>) -> Result<Scenario, SimError> {
    let mut ins = InsErrorSim::new(&params.ins, params.seed)?;
    let mut sensors = AidSensors::new(&params.sensors, params.ins_rate_hz, params.seed)?;
    let mut injector = FaultInjector::new(params.faults.clone())?;
    let dt = 1.0 / params.ins_rate_hz;
    let epochs = truth
        .into_iter()
        .zip(0u64..)
        .map(|(truth, k)| {
            let mut epoch = Epoch {
                t: truth.t,
                ins: Some(ins.step(&truth, dt)),
                ..Epoch::default()
            };
            sensors.observe(k, &truth, &mut injector, &mut epoch);
            SimEpoch { epoch, truth }
        })
        .collect();
    Ok(Scenario {
        name: params.name,
        seed: params.seed,
        epochs,
        faults: params.faults,
        ins_rate_hz: params.ins_rate_hz,
        sensors: params.sensors,
        ins: params.ins,
    })
}

/// The ship's route: from 30°N 114°E at 10 m/s heading 045°, straight legs
/// joined by gentle coordinated turns (0.3–0.5 °/s, bank ≈ 0.3–0.5°) and two
/// speed changes (10 → 12 → 10 m/s at 0.02 m/s²), at sea level:
///
/// | t (s) | manoeuvre |
/// |---|---|
/// | 0–400 | straight, 045° |
/// | 400–580 | turn right 90° at 0.5 °/s → 135° |
/// | 580–1000 | straight |
/// | 1000–1100 | speed up to 12 m/s |
/// | 1100–1600 | straight |
/// | 1600–1870 | turn left 135° at 0.5 °/s → 000° |
/// | 1870–2300 | straight |
/// | 2300–2400 | slow down to 10 m/s |
/// | 2400–2600 | turn right 60° at 0.3 °/s → 060° |
/// | 2600– | straight (for as long as the run lasts) |
pub fn ship_trajectory() -> Result<Trajectory, SimError> {
    let start = Lla {
        lat: SHIP_START_LAT_DEG.to_radians(),
        lon: SHIP_START_LON_DEG.to_radians(),
        h: 0.0,
    };
    let deg = |d: f64| d.to_radians();
    TrajectoryBuilder::new(start, 10.0, deg(45.0))
        .straight(400.0)
        .turn(deg(90.0), deg(0.5))
        .straight(420.0)
        .speed_change(12.0, 0.02)
        .straight(500.0)
        .turn(deg(-135.0), deg(0.5))
        .straight(430.0)
        .speed_change(10.0, 0.02)
        .turn(deg(60.0), deg(0.3))
        .build()
}

/// A ship that stops and starts again (docs/methods.md §M19, §M23; for the frozen-fix
/// faults of `experiment guards`): seed 004's start, then
///
/// | t (s) | manoeuvre |
/// |---|---|
/// | 0–300 | straight, 045°, 10 m/s |
/// | 300–500 | slow down to 0 at 0.05 m/s² |
/// | 500–1200 | stationary |
/// | 1200–1210 | creep off at 0.05 m/s² to 0.5 m/s |
/// | 1210–1510 | creeping at 0.5 m/s |
/// | 1510–1700 | speed up to 10 m/s |
/// | 1700– | straight at 10 m/s |
pub fn station_keeping_trajectory() -> Result<Trajectory, SimError> {
    let start = Lla {
        lat: SHIP_START_LAT_DEG.to_radians(),
        lon: SHIP_START_LON_DEG.to_radians(),
        h: 0.0,
    };
    TrajectoryBuilder::new(start, 10.0, 45f64.to_radians())
        .straight(300.0)
        .speed_change(0.0, 0.05)
        .straight(700.0)
        .speed_change(0.5, 0.05)
        .straight(300.0)
        .speed_change(10.0, 0.05)
        .build()
}

/// A frozen GNSS fix: every position component held at its value at `start_s` until
/// `end_s` (seed 001's stuck fault on a whole fix; the velocity keeps reporting).
pub fn gnss_freeze(start_s: f64, end_s: f64) -> Vec<Fault> {
    (0..3)
        .map(|component| Fault {
            aid: Aid::Gnss,
            channel: Channel::Position,
            component,
            kind: FaultKind::Stuck,
            start_s,
            end_s: Some(end_s),
        })
        .collect()
}

/// The station-keeping ship (10 Hz INS, seed 004's sensors) with `faults`, `duration_s`
/// long.
///
/// # Errors
/// [`SimError`] for a negative duration or an invalid fault.
pub fn station_keeping_with(
    seed: u64,
    faults: Vec<Fault>,
    duration_s: f64,
) -> Result<Scenario, SimError> {
    check_non_negative("duration_s", duration_s)?;
    let truth = station_keeping_trajectory()?.sample(SHIP_INS_RATE_HZ, duration_s)?;
    simulate(
        ScenarioParams {
            name: "station-keeping".into(),
            ..ship_params(seed, faults)
        },
        truth,
    )
}

/// Seed 004's faults (docs/methods.md §M19): a GNSS position jump of 0.02′ in latitude
/// and longitude (converted at 30°N: ≈ 36.95 m north, 32.16 m east — the ship
/// stays within 0.2° of 30°N, so the metres differ from 0.02′ at its true
/// latitude by < 0.2 %) on [1080, 1200) s, and a GNSS velocity jump of +0.4 m/s
/// east and north from 1800 s to the end of the run (the seed gives no end).
pub fn ship_faults() -> Vec<Fault> {
    let (east_m, north_m) = arcmin_to_metres(SHIP_START_LAT_DEG.to_radians(), 0.0);
    let gnss = |channel, component, value, start_s, end_s| Fault {
        aid: Aid::Gnss,
        channel,
        component,
        kind: FaultKind::Step { value },
        start_s,
        end_s,
    };
    vec![
        gnss(Channel::Position, 0, 0.02 * east_m, 1080.0, Some(1200.0)),
        gnss(Channel::Position, 1, 0.02 * north_m, 1080.0, Some(1200.0)),
        gnss(Channel::Velocity, 0, 0.4, 1800.0, None),
        gnss(Channel::Velocity, 1, 0.4, 1800.0, None),
    ]
}

/// The ship's sensors and INS (seed 004 §3) with the given faults.
pub fn ship_params(seed: u64, faults: Vec<Fault>) -> ScenarioParams {
    ScenarioParams {
        name: "ship".into(),
        seed,
        ins_rate_hz: SHIP_INS_RATE_HZ,
        ins: InsErrorConfig::default(),
        sensors: SensorConfig::default(),
        faults,
    }
}

/// The ship with any faults and length (the route continues straight past 2600 s).
///
/// # Errors
/// [`SimError`] for a negative or non-finite duration or an invalid fault.
pub fn ship_with(seed: u64, faults: Vec<Fault>, duration_s: f64) -> Result<Scenario, SimError> {
    check_non_negative("duration_s", duration_s)?;
    let truth = ship_trajectory()?.sample(SHIP_INS_RATE_HZ, duration_s)?;
    simulate(ship_params(seed, faults), truth)
}

/// Seed 004's ship scenario (docs/methods.md §M19): 3600 s at 10 Hz, the faults of [`ship_faults`].
pub fn ship(seed: u64) -> Scenario {
    // The route, sensors and faults are constants (checked by this module's tests).
    ship_with(seed, ship_faults(), SHIP_DURATION_S)
        .expect("the ship scenario's constants are valid")
}

/// The ship without faults, 3600 s.
pub fn ship_fault_free(seed: u64) -> Scenario {
    ship_with(seed, Vec::new(), SHIP_DURATION_S).expect("the ship scenario's constants are valid")
}

/// The ship's sensors and INS riding on a real track (truth from [`Track::truth`]
/// at 10 Hz), with the given faults. On a land track the DVL stands in for a
/// body-frame odometer.
///
/// # Errors
/// [`SimError`] for an invalid fault.
pub fn track_scenario(track: &Track, seed: u64, faults: Vec<Fault>) -> Result<Scenario, SimError> {
    let truth = track.truth(SHIP_INS_RATE_HZ)?;
    simulate(
        ScenarioParams {
            name: "track".into(),
            ..ship_params(seed, faults)
        },
        truth,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use navguard_core::geo;
    use serde_json::json;

    fn gnss_lla(e: &SimEpoch) -> Option<Lla> {
        e.epoch.gnss.as_ref().map(|g| Lla {
            lat: g.lat,
            lon: g.lon,
            h: g.h,
        })
    }

    #[test]
    fn ship_is_reproducible_and_has_the_seed_004_faults() {
        let a = ship(1);
        assert_eq!(a.epochs.len(), 36_001);
        assert_eq!(a.duration_s(), 3600.0);
        assert_eq!(a, ship(1), "same seed, same epochs");
        let b = ship(2);
        assert_ne!(
            a.epochs[0].epoch, b.epochs[0].epoch,
            "different seed, different epochs"
        );
        assert_eq!(a.epochs[500].truth, b.epochs[500].truth, "same route");
        // Against the fault-free run (same noise): the jump on [1080, 1200) only.
        let clean = ship_fault_free(1);
        for (f, c) in a.epochs.iter().zip(&clean.epochs) {
            assert_eq!(f.epoch.ins, c.epoch.ins);
            let (Some(pf), Some(pc)) = (gnss_lla(f), gnss_lla(c)) else {
                continue;
            };
            let d = geo::local_offset(&pf, &pc);
            let t = f.epoch.t;
            let vf = f.epoch.gnss.as_ref().and_then(|g| g.vel).unwrap();
            let vc = c.epoch.gnss.as_ref().and_then(|g| g.vel).unwrap();
            if (1080.0..1200.0).contains(&t) {
                assert_relative_eq!(d.y, 36.95, epsilon = 0.05);
                assert_relative_eq!(d.x, 32.16, epsilon = 0.05);
            } else {
                assert!(d.norm() < 1e-6, "no position fault at {t}: {d}");
            }
            let dv = [vf[0] - vc[0], vf[1] - vc[1], vf[2] - vc[2]];
            let want = if t >= 1800.0 { 0.4 } else { 0.0 };
            assert_relative_eq!(dv[0], want, epsilon = 1e-12);
            assert_relative_eq!(dv[1], want, epsilon = 1e-12);
            assert_eq!(dv[2], 0.0);
        }
        // Aids at their rates: 3601 GNSS and DVL readings, 361 CNS fixes.
        let count = |f: fn(&SimEpoch) -> bool| a.epochs.iter().filter(|e| f(e)).count();
        assert_eq!(count(|e| e.epoch.gnss.is_some()), 3601);
        assert_eq!(count(|e| e.epoch.dvl_vel_b.is_some()), 3601);
        assert_eq!(count(|e| e.epoch.cns.is_some()), 361);
    }

    #[test]
    fn ship_route_is_gentle_and_ends_where_the_table_says() {
        let truth = ship_trajectory().unwrap().sample(1.0, 3600.0).unwrap();
        let speed = |t: usize| truth[t].vel.xy().norm();
        assert_relative_eq!(speed(200), 10.0, epsilon = 1e-9);
        assert_relative_eq!(speed(1300), 12.0, epsilon = 1e-9);
        assert_relative_eq!(speed(3000), 10.0, epsilon = 1e-9);
        assert_relative_eq!(truth[3000].att[2].to_degrees(), 60.0, epsilon = 1e-9);
        let max_bank = truth.iter().map(|s| s.att[0].abs()).fold(0.0, f64::max);
        assert!(max_bank.to_degrees() < 0.7, "bank {max_bank}");
        // The ship stays close to 30°N (the arc-minute conversion's latitude).
        assert!(
            truth
                .iter()
                .all(|s| (s.lla.lat.to_degrees() - 30.0).abs() < 0.2)
        );
    }

    #[test]
    fn ins_output_carries_the_seed_004_initial_errors() {
        let s = ship_with(3, Vec::new(), 1.0).unwrap();
        let e0 = &s.epochs[0];
        let ins = e0.epoch.ins.as_ref().unwrap();
        let d = geo::local_offset(
            &Lla {
                lat: ins.lat,
                lon: ins.lon,
                h: ins.h,
            },
            &e0.truth.lla,
        );
        for i in 0..3 {
            assert_relative_eq!(d[i].abs(), 10.0, epsilon = 1e-6);
            assert_relative_eq!((ins.vel[i] - e0.truth.vel[i]).abs(), 0.1, epsilon = 1e-12);
        }
        // Heading error = +φ_u = 30″: C̃ = (I − [φ×]) C turns the body by −φ_u about
        // up, i.e. clockwise, and heading is measured clockwise.
        let dyaw = ins.att[2] - e0.truth.att[2];
        assert_relative_eq!(dyaw.to_degrees() * 3600.0, 30.0, epsilon = 0.1);
    }

    #[test]
    fn any_fault_changes_only_its_channel_on_its_interval() {
        let fault = Fault {
            aid: Aid::Dvl,
            channel: Channel::Velocity,
            component: 1,
            kind: FaultKind::Gain { k: 1.1 },
            start_s: 20.0,
            end_s: Some(40.0),
        };
        let f = ship_with(9, vec![fault], 60.0).unwrap();
        let c = ship_with(9, Vec::new(), 60.0).unwrap();
        for (f, c) in f.epochs.iter().zip(&c.epochs) {
            assert_eq!(
                (&f.epoch.gnss, &f.epoch.cns, &f.epoch.ins),
                (&c.epoch.gnss, &c.epoch.cns, &c.epoch.ins)
            );
            let (Some(vf), Some(vc)) = (f.epoch.dvl_vel_b, c.epoch.dvl_vel_b) else {
                continue;
            };
            let k = if (20.0..40.0).contains(&f.epoch.t) {
                1.1
            } else {
                1.0
            };
            assert_eq!((vf[0], vf[2]), (vc[0], vc[2]));
            assert_relative_eq!(vf[1], k * vc[1], epsilon = 1e-12);
        }
        let missing = Fault {
            kind: FaultKind::Missing,
            aid: Aid::Cns,
            channel: Channel::Position,
            component: 0,
            ..fault
        };
        let m = ship_with(9, vec![missing], 60.0).unwrap();
        let cns_at = |s: &Scenario, t: usize| s.epochs[t * 10].epoch.cns.is_some();
        assert!(cns_at(&m, 10) && !cns_at(&m, 20) && !cns_at(&m, 30) && cns_at(&m, 40));
    }

    #[test]
    fn monitor_config_matches_the_sensors() {
        let s = ship_with(1, Vec::new(), 1.0).unwrap();
        let cfg = s.default_monitor_config();
        assert_eq!(cfg["aids"], json!(["gnss", "dvl", "cns"]));
        assert_eq!(cfg["gnss"]["pos_sigma_m"], json!(10.0));
        assert_eq!(cfg["gnss"]["vel_sigma_mps"], json!(0.1));
        assert_eq!(cfg["dvl"]["vel_sigma_mps"], json!(0.1));
        assert_eq!(cfg["cns"]["pos_sigma_m"], json!(450.0));
        assert_eq!(cfg["imu"]["gyro_bias_dph"], json!(0.002));
        assert_eq!(cfg["imu"]["accel_bias_ug"], json!(10.0));
        assert_eq!(cfg["init"]["att_sigma_arcsec"], json!([5.0, 5.0, 30.0]));
        // The typed config and its JSON agree, and the defaults are the monitor's.
        assert_eq!(
            serde_json::from_value::<FederatedConfigWire>(cfg.clone()).unwrap(),
            s.monitor_config()
        );
        assert_eq!(s.monitor_config().gnss, Some(GnssNoise::default()));
        assert_eq!(s.monitor_config().cns, Some(CnsNoise::default()));
        // The federated monitor accepts it as is.
        let parsed = navguard_core::monitor::federated::FederatedConfig::from_json(&cfg).unwrap();
        assert_eq!(parsed.cns_pos_sigma_m, 450.0);
        assert_eq!(parsed.init_pos_sigma_m, 10.0);
        assert!(ship_with(1, Vec::new(), -1.0).is_err());
        let bad = Fault {
            component: 5,
            ..ship_faults()[0]
        };
        assert!(matches!(
            ship_with(1, vec![bad], 1.0),
            Err(SimError::InvalidFault { index: 0, .. })
        ));
    }

    #[test]
    fn the_station_keeping_ship_stops_creeps_and_a_freeze_holds_the_fix() {
        let truth = station_keeping_trajectory()
            .unwrap()
            .sample(1.0, 1800.0)
            .unwrap();
        let speed = |t: usize| truth[t].vel.xy().norm();
        assert_relative_eq!(speed(100), 10.0, epsilon = 1e-9);
        assert!(speed(800) < 1e-9);
        assert_relative_eq!(speed(1300), 0.5, epsilon = 1e-9);
        assert_relative_eq!(speed(1750), 10.0, epsilon = 1e-9);
        let s = station_keeping_with(2, gnss_freeze(20.0, 30.0), 40.0).unwrap();
        let fix = |t: usize| gnss_lla(&s.epochs[t * 10]).unwrap();
        assert_eq!(fix(20), fix(29), "held");
        assert_ne!(fix(19), fix(20));
        assert_ne!(fix(29), fix(30), "released");
        assert_eq!(s.name, "station-keeping");
    }

    #[test]
    fn a_track_scenario_rides_the_real_fixes() {
        let text: String = (0..30)
            .map(|i| {
                format!(
                    "{} {:.10} 114.4718661 21.0\n",
                    456_250 + i,
                    30.4447858 + 9e-5 * f64::from(i)
                )
            })
            .collect();
        let s = track_scenario(&Track::parse(&text).unwrap(), 1, ship_faults()).unwrap();
        assert_eq!(s.epochs.len(), 291);
        assert_eq!(s.name, "track");
        assert_relative_eq!(
            s.epochs[150].truth.vel.y,
            9e-5f64.to_radians() * (geo::radii(0.5314).meridian + 21.0),
            max_relative = 1e-3
        );
    }
}
