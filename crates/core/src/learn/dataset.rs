//! A validated training or prediction set: `n` samples of dimension `d` (rows of
//! `x`), and for supervised models `n` targets or labels. Built once at the edge
//! so every algorithm can assume finite, rectangular, non-empty data.

use nalgebra::{DMatrix, DVector};

use super::LearnError;

/// `n × d` inputs (one sample per row) and optional targets.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    x: DMatrix<f64>,
    y: Option<DVector<f64>>,
}

impl Dataset {
    /// Validates and packs `x` (one sample per inner vector) and `y`.
    ///
    /// Errors name the offending element: empty set, ragged rows, non-finite
    /// values, `x`/`y` length mismatch.
    pub fn new(x: &[Vec<f64>], y: Option<&[f64]>) -> Result<Self, LearnError> {
        let n = x.len();
        if n == 0 {
            return Err(LearnError::data("x", "needs at least one sample"));
        }
        let d = x[0].len();
        if d == 0 {
            return Err(LearnError::data(
                "x[0]",
                "a sample needs at least one feature",
            ));
        }
        for (i, row) in x.iter().enumerate() {
            if row.len() != d {
                return Err(LearnError::data(
                    format!("x[{i}]"),
                    format!("has {} features, x[0] has {d}", row.len()),
                ));
            }
            if let Some(j) = row.iter().position(|v| !v.is_finite()) {
                return Err(LearnError::data(format!("x[{i}][{j}]"), "must be finite"));
            }
        }
        let y = match y {
            None => None,
            Some(y) => {
                if y.len() != n {
                    return Err(LearnError::data(
                        "y",
                        format!("has {} values, x has {n} samples", y.len()),
                    ));
                }
                if let Some(i) = y.iter().position(|v| !v.is_finite()) {
                    return Err(LearnError::data(format!("y[{i}]"), "must be finite"));
                }
                Some(DVector::from_column_slice(y))
            }
        };
        let x = DMatrix::from_fn(n, d, |i, j| x[i][j]);
        Ok(Dataset { x, y })
    }

    /// Packs an already-valid matrix (rows are samples). The caller guarantees
    /// finite values and `y.len() == x.nrows()`; used by internal callers such as CV.
    pub fn from_parts(x: DMatrix<f64>, y: Option<DVector<f64>>) -> Self {
        debug_assert!(y.as_ref().is_none_or(|y| y.len() == x.nrows()));
        Dataset { x, y }
    }

    /// Number of samples.
    pub fn n(&self) -> usize {
        self.x.nrows()
    }

    /// Input dimension.
    pub fn dim(&self) -> usize {
        self.x.ncols()
    }

    /// The inputs, one sample per row.
    pub fn x(&self) -> &DMatrix<f64> {
        &self.x
    }

    /// The targets, when the set has them.
    pub fn y(&self) -> Option<&DVector<f64>> {
        self.y.as_ref()
    }

    /// The targets, or an `InvalidData` error on `y` for supervised models.
    pub fn require_y(&self) -> Result<&DVector<f64>, LearnError> {
        self.y
            .as_ref()
            .ok_or_else(|| LearnError::data("y", "this model kind needs targets `y`"))
    }

    /// Sample `i` as a vector.
    pub fn row(&self, i: usize) -> Vec<f64> {
        self.x.row(i).iter().copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ragged_rows_name_the_row() {
        let e = Dataset::new(&[vec![1.0, 2.0], vec![1.0]], None).unwrap_err();
        assert_eq!(e, LearnError::data("x[1]", "has 1 features, x[0] has 2"));
    }

    #[test]
    fn non_finite_values_name_the_element() {
        let e = Dataset::new(&[vec![1.0, f64::NAN]], None).unwrap_err();
        assert_eq!(e, LearnError::data("x[0][1]", "must be finite"));
        let e = Dataset::new(&[vec![1.0]], Some(&[f64::INFINITY])).unwrap_err();
        assert_eq!(e, LearnError::data("y[0]", "must be finite"));
    }

    #[test]
    fn length_mismatch_and_empty_sets_are_refused() {
        assert!(Dataset::new(&[], None).is_err());
        assert!(Dataset::new(&[vec![1.0]], Some(&[1.0, 2.0])).is_err());
        let d = Dataset::new(&[vec![1.0, 2.0], vec![3.0, 4.0]], Some(&[1.0, -1.0])).unwrap();
        assert_eq!((d.n(), d.dim()), (2, 2));
        assert_eq!(d.x()[(1, 0)], 3.0);
        assert_eq!(d.row(1), vec![3.0, 4.0]);
    }
}
