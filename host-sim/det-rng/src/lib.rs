//! Seeded pseudo-random numbers that come out the same on every target (host and Cortex-M4F):
//! the simulated CAN bus's random faults, the golden vectors' arbitrary inputs, the property
//! tests' inputs and the gap selftest's worlds. Reproducible on purpose, so never for anything
//! that must be unpredictable.
//!
//! Two generators, because stored results depend on each one's exact sequence:
//! - [`XorShift64Star`] (Vigna 2016): the bus, the golden vectors and the firmware's property
//!   tests. Its state must not be 0 (xorshift never leaves 0); [`XorShift64Star::seeded`]
//!   spreads a small seed with SplitMix64's finaliser first, [`XorShift64Star::from_state`]
//!   takes the state as given.
//! - [`SplitMix64`] (Steele, Lea, Flood 2014): the selftest's worlds.
#![cfg_attr(not(feature = "std"), no_std)]

/// SplitMix64's increment (2^64 / golden ratio).
const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function: a bijection that spreads neighbouring inputs apart.
const fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The top 53 bits of `bits` as a uniform value in [0, 1).
fn unit_from(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// xorshift64*: one xorshift triple (12, 25, 27) on 64 bits of state, output multiplied by
/// 2685821657736338717.
#[derive(Debug, Clone)]
pub struct XorShift64Star(u64);

impl XorShift64Star {
    /// The generator at `state` as given (0, which xorshift never leaves, becomes 1).
    pub const fn from_state(state: u64) -> Self {
        XorShift64Star(if state == 0 { 1 } else { state })
    }

    /// The generator for `seed`: the state is SplitMix64's finaliser of `seed + GAMMA`, so
    /// neighbouring seeds give unrelated streams.
    pub const fn seeded(seed: u64) -> Self {
        Self::from_state(mix(seed.wrapping_add(GAMMA)))
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        unit_from(self.next_u64())
    }

    /// In `0..n` (`n` 0 counts as 1), from the high 32 bits.
    pub fn below(&mut self, n: u32) -> u32 {
        ((self.next_u64() >> 32) % u64::from(n.max(1))) as u32
    }

    /// Any bit pattern half the time (NaN, infinities, subnormals), else uniform in +-`span`:
    /// the inputs a decoder or a control law must survive.
    pub fn any_f32(&mut self, span: f32) -> f32 {
        let bits = self.next_u64();
        if bits & 1 == 0 {
            f32::from_bits((bits >> 32) as u32)
        } else {
            ((bits >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2.0 * span
        }
    }

    /// Eight bytes of one draw, little-endian.
    pub fn bytes(&mut self) -> [u8; 8] {
        self.next_u64().to_le_bytes()
    }
}

/// SplitMix64: a counter stepped by `GAMMA`, each value through SplitMix64's output function.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// The generator whose first draw mixes `state + GAMMA` (any state, 0 included).
    pub const fn from_state(state: u64) -> Self {
        SplitMix64(state)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GAMMA);
        mix(self.0)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        unit_from(self.next_u64())
    }

    /// Uniform in [`lo`, `hi`).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Standard normal, by Box-Muller (two draws, the cosine branch).
    #[cfg(feature = "std")]
    pub fn normal(&mut self) -> f64 {
        let u1 = self.unit().max(1e-300);
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Known answers, computed independently (a Python transcription of each algorithm with
    // 64-bit masking): these are the sequences the stored golden vectors, the bus tests and the
    // selftest were made with.

    #[test]
    fn xorshift64_star_from_state_one_gives_the_published_sequence() {
        let mut r = XorShift64Star::from_state(1);
        assert_eq!(r.next_u64(), 0x47e4_ce4b_896c_dd1d);
        assert_eq!(r.next_u64(), 0xabcf_a6a8_e079_651d);
        assert_eq!(r.next_u64(), 0xb9d1_0d8f_eb73_1f57);
    }

    #[test]
    fn seeded_spreads_the_seed_through_splitmix() {
        let mut r = XorShift64Star::seeded(7);
        assert_eq!(r.0, 0x63cb_e1e4_5932_0dd7);
        assert_eq!(r.next_u64(), 0x14ea_a7d1_f828_843a);
        assert_eq!(r.next_u64(), 0x421d_9d8f_ff2d_1844);
        assert_eq!(r.next_u64(), 0x5aa5_48bb_d8c6_01d5);
    }

    #[test]
    fn state_zero_is_moved_off_the_fixed_point() {
        let mut r = XorShift64Star::from_state(0);
        assert_ne!(r.next_u64(), 0);
        assert_ne!(r.next_u64(), 0);
    }

    #[test]
    fn splitmix64_gives_its_sequence() {
        let mut r = SplitMix64::from_state(1 ^ GAMMA);
        assert_eq!(r.next_u64(), 0xe99f_f867_dbf6_82c9);
        assert_eq!(r.next_u64(), 0x382f_f84c_b272_81e9);
        assert_eq!(r.next_u64(), 0x6d1d_b36c_cba9_82d2);
    }

    #[test]
    fn derived_draws_stay_in_their_ranges() {
        let mut x = XorShift64Star::seeded(3);
        let mut s = SplitMix64::from_state(3);
        let (mut nan, mut within) = (0, 0);
        for _ in 0..10_000 {
            assert!((0.0..1.0).contains(&x.unit()));
            assert!(x.below(7) < 7);
            assert_eq!(x.below(0), 0);
            let f = x.any_f32(5.0);
            nan += usize::from(f.is_nan());
            within += usize::from(f.abs() <= 5.0);
            assert!((2.0..3.0).contains(&s.range(2.0, 3.0)));
        }
        // Half the draws are uniform in +-5, and a raw bit pattern is NaN about once in 256.
        assert!(within > 4_500, "{within} of 10 000 within the span");
        assert!(nan > 0, "no NaN among 10 000 arbitrary f32");
    }
}
