//! The stack's high-water mark: how deep the firmware's stack has ever been since boot.
//!
//! flip-link puts the stack at the bottom of RAM, under the statics, so an overflow faults
//! instead of overwriting them; this says how close it came. At boot the firmware paints the
//! free stack (from the RAM start up to just below the stack pointer) with [`PAINT`]; the stack
//! grows down from its top, so the words the deepest call ever reached are the lowest ones
//! that no longer hold the paint. The painting and the reads of the region are chip code
//! (`src/firmware/stack.rs`); the measuring here is plain code over a word reader, tested on a
//! host buffer.

/// The word the free stack is painted with: not zero and not a RAM address, so neither a zeroed
/// local nor a saved pointer is taken for paint.
pub const PAINT: u32 = 0xC5AC_CE55;

/// How much of a stack region has been used, bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StackUsage {
    /// The deepest the stack has been: the region's size less the painted words at its bottom.
    pub peak_bytes: u32,
    /// The whole region, from its bottom (the RAM start) to its top (the statics).
    pub size_bytes: u32,
}

impl StackUsage {
    /// The usage of a region of `words` 4-byte words, index 0 its lowest address (where the
    /// stack ends) and `words - 1` its highest (where it starts), read through `read`: the
    /// painted words are counted from index 0 up to the first that is not [`PAINT`]. A
    /// region never painted, or used to its bottom, reads as used in full.
    pub fn measure(words: usize, read: impl Fn(usize) -> u32) -> StackUsage {
        let painted = (0..words).take_while(|&i| read(i) == PAINT).count();
        let bytes = |n: usize| u32::try_from(n.saturating_mul(4)).unwrap_or(u32::MAX);
        StackUsage {
            peak_bytes: bytes(words.saturating_sub(painted)),
            size_bytes: bytes(words),
        }
    }

    /// `peak_bytes` and `size_bytes` in 4-byte words, saturated to u16 (the diagnostic frame's
    /// counter words: 256 KiB, twice the F446's RAM).
    pub fn words_u16(&self) -> [u16; 2] {
        [self.peak_bytes / 4, self.size_bytes / 4].map(|w| u16::try_from(w).unwrap_or(u16::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A painted region that a stack has then used from its top down to `depth` words, with
    /// some of the used words left holding the paint's value by chance (a local equal to it
    /// above the deepest point does not hide the depth below it).
    fn used(words: usize, depth: usize) -> Vec<u32> {
        let mut region = vec![PAINT; words];
        for (i, w) in region.iter_mut().enumerate().skip(words - depth) {
            *w = if i % 7 == 0 { PAINT } else { i as u32 };
        }
        region
    }

    #[test]
    fn the_peak_is_the_lowest_word_that_lost_its_paint() {
        for depth in [1, 2, 100, 999, 1000] {
            let region = used(1000, depth);
            // The lowest used word may hold the paint by chance; the deepest one that does not
            // is found, and the usage is never more than was used.
            let usage = StackUsage::measure(region.len(), |i| region[i]);
            assert_eq!(usage.size_bytes, 4000);
            let lowest_unpainted = region.iter().position(|w| *w != PAINT).unwrap();
            assert_eq!(usage.peak_bytes as usize, 4 * (1000 - lowest_unpainted));
            assert!(usage.peak_bytes as usize <= 4 * depth);
            assert!(usage.peak_bytes as usize >= 4 * (depth - 1));
        }
    }

    #[test]
    fn an_untouched_painted_region_is_unused_and_an_unpainted_one_full() {
        let painted = vec![PAINT; 64];
        assert_eq!(
            StackUsage::measure(64, |i| painted[i]),
            StackUsage {
                peak_bytes: 0,
                size_bytes: 256
            }
        );
        let zeroed = vec![0u32; 64];
        assert_eq!(StackUsage::measure(64, |i| zeroed[i]).peak_bytes, 256);
        assert_eq!(StackUsage::measure(0, |_| PAINT).size_bytes, 0);
    }

    #[test]
    fn the_frame_words_are_the_usage_in_words_saturated() {
        let u = StackUsage {
            peak_bytes: 4 * 1234,
            size_bytes: 126_576,
        };
        assert_eq!(u.words_u16(), [1234, 31_644]);
        let big = StackUsage {
            peak_bytes: 4 * 70_000,
            size_bytes: u32::MAX,
        };
        assert_eq!(big.words_u16(), [u16::MAX, u16::MAX]);
    }
}
