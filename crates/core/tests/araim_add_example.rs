//! The ARAIM user algorithm on the worked example in the appendix of Blanch et al.,
//! "Advanced RAIM user algorithm description: integrity support message processing, fault
//! detection, exclusion, and protection level calculation", ION GNSS 2012: ten
//! satellites of two constellations, their geometry and C_acc given to four decimals, and
//! the subset σ's and biases, K_fa, σ_acc, VPL and HPL printed. Our subset solutions are
//! checked against those figures, and the example's PLs are recomputed with our PL
//! solver from our subsets over the example's mode set (which the 2012 document chose by
//! separate satellite and constellation limits; `AraimModel` itself enumerates joint
//! events, as the later ADD does, so its own mode set here is larger). The example's EMT
//! (11.8 m) is not checked: its 2012 definition could not be recovered from the figures
//! (the later ADD's, max T_k,3 over modes at least P_EMT probable, gives 8.26 m here).

use navguard_core::epoch::SatId;
use navguard_core::gnss::araim::{AraimModel, AraimParams, AraimSat, PlTerm, q_inv, solve_pl};

/// The example's geometry matrix: five satellites of each of two constellations, rows
/// `[−LOS_east, −LOS_north, −LOS_up]` (the clock columns follow the constellation).
const G: [[f64; 3]; 10] = [
    [0.0225, 0.9951, -0.0966],
    [0.6750, -0.6900, -0.2612],
    [0.0723, -0.6601, -0.7477],
    [-0.9398, 0.2553, -0.2269],
    [-0.5907, -0.7539, -0.2877],
    [-0.3236, -0.0354, -0.9455],
    [-0.6748, 0.4356, -0.5957],
    [0.0938, -0.7004, -0.7075],
    [0.5571, 0.3088, -0.7709],
    [0.6622, 0.6958, -0.2780],
];

/// The example's C_acc diagonal, m² (σ_URE² + σ_tropo² + σ_user², σ_URE = 0.5 m).
const C_ACC: [f64; 10] = [
    3.5740, 1.1252, 0.5479, 1.3258, 1.0104, 0.5309, 0.5838, 0.5544, 0.5448, 1.0491,
];

fn sats() -> Vec<AraimSat> {
    (0..10)
        .map(|i| {
            let los = [-G[i][0], -G[i][1], -G[i][2]];
            let norm = (los[0] * los[0] + los[1] * los[1] + los[2] * los[2]).sqrt();
            let id = if i < 5 {
                format!("G{:02}", i + 1)
            } else {
                format!("E{:02}", i - 4)
            };
            AraimSat {
                id: SatId::parse(&id).unwrap(),
                los_enu: [los[0] / norm, los[1] / norm, los[2] / norm],
                clock: usize::from(i >= 5),
                sigma_ura: 0.75,
                sigma_ure: 0.5,
                b_nom: 0.5,
                el: (los[2] / norm).asin(),
                sigma_local: Some((C_ACC[i] - 0.25).sqrt()),
            }
        })
        .collect()
}

/// The example's ISM and allocations: P_sat = P_const = 1e-4 and the ADD's LPV-200
/// budgets (the defaults). Every one- and two-event mode is enumerated (`p_thres`
/// negligible) so that each subset of the example's mode set is fitted.
fn params() -> AraimParams {
    let mut p = AraimParams {
        p_sat: 1e-4,
        p_thres: 1e-15,
        max_fault_order: 2,
        ..AraimParams::default()
    };
    p.p_const[0] = 1e-4;
    p.p_const[1] = 1e-4;
    p
}

/// The mode of `model` that excludes exactly `ids`, as a subset index (mode + 1).
fn subset(model: &AraimModel, ids: &[&str]) -> usize {
    let want: Vec<SatId> = ids.iter().map(|s| SatId::parse(s).unwrap()).collect();
    (0..model.modes().len())
        .find(|&k| model.excluded(k) == want)
        .unwrap_or_else(|| panic!("no mode excludes {ids:?}"))
        + 1
}

fn close(got: f64, want: f64, tol: f64, what: &str) {
    assert!((got - want).abs() <= tol, "{what}: {got} against {want}");
}

#[test]
fn subset_sigmas_biases_and_accuracy_match_the_worked_example() {
    let m = AraimModel::fit(&sats(), &params()).unwrap();
    // The example prints σ₃, σ_ss,3 and b₃ of the two constellation-out subsets to 1e-4 m
    // (its C_acc to 1e-4 m² too) and σ_v,acc to 1e-2 m.
    let gps_out = subset(&m, &["G01", "G02", "G03", "G04", "G05"]);
    let gal_out = subset(&m, &["E01", "E02", "E03", "E04", "E05"]);
    close(m.sigma(gps_out)[2], 2.5760, 2e-4, "σ₃ without GPS");
    close(m.sigma(gal_out)[2], 2.5577, 2e-4, "σ₃ without Galileo");
    close(m.sigma_ss(gps_out)[2], 1.5307, 2e-4, "σ_ss,3 without GPS");
    close(
        m.sigma_ss(gal_out)[2],
        1.5292,
        2e-4,
        "σ_ss,3 without Galileo",
    );
    close(m.bias(gps_out)[2], 2.8935, 2e-4, "b₃ without GPS");
    close(m.bias(gal_out)[2], 2.0875, 2e-4, "b₃ without Galileo");
    close(m.sigma_acc(), 1.47, 5e-3, "σ_v,acc");
}

/// The example's mode set (ADD 2012: up to N_sat,max = 2 satellites, or N_const,max = 1
/// constellation, never both): ten single satellites, their 45 pairs and the two
/// constellations, 57 modes, each with its subset index in `model` and prior.
fn example_modes(model: &AraimModel) -> Vec<(usize, f64)> {
    let ids: Vec<String> = (1..=5)
        .map(|k| format!("G{k:02}"))
        .chain((1..=5).map(|k| format!("E{k:02}")))
        .collect();
    let id = |i: usize| ids[i].as_str();
    let mut modes = Vec::new();
    for i in 0..10 {
        modes.push((subset(model, &[id(i)]), 1e-4));
        for j in i + 1..10 {
            modes.push((subset(model, &[id(i), id(j)]), 1e-8));
        }
    }
    modes.push((
        subset(
            model,
            &ids[..5].iter().map(String::as_str).collect::<Vec<_>>(),
        ),
        1e-4,
    ));
    modes.push((
        subset(
            model,
            &ids[5..].iter().map(String::as_str).collect::<Vec<_>>(),
        ),
        1e-4,
    ));
    modes
}

#[test]
fn protection_levels_over_the_examples_modes_match_the_worked_example() {
    let m = AraimModel::fit(&sats(), &params()).unwrap();
    let modes = example_modes(&m);
    assert_eq!(modes.len(), 57);
    let n = modes.len() as f64;
    // K_fa,3 = Q⁻¹(P_FA,VERT / 2N) = 5.3953 (the example's figure); K_fa,1,2 = Q⁻¹(P_FA,HOR / 4N).
    let k_fa = [
        q_inv(9e-8 / (4.0 * n)),
        q_inv(9e-8 / (4.0 * n)),
        q_inv(3.9e-6 / (2.0 * n)),
    ];
    close(k_fa[2], 5.3953, 1e-4, "K_fa,3");
    // P_not_monitored: three or more of the ten satellites, or both constellations.
    let p = 1e-4_f64;
    let p_sat_nm =
        1.0 - (1.0 - p).powi(10) - 10.0 * p * (1.0 - p).powi(9) - 45.0 * p * p * (1.0 - p).powi(8);
    let p_nm = p_sat_nm + p * p;
    let scale = 1.0 - p_nm / 1e-7;
    let pl = |q: usize, budget: f64| {
        let mut terms = vec![PlTerm {
            coef: 2.0,
            offset: m.bias(0)[q],
            sigma: m.sigma(0)[q],
        }];
        terms.extend(modes.iter().map(|&(k, p_fault)| PlTerm {
            coef: p_fault,
            offset: k_fa[q] * m.sigma_ss(k)[q] + m.bias(k)[q],
            sigma: m.sigma(k)[q],
        }));
        solve_pl(&terms, budget * scale, 5e-2)
    };
    let vpl = pl(2, 9.8e-8);
    let hpl = pl(0, 1e-9).hypot(pl(1, 1e-9));
    // The example gives the levels to 0.1 m; TOL_PL is 0.05 m.
    println!("example: VPL {vpl:.3} m, HPL {hpl:.3} m");
    close(vpl, 19.7, 0.1, "VPL");
    close(hpl, 14.9, 0.1, "HPL");
}
