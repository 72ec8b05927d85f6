//! CRC-8 SAE J1850 (polynomial 0x1D, initial value 0xFF, final XOR 0xFF), the CRC of
//! AUTOSAR E2E profiles 1 and 2. Check value: CRC("123456789") = 0x4B.

/// CRC-8 SAE J1850 of `data`, continuing from `crc` (start with [`INIT`]); finish with
/// [`finish`].
pub fn update(mut crc: u8, data: &[u8]) -> u8 {
    for &b in data {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x1D
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Initial value.
pub const INIT: u8 = 0xFF;

/// Final XOR.
pub fn finish(crc: u8) -> u8 {
    crc ^ 0xFF
}

/// CRC-8 SAE J1850 of `data`.
pub fn crc8(data: &[u8]) -> u8 {
    finish(update(INIT, data))
}

#[cfg(test)]
mod tests {
    #[test]
    fn check_value() {
        assert_eq!(super::crc8(b"123456789"), 0x4B);
        assert_eq!(super::crc8(&[]), 0x00);
    }
}
