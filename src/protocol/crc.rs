//! CRC-8/AUTOSAR, the checksum of both frames (AUTOSAR CRC library, "CRC8H2F").
//!
//! Parameters as in the CRC RevEng catalogue: width 8, poly 0x2F, init 0xFF, refin false,
//! refout false, xorout 0xFF, check 0xDF (the CRC of the ASCII bytes "123456789").
//! It is the polynomial AUTOSAR chose for its E2E protection over 0x1D (SAE J1850) because it
//! keeps a Hamming distance of 4 over a whole 8-byte CAN payload; the test
//! `crc_detects_every_error_of_up_to_three_bits_in_a_frame` checks that on our frames.

/// CRC-8/AUTOSAR generator polynomial, normal (MSB-first) form.
pub const POLY: u8 = 0x2F;
const INIT: u8 = 0xFF;
const XOR_OUT: u8 = 0xFF;

/// One entry per byte value: 256 bytes of flash instead of 8 shifts per byte.
const TABLE: [u8; 256] = table();

#[expect(
    clippy::arithmetic_side_effects,
    clippy::indexing_slicing,
    reason = "evaluated by the compiler only (TABLE): an overflow or a bad index fails the build"
)]
const fn table() -> [u8; 256] {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = i as u8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ POLY
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// CRC-8/AUTOSAR of a byte sequence (init and final XOR applied).
#[expect(
    clippy::indexing_slicing,
    reason = "a u8 indexes the 256-entry table: always in range"
)]
pub fn crc8_autosar<'a>(bytes: impl IntoIterator<Item = &'a u8>) -> u8 {
    let crc = bytes
        .into_iter()
        .fold(INIT, |crc, &b| TABLE[usize::from(crc ^ b)]);
    crc ^ XOR_OUT
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-by-bit reference implementation, straight from the parameter set.
    fn crc8_bitwise(bytes: &[u8]) -> u8 {
        let mut crc = INIT;
        for &b in bytes {
            crc ^= b;
            for _ in 0..8 {
                crc = if crc & 0x80 != 0 {
                    (crc << 1) ^ POLY
                } else {
                    crc << 1
                };
            }
        }
        crc ^ XOR_OUT
    }

    #[test]
    fn check_value_over_123456789_is_0xdf() {
        assert_eq!(crc8_autosar(b"123456789"), 0xDF);
        assert_eq!(crc8_bitwise(b"123456789"), 0xDF);
    }

    #[test]
    fn matches_the_autosar_crc_library_test_vectors() {
        // AUTOSAR SWS CRC Library, "8-bit 0x2F polynomial CRC calculation" examples.
        let vectors: [(&[u8], u8); 7] = [
            (&[0x00, 0x00, 0x00, 0x00], 0x12),
            (&[0xF2, 0x01, 0x83], 0xC2),
            (&[0x0F, 0xAA, 0x00, 0x55], 0xC6),
            (&[0x00, 0xFF, 0x55, 0x11], 0x77),
            (
                &[0x33, 0x22, 0x55, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE, 0xFF],
                0x11,
            ),
            (&[0x92, 0x6B, 0x55], 0x33),
            (&[0xFF, 0xFF, 0xFF, 0xFF], 0x6C),
        ];
        for (bytes, crc) in vectors {
            assert_eq!(crc8_autosar(bytes), crc, "{bytes:02X?}");
        }
    }

    #[test]
    fn table_agrees_with_the_bitwise_definition() {
        let mut bytes = [0u8; 9];
        for seed in 0..2000u32 {
            for (i, b) in bytes.iter_mut().enumerate() {
                *b = (seed.wrapping_mul(2_654_435_761).rotate_left(i as u32 * 5) >> 3) as u8;
            }
            let n = (seed % 10) as usize;
            assert_eq!(crc8_autosar(&bytes[..n]), crc8_bitwise(&bytes[..n]));
        }
    }
}
