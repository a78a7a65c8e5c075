"""Independent single-point positioning on navguard's real test data (not a test dependency).

Computes, per data set of tests/data/gnss (see its README for formats, truths and
quirks), the horizontal position error of independent tools' epoch-by-epoch fixes
against the stated truth (east/north at the truth point, WGS-84): number of epochs,
mean, 95th percentile (nearest rank, as navguard's `experiment raim`) and max, and
prints them as a table next to navguard's own figures. Python is a reference only:
nothing in the project runs or tests this script.

Tools and what each does here:
* gnss_lib_py 1.1.0 (Stanford NAV Lab, MIT):
  - gsdc2021 / gsdc2023: its own loaders AndroidDerived2021 / AndroidDerived2023 and
    AndroidGroundTruth2021 / AndroidGroundTruth2023 (these apply the README's GSDC-2021
    quirks themselves: previous-epoch mapping with the first epoch dropped, the (0,300)
    ms timing filter, truth height - 61 m), corrected pseudorange = raw + sat clock -
    ISRB - iono - tropo from the file, and its WLS `solve_wls` (one receiver clock,
    Sagnac rotation inside). Two settings: the library default (all signals of the
    file, L1 and L5 band, unweighted, no mask) and navguard-like (L1/E1/G1 band only,
    W = 1/sigma^2 from the file's pseudorange uncertainty, 10 deg mask from a first fix).
  - geonet (RINEX 2.10 station 0759): gnss_lib_py cannot read this file with its own
    RinexObs (georinex.load fails under numpy 2 when merging into an empty dataset, and
    RinexObs expects the RINEX 3 header layout), so the observations are read with
    georinex's RINEX-2 reader (`georinex.obs2.rinexsystem2(path, "G")`) and the
    epoch tags are taken as GPS time. Everything else is gnss_lib_py: RinexNav (nav file
    + ION ALPHA/BETA), `find_sv_states` (broadcast orbit and clock incl. relativity and
    -TGD) at the transmission time t_rx - PR/c - dt_sv, `calculate_pseudorange_corr`
    (its Klobuchar and its simple exponential troposphere model) and `wls` (unweighted,
    Sagnac rotation inside). Ephemeris: per satellite the healthy record with t_oe
    nearest the epoch. Mask 10 deg. Two settings: C1 single frequency with Klobuchar,
    and iono-free C1/P2 (TGD added back, no iono model).
  - gnsslogger (2016 demo log + hour1820.16n): its AndroidRawGnss loader, adapted for
    GnssLogger 1.4 (header ' Svid' with a blank, no utcTimeMillis, no CodeType: added
    from TimeNanos - FullBiasNanos - BiasNanos - 17 s and 'C'), its pseudorange (the
    first record's FullBiasNanos, as Google's ProcessGnssMeas) and sigma
    (ReceivedSvTimeUncertaintyNanos * c), its filters less BiasUncertaintyNanos < 40 ns
    (fails 1301 of 1379 records of this duty-cycled log), the ADR ones (no carrier
    phase) and the 500 ns cut. Satellites at the transmission time from
    ReceivedSvTimeNanos (the README's advice), then the same gnss_lib_py models and wls
    as for geonet (C1 + Klobuchar + its tropo, mask 10), unweighted and W = 1/sigma^2.
* RTKLIB 2.4.3 through pyrtklib 0.2.7 (MIT binding of RTKLIB, BSD-2-clause with
  RTKLIB's clauses): `postpos` in PMODE_SINGLE on the GEONET obs+nav, GPS only,
  elevation mask 10 deg, Saastamoinen troposphere, RTKLIB's default SPP weighting
  (elevation model err = 0.003 m a/b x EFACT, plus URA), no RAIM-FDE. Two settings:
  ionoopt brdc (C1, Klobuchar) and ionoopt iflc (C1/P2 iono-free; no P1-C1 DCB file).
  RTKLIB cannot read the GSDC CSVs or the GnssLogger text log, so it has GEONET only.
* For the GSDC sets, one more row that is not a tool: a plain numpy WLS (this file)
  with one receiver clock per constellation instead of gnss_lib_py's single clock,
  otherwise as the navguard-like gnss_lib_py row. It separates the effect of the clock
  model from that of navguard's fault exclusions.

Install (Python 3.11, Linux x86-64; versions used):
    python3 -m venv /tmp/glp
    /tmp/glp/bin/pip install gnss_lib_py==1.1.0 pyrtklib==0.2.7
    (gnss_lib_py 1.1.0 pulls georinex 1.16.1, numpy 2.4.6, pandas 2.3.3,
     scipy 1.17.1, xarray 2024.7.0)
Run from the repository root:
    /tmp/glp/bin/python crates/formats/reference/compare_reference_spp.py
"""
import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "tests" / "data" / "gnss"
C = 299792458.0
F1, F2 = 1575.42e6, 1227.60e6
GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
GEONET_TRUTH = np.array([-3976219.5082, 3382372.5671, 3652512.9849])
MASK_DEG = 10.0

# navguard's own figures, fault-free rows of `cargo run --release -- experiment raim`
# (σ scaled to the data, mask 10 deg; the fault-free rows do not depend on --draws),
# copied by hand from its output at the time of writing: (data, epochs, mean, 95 %, max,
# settings). Greedy excluded one satellite in one gsdc2021 epoch; solution separation
# excluded none.
NAVGUARD = [
    ("geonet", 120, 0.94, 1.83, 2.72, "greedy: iono-free C1/P2, elevation sigma, Saastamoinen"),
    ("gnsslogger", 223, 8.56, 17.19, 29.92, "greedy: L1 C/A + Klobuchar, given sigma"),
    ("gsdc2021", 6, 3.14, 6.55, 6.55, "greedy (1 exclusion): L1/E1/G1, given sigma"),
    ("gsdc2021", 6, 2.41, 5.68, 5.68, "solution_separation (0 excl.): L1/E1/G1, given sigma"),
    ("gsdc2023", 5, 3.43, 4.81, 4.81, "greedy: L1/E1/G1, given sigma"),
]


# ---------------------------------------------------------------- metrics

def ecef_to_lat_lon(x):
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    p = math.hypot(x[0], x[1])
    lat = math.atan2(x[2], p * (1 - e2))
    for _ in range(10):
        n = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(x[2], p * (1 - e2 * n / (n + h)))
    return lat, math.atan2(x[1], x[0])


def horizontal_errors(est, truth):
    """East/north error norm of each row of est (N,3) at truth (N,3) or (3,)."""
    est = np.atleast_2d(est)
    truth = np.broadcast_to(truth, est.shape)
    out = []
    for e, t in zip(est, truth):
        lat, lon = ecef_to_lat_lon(t)
        d = e - t
        east = -math.sin(lon) * d[0] + math.cos(lon) * d[1]
        north = (-math.sin(lat) * math.cos(lon) * d[0] - math.sin(lat) * math.sin(lon) * d[1]
                 + math.cos(lat) * d[2])
        out.append(math.hypot(east, north))
    return np.array(out)


def stats(h):
    h = np.sort(np.asarray(h)[np.isfinite(h)])
    if h.size == 0:
        return (0, float("nan"), float("nan"), float("nan"))
    k = min(max(math.ceil(h.size * 0.95), 1), h.size) - 1
    return (h.size, float(h.mean()), float(h[k]), float(h[-1]))


# ---------------------------------------------------------------- gnss_lib_py, GSDC

def _elevations_deg(rx, sv):
    from gnss_lib_py.utils.coordinates import ecef_to_el_az
    return ecef_to_el_az(np.reshape(rx, (3, 1)), np.asarray(sv).T)[0]


def gsdc_glp(derived, truth, navguard_like):
    """WLS per epoch with gnss_lib_py; returns (fix ECEF (N,3), truth ECEF (N,3))."""
    from gnss_lib_py.algorithms.snapshot import solve_wls, wls
    from gnss_lib_py.navdata.operations import loop_time
    fixes, t_ecef = [], []
    if not navguard_like:
        st = solve_wls(derived)  # library default: every signal, unweighted
        times = st["gps_millis"]
        fixes = st[["x_rx_wls_m", "y_rx_wls_m", "z_rx_wls_m"]].T
    else:
        times = []
        sub = derived.where("signal_type", ["l1", "e1", "g1", "GPS_L1_CA", "GAL_E1_C_P",
                                            "GLO_G1_CA"], "eq")
        for t, _, m in loop_time(sub, "gps_millis", delta_t_decimals=-2):
            sv = m[["x_sv_m", "y_sv_m", "z_sv_m"]].T
            pr = m["corr_pr_m"].reshape(-1, 1)
            sig = m["raw_pr_sigma_m"].reshape(-1)
            ok = np.isfinite(sv).all(axis=1) & np.isfinite(pr[:, 0]) & (sig > 0)
            sv, pr, w = sv[ok], pr[ok], 1.0 / sig[ok] ** 2
            x = wls(np.zeros((4, 1)), sv.copy(), pr, w.reshape(-1, 1))
            for _ in range(2):  # mask from the previous fix, then refit
                keep = _elevations_deg(x[:3, 0], sv) >= MASK_DEG
                x = wls(x, sv[keep].copy(), pr[keep], w[keep].reshape(-1, 1))
            times.append(t)
            fixes.append(x[:3, 0])
        times, fixes = np.array(times), np.array(fixes)
    tt = truth["gps_millis"]
    tx = truth[["x_rx_gt_m", "y_rx_gt_m", "z_rx_gt_m"]].T
    for t in times:
        j = int(np.argmin(np.abs(tt - t)))
        if abs(tt[j] - t) > 100:
            raise RuntimeError(f"no truth within 100 ms of {t}")
        t_ecef.append(tx[j])
    return np.asarray(fixes), np.asarray(t_ecef)


def _wls_clock_per_constellation(sv, pr, w, systems):
    """Plain Gauss-Newton WLS, one clock per constellation, Sagnac rotation by
    omega_E * (pr - clock)/c as gnss_lib_py's wls. Returns [x, y, z, clocks...]."""
    names = sorted(set(systems))
    k = np.array([names.index(s) for s in systems])
    x = np.zeros(3 + len(names))
    for _ in range(30):
        th = 7.2921151467e-5 * (pr - x[3 + k]) / C
        rot = np.c_[np.cos(th) * sv[:, 0] + np.sin(th) * sv[:, 1],
                    -np.sin(th) * sv[:, 0] + np.cos(th) * sv[:, 1], sv[:, 2]]
        d = rot - x[:3]
        r = np.linalg.norm(d, axis=1)
        h = np.zeros((len(pr), 3 + len(names)))
        h[:, :3] = -d / r[:, None]
        h[np.arange(len(pr)), 3 + k] = 1.0
        sw = np.sqrt(w)
        dx = np.linalg.lstsq(h * sw[:, None], (pr - r - x[3 + k]) * sw, rcond=None)[0]
        x += dx
        if np.linalg.norm(dx) < 1e-6:
            break
    return x


def gsdc_clock_per_constellation(derived, truth):
    """L1/E1/G1, W = 1/sigma^2, 10 deg mask from the previous fix, one clock per
    constellation (navguard's model); gnss_lib_py only loads the data."""
    from gnss_lib_py.navdata.operations import loop_time
    sub = derived.where("signal_type", ["l1", "e1", "g1", "GPS_L1_CA", "GAL_E1_C_P",
                                        "GLO_G1_CA"], "eq")
    tt = truth["gps_millis"]
    tx = truth[["x_rx_gt_m", "y_rx_gt_m", "z_rx_gt_m"]].T
    fixes, t_ecef = [], []
    for t, _, m in loop_time(sub, "gps_millis", delta_t_decimals=-2):
        sv = m[["x_sv_m", "y_sv_m", "z_sv_m"]].T
        pr, sig = m["corr_pr_m"], m["raw_pr_sigma_m"]
        sysid = np.array(m["gnss_id"])
        ok = np.isfinite(sv).all(axis=1) & np.isfinite(pr) & (sig > 0)
        sv, pr, sig, sysid = sv[ok], pr[ok], sig[ok], sysid[ok]
        x = _wls_clock_per_constellation(sv, pr, 1 / sig ** 2, list(sysid))
        for _ in range(2):
            k = _elevations_deg(x[:3], sv) >= MASK_DEG
            x = _wls_clock_per_constellation(sv[k], pr[k], 1 / sig[k] ** 2, list(sysid[k]))
        fixes.append(x[:3])
        t_ecef.append(tx[int(np.argmin(np.abs(tt - t)))])
    return np.array(fixes), np.array(t_ecef)


def run_gsdc2021(mode):
    from gnss_lib_py.parsers.google_decimeter import (AndroidDerived2021,
                                                      AndroidGroundTruth2021)
    d = AndroidDerived2021(DATA / "gsdc" / "gsdc2021_Pixel4_derived.csv")
    g = AndroidGroundTruth2021(DATA / "gsdc" / "gsdc2021_Pixel4_ground_truth.csv")
    if mode == "clocks":
        return gsdc_clock_per_constellation(d, g)
    return gsdc_glp(d, g, mode == "navguard_like")


def run_gsdc2023(mode):
    from gnss_lib_py.parsers.google_decimeter import (AndroidDerived2023,
                                                      AndroidGroundTruth2023)
    d = AndroidDerived2023(DATA / "gsdc" / "gsdc2023_pixel7pro_device_gnss.csv")
    g = AndroidGroundTruth2023(DATA / "gsdc" / "gsdc2023_pixel7pro_ground_truth.csv")
    if mode == "clocks":
        return gsdc_clock_per_constellation(d, g)
    return gsdc_glp(d, g, mode == "navguard_like")


# ---------------------------------------------------------------- gnss_lib_py, broadcast SPP

GNSSLOGGER_TRUTH_LLA = (37.422578, -122.081678, -28.0)  # ProcessGnssMeasScript.m


def _glp_epoch_fix(t_ms, t_tx_ms, pr, eph, iono, weights, single_freq=True):
    """One epoch with gnss_lib_py's orbit, clock, iono/tropo models and wls.

    t_ms: receive time (GPS ms, for the models); t_tx_ms: transmission time per
    satellite (GPS ms, before the satellite clock correction); pr: pseudoranges (m).
    """
    from gnss_lib_py.algorithms.snapshot import wls
    from gnss_lib_py.navdata.navdata import NavData
    from gnss_lib_py.utils.gnss_models import calculate_pseudorange_corr
    from gnss_lib_py.utils.sv_models import find_sv_states
    sv = find_sv_states(t_tx_ms, eph)
    sv = find_sv_states(t_tx_ms - sv["b_sv_m"] / C * 1000.0, eph)  # with dt_sv
    b_sv = sv["b_sv_m"] + (0.0 if single_freq else C * eph["TGD"])
    pos = sv[["x_sv_m", "y_sv_m", "z_sv_m"]].T
    corr0 = (pr + b_sv).reshape(-1, 1)
    w = None if weights is None else np.asarray(weights).reshape(-1, 1)
    x = wls(np.zeros((4, 1)), pos.copy(), corr0, w)
    for _ in range(3):  # corrections and mask at the previous fix
        state = NavData()
        for r, v in zip(["x_rx_m", "y_rx_m", "z_rx_m", "vx_rx_mps", "vy_rx_mps",
                         "vz_rx_mps", "b_rx_m", "b_dot_rx_mps"],
                        [x[0, 0], x[1, 0], x[2, 0], 0, 0, 0, x[3, 0], 0]):
            state[r] = np.array([v])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tropo, ion = calculate_pseudorange_corr(
                t_ms, state=state, sv_posvel=sv,
                iono_params=iono if single_freq else None)
        corr = corr0 - (tropo + ion).reshape(-1, 1)
        keep = _elevations_deg(x[:3, 0], pos) >= MASK_DEG
        if keep.sum() < 4:
            return None
        x = wls(x, pos[keep].copy(), corr[keep], None if w is None else w[keep])
    return x[:3, 0]


def _nearest_healthy(nav, svs, t_s):
    toe_abs = nav["gps_week"] * 604800.0 + nav["t_oe"]
    healthy = nav["health"] == 0
    cols = []
    for s in svs:
        cand = np.where((nav["sv_id"] == int(s)) & healthy)[0]
        cols.append(cand[np.argmin(np.abs(toe_abs[cand] - t_s))])
    return nav.copy(cols=cols)


def run_geonet_glp(iono_free):
    import georinex.obs2
    from gnss_lib_py.parsers.rinex_nav import RinexNav

    # gnss_lib_py's RinexObs cannot load this RINEX 2.10 file (see the docstring)
    obs = georinex.obs2.rinexsystem2(DATA / "rtklib" / "07590920.05o", "G")
    nav = RinexNav(DATA / "rtklib" / "07590920.05n")
    iono = list(nav.iono_params.values())[0]  # {"gps": 2x4 alpha/beta}
    fixes = []
    for it, t in enumerate(obs.time.values):
        t_ms = (t - GPS_EPOCH) / np.timedelta64(1, "ms")  # tags are GPS time
        c1 = obs["C1"].values[it]
        p2 = obs["P2"].values[it]
        ok = np.isfinite(c1) & (np.isfinite(p2) if iono_free else True)
        svs = [int(s[1:]) for s in obs.sv.values[ok]]
        if iono_free:
            pr = (F1 ** 2 * c1[ok] - F2 ** 2 * p2[ok]) / (F1 ** 2 - F2 ** 2)
        else:
            pr = c1[ok]
        eph = _nearest_healthy(nav, svs, t_ms / 1000.0)
        # transmission time from the pseudorange: exact whatever the receiver clock
        # (this receiver's epoch tags carry offsets of a few ms)
        x = _glp_epoch_fix(t_ms, t_ms - pr / C * 1000.0, pr, eph, iono, None,
                           single_freq=not iono_free)
        if x is not None:
            fixes.append(x)
    fixes = np.array(fixes)
    return fixes, np.broadcast_to(GEONET_TRUTH, fixes.shape)


def run_gnsslogger_glp(weighted):
    from gnss_lib_py.navdata.operations import loop_time
    from gnss_lib_py.parsers.android import AndroidRawGnss
    from gnss_lib_py.parsers.rinex_nav import RinexNav
    from gnss_lib_py.utils.coordinates import geodetic_to_ecef

    class Raw2016(AndroidRawGnss):
        """AndroidRawGnss for a GnssLogger 1.4 log: that version's header has
        ' Svid' (leading blank), no utcTimeMillis and no CodeType."""

        def preprocess(self, input_path):
            df = super().preprocess(input_path)
            df.columns = [c.strip() for c in df.columns]
            # receiver GPS time from each record's own FullBiasNanos, as UTC (-17 s)
            gps_ns = df["TimeNanos"] - df["FullBiasNanos"] - df["BiasNanos"]
            df["utcTimeMillis"] = gps_ns / 1e6 + 315964800000.0 - 17000.0
            df["CodeType"] = "C"
            return df

    # gnss_lib_py's default filters less: the carrier-phase (ADR) ones (this log has no
    # carrier phase), BiasUncertaintyNanos < 40 (1301 of 1379 records of this
    # duty-cycled log fail it; the WLS estimates the clock anyway) and the 500 ns
    # time-uncertainty cut (the weights handle it). As Google's ProcessGnssMeas: keep
    # FullBiasNanos < 0 (set), TOW decoded, GPS.
    filters = {"bias_valid": True, "arrival_time": True,
               "unknown_constellations": True, "time_valid": True,
               "state_decoded": True}
    raw = Raw2016(DATA / "gnsslogger" / "pseudoranges_log_2016_06_30_21_26_07.txt",
                  measurement_filters=filters)
    raw = raw.where("gnss_id", "gps", "eq")
    nav = RinexNav(DATA / "gnsslogger" / "hour1820.16n")
    iono = list(nav.iono_params.values())[0]
    fixes = []
    for t_ms, _, m in loop_time(raw, "gps_millis", delta_t_decimals=-2):
        pr_first = m["raw_pr_m"]  # PR with the first record's FullBiasNanos (library)
        t_s = t_ms / 1000.0
        week = math.floor(t_s / 604800.0)
        # transmission time from the satellite's own time tag (exact; the README's
        # advice for this duty-cycled log), then the library's PR for the fix
        tow_tx = m["ReceivedSvTimeNanos"] * 1e-9
        t_tx_ms = (week * 604800.0 + tow_tx) * 1000.0
        eph = _nearest_healthy(nav, m["sv_id"], t_s)
        if len(pr_first) < 4:
            continue
        w = 1.0 / m["raw_pr_sigma_m"] ** 2 if weighted else None
        x = _glp_epoch_fix(t_ms, t_tx_ms, pr_first, eph, iono, w)
        if x is not None:
            fixes.append(x)
    truth = geodetic_to_ecef(np.array([GNSSLOGGER_TRUTH_LLA]))[0]
    fixes = np.array(fixes)
    return fixes, np.broadcast_to(truth, fixes.shape)


# ---------------------------------------------------------------- RTKLIB via pyrtklib

def run_geonet_rtklib(iono_free):
    import pyrtklib as prl
    popt = prl.prcopt_default
    sopt = prl.solopt_default
    fopt = prl.filopt_t()
    popt.mode = prl.PMODE_SINGLE
    popt.navsys = prl.SYS_GPS
    popt.elmin = MASK_DEG * prl.D2R
    popt.tropopt = prl.TROPOPT_SAAS
    popt.sateph = prl.EPHOPT_BRDC
    popt.ionoopt = prl.IONOOPT_IFLC if iono_free else prl.IONOOPT_BRDC
    popt.nf = 2 if iono_free else 1
    sopt.posf = prl.SOLF_XYZ
    out = Path(tempfile.mkdtemp()) / "geonet.pos"
    files = [str(DATA / "rtklib" / "07590920.05o"), str(DATA / "rtklib" / "07590920.05n")]
    ret = prl.postpos(prl.gtime_t(), prl.gtime_t(), 0.0, 0.0, popt, sopt, fopt, files,
                      len(files), prl.Arr1Dchar(str(out)), "", "")
    if ret != 0:
        raise RuntimeError(f"postpos returned {ret}")
    fixes = []
    for line in out.read_text().splitlines():
        if line.startswith("%") or not line.strip():
            continue
        f = line.split()
        if f[5] == "5":  # Q = single
            fixes.append([float(f[2]), float(f[3]), float(f[4])])
    fixes = np.array(fixes)
    return fixes, np.broadcast_to(GEONET_TRUTH, fixes.shape)


# ---------------------------------------------------------------- table

RUNS = [
    ("gsdc2021", "gnss_lib_py WLS, default (all signals L1+L5, unweighted, no mask)",
     lambda: run_gsdc2021("default")),
    ("gsdc2021", "gnss_lib_py WLS, L1/E1/G1, W=1/sigma^2, mask 10",
     lambda: run_gsdc2021("navguard_like")),
    ("gsdc2021", "numpy WLS (not a tool), as above but one clock per constellation",
     lambda: run_gsdc2021("clocks")),
    ("gsdc2023", "gnss_lib_py WLS, default (all signals L1+L5, unweighted, no mask)",
     lambda: run_gsdc2023("default")),
    ("gsdc2023", "gnss_lib_py WLS, L1/E1/G1, W=1/sigma^2, mask 10",
     lambda: run_gsdc2023("navguard_like")),
    ("gsdc2023", "numpy WLS (not a tool), as above but one clock per constellation",
     lambda: run_gsdc2023("clocks")),
    ("geonet", "gnss_lib_py, C1 + Klobuchar + its tropo, unweighted, mask 10",
     lambda: run_geonet_glp(False)),
    ("geonet", "gnss_lib_py, iono-free C1/P2 + its tropo, unweighted, mask 10",
     lambda: run_geonet_glp(True)),
    ("geonet", "RTKLIB 2.4.3 SPP, C1 + Klobuchar, Saastamoinen, mask 10",
     lambda: run_geonet_rtklib(False)),
    ("geonet", "RTKLIB 2.4.3 SPP, iono-free C1/P2, Saastamoinen, mask 10",
     lambda: run_geonet_rtklib(True)),
    ("gnsslogger", "gnss_lib_py, L1 C/A + Klobuchar + its tropo, unweighted, mask 10",
     lambda: run_gnsslogger_glp(False)),
    ("gnsslogger", "gnss_lib_py, L1 C/A + Klobuchar + its tropo, W=1/sigma^2, mask 10",
     lambda: run_gnsslogger_glp(True)),
]


def main():
    rows = []
    for name, label, fn in RUNS:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est, truth = fn()
            rows.append((name, label, stats(horizontal_errors(est, truth))))
        except Exception as exc:  # report and go on with the other tools
            rows.append((name, label, f"FAILED: {type(exc).__name__}: {exc}"))
    for name, n, mean, p95, mx, how in NAVGUARD:
        rows.append((name, f"navguard experiment raim, {how}", (n, mean, p95, mx)))
    rows.sort(key=lambda r: r[0])
    print(f"{'data':<10} {'epochs':>6} {'mean':>7} {'95 %':>7} {'max':>7}  tool / settings")
    for name, label, s in rows:
        if isinstance(s, str):
            print(f"{name:<10} {'':>6} {'':>7} {'':>7} {'':>7}  {label}: {s}")
        else:
            n, mean, p95, mx = s
            print(f"{name:<10} {n:>6d} {mean:>7.2f} {p95:>7.2f} {mx:>7.2f}  {label}")
    print("horizontal error, metres, east/north at the truth; 95 % = nearest rank")
    return 0


if __name__ == "__main__":
    sys.exit(main())
