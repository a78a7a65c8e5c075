//! ARAIM fault-mode determination (the ADD's "determine subsets"; Blanch et al. 2015 §III.B):
//! which combinations of satellite and constellation faults the solution separation must
//! monitor, their prior probabilities, and the probability `P_not_monitored` of those it
//! does not. Used by [`super::AraimModel::fit`]; pure combinatorics on bitmasks.

use crate::epoch::Constellation;

/// One independent fault event of the threat model: a satellite fault (`P_sat`) or a
/// constellation-wide fault (`P_const`), with the satellites it corrupts.
#[derive(Debug, Clone, Copy)]
pub(super) struct FaultEvent {
    /// Prior probability of the event.
    pub(super) p: f64,
    /// Bit `i` set when satellite `i` is corrupted by the event.
    pub(super) mask: u64,
}

/// A monitored fault mode: the satellites its fault-tolerant subset leaves out.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultMode {
    /// Bit `i` set when satellite `i` (input order) is excluded from the subset.
    pub excluded_mask: u64,
    /// `p_fault,k`: the prior probability of the event combinations whose subset this is
    /// (combinations that exclude the same satellites are merged and their probabilities
    /// added, as the ADD does for a constellation fault and a satellite of it).
    pub p_fault: f64,
}

/// The fault modes to monitor and what is left unmonitored.
#[derive(Debug, Clone)]
pub(super) struct ModeSet {
    /// Monitored modes, most probable first.
    pub(super) modes: Vec<FaultMode>,
    /// Prior probability of the fault combinations not monitored (too many simultaneous
    /// events, or a subset that leaves no solvable geometry).
    pub(super) p_not_monitored: f64,
    /// Largest number of simultaneous events enumerated.
    pub(super) max_order: usize,
}

/// The independent events: one per satellite and, when at least two constellations are
/// in view, one per constellation (a constellation fault with a single constellation in
/// view cannot be monitored: its probability is returned as the second value, to be
/// counted in `P_not_monitored`).
pub(super) fn events(
    constellations: &[Constellation],
    p_sat: &[f64],
    p_const: impl Fn(Constellation) -> f64,
) -> (Vec<FaultEvent>, f64) {
    let mut out: Vec<FaultEvent> = p_sat
        .iter()
        .enumerate()
        .filter(|(_, p)| **p > 0.0)
        .map(|(i, &p)| FaultEvent { p, mask: 1 << i })
        .collect();
    let present: Vec<Constellation> = Constellation::ALL
        .into_iter()
        .filter(|c| constellations.contains(c))
        .collect();
    let mut unmonitorable = 0.0;
    for &c in &present {
        let p = p_const(c);
        if p <= 0.0 {
            continue;
        }
        if present.len() < 2 {
            unmonitorable += p;
            continue;
        }
        let mask = constellations
            .iter()
            .enumerate()
            .filter(|(_, k)| **k == c)
            .fold(0u64, |m, (i, _)| m | (1 << i));
        out.push(FaultEvent { p, mask });
    }
    (out, unmonitorable)
}

/// Enumerates fault modes by increasing number of simultaneous events, most probable
/// first within an order, until the probability of the modes not yet monitored is at
/// most `p_thres` (ADD: `P_not_monitored ≤ P_THRES`), or `max_order` events.
/// `solvable(mask)` says whether the subset without the satellites of `mask` can be
/// solved; a mode that cannot stays in `P_not_monitored`.
pub(super) fn determine(
    events: &[FaultEvent],
    p_unmonitorable: f64,
    p_thres: f64,
    max_order: usize,
    solvable: impl Fn(u64) -> bool,
) -> ModeSet {
    // Probability of no event, and of at least one: P(any) = 1 − Π(1 − p_e).
    let ln_p0: f64 = events.iter().map(|e| (-e.p).ln_1p()).sum();
    let p0 = ln_p0.exp();
    let mut p_nm = -ln_p0.exp_m1() + p_unmonitorable;
    let mut merged: Vec<FaultMode> = Vec::with_capacity(events.len());
    let mut order = 0;
    // Odds p_e / (1 − p_e): the probability of exactly the combination C is p0 Π_C odds.
    let odds: Vec<f64> = events.iter().map(|e| e.p / (1.0 - e.p)).collect();
    while p_nm > p_thres && order < max_order.min(events.len()) {
        order += 1;
        // Sized for the order's combinations (a hint, capped: a large `max_order` must
        // not reserve memory up front).
        let mut combos: Vec<(f64, u64)> =
            Vec::with_capacity(binomial(events.len(), order).min(4096));
        for_each_combination(events.len(), order, |idx| {
            let p = p0 * idx.iter().map(|&j| odds[j]).product::<f64>();
            let mask = idx.iter().fold(0u64, |m, &j| m | events[j].mask);
            combos.push((p, mask));
        });
        combos.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (p, mask) in combos {
            if p_nm <= p_thres {
                break;
            }
            if !solvable(mask) {
                continue;
            }
            p_nm -= p;
            match merged.iter_mut().find(|m| m.excluded_mask == mask) {
                Some(m) => m.p_fault += p,
                None => merged.push(FaultMode {
                    excluded_mask: mask,
                    p_fault: p,
                }),
            }
        }
    }
    merged.sort_by(|a, b| b.p_fault.total_cmp(&a.p_fault));
    ModeSet {
        modes: merged,
        p_not_monitored: p_nm.max(0.0),
        max_order: order,
    }
}

/// `n` choose `r` (the number of combinations [`for_each_combination`] visits), saturating.
fn binomial(n: usize, r: usize) -> usize {
    if r > n {
        return 0;
    }
    (0..r).fold(1usize, |c, k| c.saturating_mul(n - k) / (k + 1))
}

/// Calls `f` with every `r`-element combination of `0..n`, in lexicographic order.
fn for_each_combination(n: usize, r: usize, mut f: impl FnMut(&[usize])) {
    if r == 0 || r > n {
        return;
    }
    let mut idx: Vec<usize> = (0..r).collect();
    loop {
        f(&idx);
        // Advance the rightmost index that can still move.
        let Some(i) = (0..r).rev().find(|&i| idx[i] < n - r + i) else {
            return;
        };
        idx[i] += 1;
        for j in i + 1..r {
            idx[j] = idx[j - 1] + 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn combinations_are_counted_by_the_binomial_coefficient() {
        let mut count = 0;
        for_each_combination(7, 3, |_| count += 1);
        assert_eq!(count, 35);
    }

    #[test]
    fn the_reserved_combinations_are_the_binomial_coefficient() {
        assert_eq!(binomial(7, 3), 35);
        assert_eq!(binomial(32, 1), 32);
        assert_eq!(binomial(66, 3), 45_760);
        assert_eq!(binomial(2, 3), 0);
    }

    #[test]
    fn single_faults_suffice_when_pairs_are_below_p_thres() {
        // 10 satellites at 1e-5: P(≥ 2 events) ≈ 45e-10 < 8e-8, so order 1 is enough.
        let ev: Vec<FaultEvent> = (0..10)
            .map(|i| FaultEvent {
                p: 1e-5,
                mask: 1 << i,
            })
            .collect();
        let set = determine(&ev, 0.0, 8e-8, 3, |_| true);
        assert_eq!(set.max_order, 1);
        assert_eq!(set.modes.len(), 10);
        // What is left is P(≥ 2 of 10) = 1 − P(0) − P(1).
        let p = 1e-5_f64;
        let want = 1.0 - (1.0 - p).powi(10) - 10.0 * p * (1.0 - p).powi(9);
        assert!(
            (set.p_not_monitored - want).abs() < 1e-15,
            "{}",
            set.p_not_monitored
        );
    }
}
