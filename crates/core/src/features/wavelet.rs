//! Wavelet packet energies (docs/methods.md §M16, seed 002 §2.2): Daubechies db1–db4,
//! periodization boundary mode, full packet decomposition to `level`, energies of
//! the `2^level` terminal nodes in natural order (PyWavelets' `order='natural'`:
//! `aaa, aad, ada, add, daa, …`), normalised to sum 1 or absolute. Sits between a
//! gyro's raw samples and the C-SVC that isolates the faulty gyro (`monitor::rimu`);
//! `POST /api/v1/features` computes the same vectors.
//!
//! Agreement with PyWavelets 1.9 `WaveletPacket(data, w, mode='periodization',
//! maxlevel=level).get_level(level, order='natural')` is tested to 1e-9.

use std::f64::consts::FRAC_1_SQRT_2;

use serde::{Deserialize, Serialize};

use super::FeatureError;

/// The Daubechies wavelets available.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Wavelet {
    /// Haar.
    Db1,
    /// Daubechies 2.
    Db2,
    /// Daubechies 3.
    Db3,
    /// Daubechies 4.
    Db4,
}

// Decomposition low-pass filters `dec_lo`, copied from PyWavelets 1.9
// (`pywt.Wavelet('dbN').dec_lo`), which tabulates Daubechies (1992), Table 6.1,
// normalised to Σh = √2. The high-pass is the quadrature mirror
// `dec_hi[k] = (−1)^(k+1) · dec_lo[F−1−k]` (as `pywt.Wavelet('dbN').dec_hi`).
// db1 is [1/√2, 1/√2]; PyWavelets prints 0.7071067811865476, the same f64.
const DB1: [f64; 2] = [FRAC_1_SQRT_2, FRAC_1_SQRT_2];
const DB2: [f64; 4] = [
    -0.12940952255126037,
    0.2241438680420134,
    0.8365163037378079,
    0.48296291314453416,
];
const DB3: [f64; 6] = [
    0.03522629188570953,
    -0.08544127388202666,
    -0.13501102001025458,
    0.45987750211849154,
    0.8068915093110925,
    0.33267055295008263,
];
const DB4: [f64; 8] = [
    -0.010597401785069032,
    0.0328830116668852,
    0.030841381835560764,
    -0.18703481171909309,
    -0.027983769416859854,
    0.6308807679298589,
    0.7148465705529157,
    0.2303778133088965,
];

impl Wavelet {
    /// The decomposition low-pass filter `dec_lo` (PyWavelets' coefficients).
    pub fn dec_lo(self) -> &'static [f64] {
        match self {
            Wavelet::Db1 => &DB1,
            Wavelet::Db2 => &DB2,
            Wavelet::Db3 => &DB3,
            Wavelet::Db4 => &DB4,
        }
    }

    /// The decomposition high-pass filter, the quadrature mirror of [`Wavelet::dec_lo`].
    pub fn dec_hi(self) -> Vec<f64> {
        let lo = self.dec_lo();
        let f = lo.len();
        (0..f)
            .map(|k| {
                let sign = if k % 2 == 0 { -1.0 } else { 1.0 };
                sign * lo[f - 1 - k]
            })
            .collect()
    }
}

/// Parameters of the packet energies. Defaults: `db4`, level 3, normalised — seed 002
/// names neither the wavelet nor the level; db4 at level 3 (8 bands of 6.25 Hz at
/// 100 Hz) is the common choice for gyro fault features and what docs/methods.md §M16 suggests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaveletPacketParams {
    /// Wavelet (default `db4`).
    #[serde(default = "default_wavelet")]
    pub wavelet: Wavelet,
    /// Decomposition level, ≥ 1 (default 3: 8 terminal nodes).
    #[serde(default = "default_level")]
    pub level: usize,
    /// Normalise the energies to sum 1 (default true); false gives absolute energies
    /// Σ c², whose sum is ‖x‖² (Parseval, the filters being orthogonal).
    #[serde(default = "default_normalize")]
    pub normalize: bool,
}

fn default_wavelet() -> Wavelet {
    Wavelet::Db4
}

fn default_level() -> usize {
    3
}

fn default_normalize() -> bool {
    true
}

impl Default for WaveletPacketParams {
    fn default() -> Self {
        WaveletPacketParams {
            wavelet: default_wavelet(),
            level: default_level(),
            normalize: default_normalize(),
        }
    }
}

/// Deepest level accepted: 2^16 = 65,536 features is far beyond any use.
pub const MAX_LEVEL: usize = 16;

impl WaveletPacketParams {
    /// Number of features: `2^level`.
    pub fn dim(&self) -> usize {
        1usize << self.level.min(MAX_LEVEL)
    }

    /// Validates the parameters (the level; the wavelet is valid by construction).
    pub fn check(&self) -> Result<(), FeatureError> {
        if self.level == 0 || self.level > MAX_LEVEL {
            return Err(FeatureError::new(
                "level",
                format!("must be between 1 and {MAX_LEVEL}, got {}", self.level),
            ));
        }
        Ok(())
    }
}

/// One level of the periodized DWT: approximation and detail, each of length n/2
/// (`n` even). PyWavelets' periodization convolves with the filter shifted by F/2:
/// `a[k] = Σ_j h[j] · x[(2k + F/2 − j) mod n]` (checked against `pywt.dwt`).
fn dwt_periodized(x: &[f64], lo: &[f64], hi: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = x.len();
    let f = lo.len();
    let half = n / 2;
    let mut a = vec![0.0; half];
    let mut d = vec![0.0; half];
    for k in 0..half {
        let base = 2 * k + f / 2;
        let (mut sa, mut sd) = (0.0, 0.0);
        for j in 0..f {
            // (base − j) mod n without going negative: add a multiple of n ≥ f.
            let idx = (base + n * f - j) % n;
            sa += lo[j] * x[idx];
            sd += hi[j] * x[idx];
        }
        a[k] = sa;
        d[k] = sd;
    }
    (a, d)
}

/// The `2^level` terminal-node energies of `signal` in natural order.
///
/// Errors name the field: `level` (0 or too deep), `signal` (empty, non-finite, or a
/// length not divisible by `2^level`, which periodization needs at every level).
pub fn packet_energies(
    signal: &[f64],
    params: &WaveletPacketParams,
) -> Result<Vec<f64>, FeatureError> {
    params.check()?;
    if signal.is_empty() {
        return Err(FeatureError::new("signal", "must not be empty"));
    }
    let nodes = params.dim();
    if signal.len() % nodes != 0 {
        return Err(FeatureError::new(
            "signal",
            format!(
                "has {} samples, not a multiple of 2^level = {nodes}",
                signal.len()
            ),
        ));
    }
    if let Some(i) = signal.iter().position(|v| !v.is_finite()) {
        return Err(FeatureError::new(format!("signal[{i}]"), "must be finite"));
    }
    let lo = params.wavelet.dec_lo();
    let hi = params.wavelet.dec_hi();
    // Natural order: each node is replaced by its (a, d) children, left to right.
    let mut level_nodes = vec![signal.to_vec()];
    for _ in 0..params.level {
        let mut next = Vec::with_capacity(level_nodes.len() * 2);
        for node in &level_nodes {
            let (a, d) = dwt_periodized(node, lo, &hi);
            next.push(a);
            next.push(d);
        }
        level_nodes = next;
    }
    let mut energies: Vec<f64> = level_nodes
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum())
        .collect();
    if params.normalize {
        let total: f64 = energies.iter().sum();
        if total > 0.0 {
            energies.iter_mut().for_each(|e| *e /= total);
        } else {
            // An all-zero window has no spectrum; spread it evenly rather than divide by 0.
            energies.iter_mut().for_each(|e| *e = 1.0 / nodes as f64);
        }
    }
    Ok(energies)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn golden_signal(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let i = i as f64;
                (0.3 * i).sin() + 0.5 * (1.7 * i).cos() + 0.01 * i * i
            })
            .collect()
    }

    fn params(wavelet: Wavelet, level: usize, normalize: bool) -> WaveletPacketParams {
        WaveletPacketParams {
            wavelet,
            level,
            normalize,
        }
    }

    // Produced with PyWavelets 1.9.0 / NumPy:
    //   i = np.arange(N); x = np.sin(0.3*i) + 0.5*np.cos(1.7*i) + 0.01*i**2
    //   wp = pywt.WaveletPacket(data=x, wavelet=w, mode='periodization', maxlevel=3)
    //   [float(np.sum(n.data**2)) for n in wp.get_level(3, order='natural')]
    const GOLDEN_32: [(Wavelet, [f64; 8]); 4] = [
        (
            Wavelet::Db1,
            [
                667.0592249596161,
                20.270829799895356,
                9.802307708946167,
                0.5566243647519694,
                0.9854190763965759,
                0.07982086668472564,
                2.5547787089194585,
                0.12785901166011812,
            ],
        ),
        (
            Wavelet::Db2,
            [
                570.3578765979556,
                60.88199534849009,
                7.866384048439007,
                41.59816524633058,
                2.3443786627870846,
                0.4244860640842756,
                6.126785766972553,
                11.836792761811116,
            ],
        ),
        (
            Wavelet::Db3,
            [
                611.5933491513161,
                62.20265427557196,
                5.360376734528644,
                1.8752096305712387,
                1.6031064427393544,
                7.702977917850113,
                6.805324426316213,
                4.29386591797628,
            ],
        ),
        (
            Wavelet::Db4,
            [
                635.7150970418118,
                10.88236201737763,
                22.877534617932447,
                25.32717472251897,
                2.735372393010353,
                2.1557388769632397,
                1.7126568375294902,
                0.03092798972629434,
            ],
        ),
    ];

    // As above with N = 16: at level 3 the db4 filter (8 taps) wraps around 4-sample
    // nodes, the case where periodization conventions differ most.
    const GOLDEN_16_DB4: [f64; 8] = [
        16.999765832199287,
        0.8353637799893399,
        0.7630138467381254,
        0.4186920996827695,
        0.08514187581378846,
        0.044574706233168386,
        1.7109056186279914,
        0.04863055062807596,
    ];

    #[test]
    fn energies_match_pywavelets_natural_order_for_db1_to_db4() {
        let x = golden_signal(32);
        for (w, want) in GOLDEN_32 {
            let got = packet_energies(&x, &params(w, 3, false)).unwrap();
            for (g, e) in got.iter().zip(want) {
                assert!((g - e).abs() < 1e-9, "{w:?}: {got:?} vs {want:?}");
            }
            let norm = packet_energies(&x, &params(w, 3, true)).unwrap();
            let total: f64 = want.iter().sum();
            for (g, e) in norm.iter().zip(want) {
                assert!((g - e / total).abs() < 1e-12, "{w:?} normalised");
            }
        }
        let got = packet_energies(&golden_signal(16), &params(Wavelet::Db4, 3, false)).unwrap();
        for (g, e) in got.iter().zip(GOLDEN_16_DB4) {
            assert!((g - e).abs() < 1e-9, "{got:?}");
        }
    }

    #[test]
    fn absolute_energies_sum_to_the_signal_energy_for_every_wavelet_and_level() {
        // Parseval: orthogonal filters with periodization preserve ‖x‖².
        let x = golden_signal(64);
        let norm2: f64 = x.iter().map(|v| v * v).sum();
        for w in [Wavelet::Db1, Wavelet::Db2, Wavelet::Db3, Wavelet::Db4] {
            for level in 1..=5 {
                let e = packet_energies(&x, &params(w, level, false)).unwrap();
                assert_eq!(e.len(), 1 << level);
                let sum: f64 = e.iter().sum();
                assert!((sum - norm2).abs() < 1e-9 * norm2, "{w:?} L{level}");
            }
        }
    }

    #[test]
    fn haar_energies_match_hand_computed_values() {
        // x = [1, 2, 3, 4], db1 level 1: a = [(1+2)/√2, (3+4)/√2] → ‖a‖² = (9+49)/2 = 29,
        // d = [(1−2)/√2, (3−4)/√2] (PyWavelets' sign: hi = [−1, 1]/√2) → ‖d‖² = 1.
        let x = [1.0, 2.0, 3.0, 4.0];
        let e = packet_energies(&x, &params(Wavelet::Db1, 1, false)).unwrap();
        assert!(
            (e[0] - 29.0).abs() < 1e-12 && (e[1] - 1.0).abs() < 1e-12,
            "{e:?}"
        );
        // Level 2: aa = (3+7)/2 = 5 → 25; ad = (3−7)/2 = −2 → 4; da = −1 → 1; dd = 0.
        let e = packet_energies(&x, &params(Wavelet::Db1, 2, false)).unwrap();
        let want = [25.0, 4.0, 1.0, 0.0];
        for (g, w) in e.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{e:?}");
        }
        let n = packet_energies(&x, &params(Wavelet::Db1, 2, true)).unwrap();
        assert!((n[0] - 25.0 / 30.0).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_refused_naming_the_field() {
        let p = WaveletPacketParams::default();
        assert_eq!(packet_energies(&[], &p).unwrap_err().field, "signal");
        let e = packet_energies(&[1.0; 100], &p).unwrap_err();
        assert_eq!(e.field, "signal");
        assert!(e.reason.contains("multiple of 2^level = 8"), "{e}");
        let e = packet_energies(&[1.0; 8], &params(Wavelet::Db2, 0, true)).unwrap_err();
        assert_eq!(e.field, "level");
        let mut x = vec![0.0; 8];
        x[3] = f64::NAN;
        assert_eq!(packet_energies(&x, &p).unwrap_err().field, "signal[3]");
    }

    #[test]
    fn params_take_their_defaults_from_an_empty_object() {
        let p: WaveletPacketParams = serde_json::from_str("{}").unwrap();
        assert_eq!(p, WaveletPacketParams::default());
        assert_eq!((p.wavelet, p.level, p.normalize), (Wavelet::Db4, 3, true));
        let p: WaveletPacketParams = serde_json::from_str(r#"{"wavelet": "db2"}"#).unwrap();
        assert_eq!(p.wavelet, Wavelet::Db2);
        assert!(serde_json::from_str::<WaveletPacketParams>(r#"{"levels": 2}"#).is_err());
    }
}
