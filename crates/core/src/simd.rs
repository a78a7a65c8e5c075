//! One switch for the AVX2 builds of the hot numerical kernels: the federated filter's
//! (`filter/federated/solver.rs`), the SVM's kernel rows (`learn/svm/rows.rs`) and the
//! online LS-SVM's slide (`learn/online.rs`). Each compiles its body a second time with
//! `#[target_feature(enable = "avx2")]` and calls that build when [`avx2`] says so. A leaf:
//! it uses no other module.

/// True when the kernels may run their AVX2 builds: the CPU has AVX2 and
/// `NAVGUARD_NO_AVX2` is not set (the switch lets the baseline build be measured on the same
/// machine). The AVX2 builds perform the same IEEE operations in the same order (no FMA is
/// enabled and Rust never contracts or reassociates floating point), four lanes at a time
/// instead of two, so their results are the baseline's to the bit (tested for each kernel);
/// only the instruction count changes. Checked once per process.
#[cfg(target_arch = "x86_64")]
pub fn avx2() -> bool {
    static AVX2: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVX2.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx2")
            && std::env::var_os("NAVGUARD_NO_AVX2").is_none()
    })
}
