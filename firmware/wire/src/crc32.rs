//! CRC-32/ISO-HDLC (the Ethernet, zlib and PNG CRC): reflected polynomial 0xEDB88320, initial value and
//! final XOR 0xFFFFFFFF. Table-driven; the table is computed at compile time.
//!
//! Hand-written rather than the `crc` crate because it is faster where it counts: over a full
//! sample-block frame (671 bytes) on the M7 this slicing-by-4 takes 3 080 instructions, the crate's
//! fastest (`Table<16>`, 16 KiB of tables) 4 280 (`cargo xtask target-test wire`, figure
//! `wire.crc32_of_that_frame`). The crate is the referee in the tests below.

const POLY: u32 = 0xEDB8_8320;

/// `TABLES[0]` is the classic byte table; `TABLES[k][i]` is the CRC of byte `i` followed by `k` zero
/// bytes, so four bytes are folded in with four lookups ("slicing by 4": about half the instructions
/// per byte of the byte table on the M7, for 3 KiB more of constants).
const TABLES: [[u32; 256]; 4] = {
    let mut t = [[0u32; 256]; 4];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { POLY ^ (c >> 1) } else { c >> 1 };
            k += 1;
        }
        t[0][i] = c;
        i += 1;
    }
    let mut k = 1;
    while k < 4 {
        let mut i = 0;
        while i < 256 {
            let prev = t[k - 1][i];
            t[k][i] = (prev >> 8) ^ t[0][(prev & 0xFF) as usize];
            i += 1;
        }
        k += 1;
    }
    t
};

/// A running CRC-32, for data that arrives in pieces.
#[derive(Debug, Clone, Copy)]
pub struct Crc32(u32);

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    pub const fn new() -> Self {
        Self(0xFFFF_FFFF)
    }

    pub fn update(&mut self, data: &[u8]) {
        let [t0, t1, t2, t3] = &TABLES;
        let mut c = self.0;
        let mut words = data.chunks_exact(4);
        for w in &mut words {
            c ^= u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
            c = t3[(c & 0xFF) as usize]
                ^ t2[((c >> 8) & 0xFF) as usize]
                ^ t1[((c >> 16) & 0xFF) as usize]
                ^ t0[(c >> 24) as usize];
        }
        for &b in words.remainder() {
            c = t0[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
        }
        self.0 = c;
    }

    pub const fn finish(self) -> u32 {
        self.0 ^ 0xFFFF_FFFF
    }
}

/// CRC-32 of `data` in one call.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(data);
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_value_of_the_standard() {
        // The catalogue's check value: CRC of the ASCII digits "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn pieces_equal_whole() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 + 3) as u8).collect();
        for split in [0, 1, 17, 999, 1000] {
            let mut c = Crc32::new();
            c.update(&data[..split]);
            c.update(&data[split..]);
            assert_eq!(c.finish(), crc32(&data));
        }
    }

    proptest::proptest! {
        #[test]
        fn equals_the_crc_crate(
            data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..1100),
            split in 0usize..1100,
        ) {
            const REFEREE: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
            proptest::prop_assert_eq!(crc32(&data), REFEREE.checksum(&data));
            let split = split.min(data.len());
            let mut c = Crc32::new();
            c.update(&data[..split]);
            c.update(&data[split..]);
            proptest::prop_assert_eq!(c.finish(), REFEREE.checksum(&data));
        }
    }

    #[test]
    fn every_single_bit_flip_is_detected() {
        let data: Vec<u8> = (0..64u8).collect();
        let good = crc32(&data);
        for i in 0..data.len() * 8 {
            let mut bad = data.clone();
            bad[i / 8] ^= 1 << (i % 8);
            assert_ne!(crc32(&bad), good, "flip of bit {i} undetected");
        }
    }
}
