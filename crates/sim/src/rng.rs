//! Random streams for the simulator: one independent `StdRng` per noise source,
//! all derived from the scenario seed, so that changing one source (adding a
//! fault, a dropout rate, a longer duration) never shifts the draws of another.
//! Used by `ins_truth`, `sensors` and `scenario`.
//!
//! Reproducible for a given seed and build: the seed → stream mapping
//! (SplitMix64 of `seed ⊕ stream·φ`) is fixed here; `StdRng` itself is
//! `rand` 0.9's, whose algorithm is only stable within a `rand` release.

use rand::SeedableRng;
use rand::rngs::StdRng;

/// The noise sources that get their own stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    /// INS initial-error signs, true biases and IMU white noise.
    Ins = 1,
    /// GNSS position and velocity noise.
    Gnss = 2,
    /// DVL velocity noise.
    Dvl = 3,
    /// CNS position noise.
    Cns = 4,
    /// Random dropouts of the aids.
    Dropouts = 5,
}

/// SplitMix64 finaliser (Steele, Lea, Flood 2014): decorrelates nearby seeds.
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of `stream` for scenario `seed`.
pub fn stream(seed: u64, stream: Stream) -> StdRng {
    let mixed = splitmix64(seed ^ (stream as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    StdRng::seed_from_u64(mixed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn same_seed_and_stream_repeat_and_others_differ() {
        let a: Vec<u64> = (0..4).map(|_| stream(7, Stream::Gnss).random()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        let mut g = stream(7, Stream::Gnss);
        let mut d = stream(7, Stream::Dvl);
        let mut g8 = stream(8, Stream::Gnss);
        let x: u64 = g.random();
        assert_ne!(x, d.random::<u64>());
        assert_ne!(x, g8.random::<u64>());
    }

    #[test]
    fn splitmix_matches_the_reference_first_output() {
        // Reference SplitMix64 with state 0: first output 0xE220A8397B1DCDAF.
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
    }
}
