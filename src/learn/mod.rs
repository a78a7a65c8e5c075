//! Learning: kernels, LS-SVM (batch, locally weighted, online), SVM and
//! one-class SVM by SMO, cross-validation. Used by the channel, rimu and tacan
//! monitors and by model training. Filled in with the LS-SVM and SVM monitors.
