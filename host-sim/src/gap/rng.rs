//! The selftests' random numbers: det-rng's SplitMix64, seeded as the selftest's worlds always
//! were, so a seed gives the same cases on every machine and every stored figure stands.

pub use det_rng::SplitMix64 as Rng;

/// The generator of `seed` (its first draw mixes `seed ^ 2^64/phi + 2^64/phi`).
pub fn seeded(seed: u64) -> Rng {
    Rng::from_state(seed ^ 0x9e37_79b9_7f4a_7c15)
}
