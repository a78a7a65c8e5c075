//! Exact `f64` storage for the LS-SVM family's stored models (the model store's JSON):
//! `serde_json` without its `float_roundtrip` feature may parse a printed `f64` one ULP
//! off, which would make a reloaded model predict differently in the last bits. The
//! coefficients are therefore stored as shortest round-trip decimal strings and parsed
//! with Rust's correctly rounded `str::parse`.

use serde::{Deserialize, Deserializer, Serialize, Serializer, de::Error};

use super::Standardizer;

fn parse(s: &str) -> Result<f64, String> {
    s.parse::<f64>()
        .map_err(|e| format!("not a number \"{s}\": {e}"))
}

/// `#[serde(with = "exact::vec")]` for `Vec<f64>`.
pub mod vec {
    use super::*;

    /// Writes each value as its shortest round-trip decimal string.
    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| format!("{x:?}")))
    }

    /// Reads the strings back exactly.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let raw = Vec::<String>::deserialize(d)?;
        raw.iter()
            .map(|s| parse(s).map_err(D::Error::custom))
            .collect()
    }
}

/// `#[serde(with = "exact::one")]` for `f64`.
pub mod one {
    use super::*;

    /// Writes the value as its shortest round-trip decimal string.
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&format!("{v:?}"))
    }

    /// Reads the string back exactly.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        parse(&String::deserialize(d)?).map_err(D::Error::custom)
    }
}

/// A [`Standardizer`] stored exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExactScale {
    /// Column means.
    #[serde(with = "vec")]
    pub mean: Vec<f64>,
    /// Column standard deviations.
    #[serde(with = "vec")]
    pub std: Vec<f64>,
}

impl From<&Standardizer> for ExactScale {
    fn from(s: &Standardizer) -> Self {
        ExactScale {
            mean: s.mean.clone(),
            std: s.std.clone(),
        }
    }
}

impl ExactScale {
    /// Standardises `v` (column `j`).
    #[inline]
    pub fn apply_one(&self, j: usize, v: f64) -> f64 {
        (v - self.mean[j]) / self.std[j]
    }

    /// Maps a standardised value of column `j` back.
    #[inline]
    pub fn invert(&self, j: usize, v: f64) -> f64 {
        v * self.std[j] + self.mean[j]
    }

    /// Standardises `x` in place.
    pub fn apply(&self, x: &mut [f64]) {
        for (j, v) in x.iter_mut().enumerate() {
            *v = self.apply_one(j, *v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn awkward_values_survive_a_json_round_trip_bit_for_bit() {
        #[derive(Serialize, Deserialize)]
        struct T(#[serde(with = "vec")] Vec<f64>);
        let v = vec![
            -0.9091490001743844,
            0.1,
            1e-300,
            -2.5e17,
            f64::MIN_POSITIVE,
            0.0,
        ];
        let back: T = serde_json::from_str(&serde_json::to_string(&T(v.clone())).unwrap()).unwrap();
        for (a, b) in back.0.iter().zip(&v) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
}
