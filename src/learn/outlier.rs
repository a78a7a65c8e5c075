//! Outlier pre-filter (seed 001 §2.2.1, DESIGN §3.5): third difference against
//! `c·√20·s`, replacement by cubic Newton extrapolation.
//! (Stub: filled in by the LS-SVM work.)

/// The filter's state: the last accepted values.
#[derive(Debug, Clone)]
pub struct OutlierFilter {
    c: f64,
    replaced: u64,
}

impl OutlierFilter {
    /// A filter with threshold factor `c` (default 3).
    pub fn new(c: f64) -> Self {
        OutlierFilter { c, replaced: 0 }
    }

    /// The threshold factor.
    pub fn c(&self) -> f64 {
        self.c
    }

    /// Filters one value: returns the value to use and whether it was replaced.
    pub fn filter(&mut self, value: f64) -> (f64, bool) {
        (value, false)
    }

    /// Values replaced so far.
    pub fn replaced(&self) -> u64 {
        self.replaced
    }
}
