//! Experiments: the papers' experiments end to end, their scorecards and plots.
