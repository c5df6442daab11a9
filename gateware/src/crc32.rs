//! Crc32Byte: one byte of the Ethernet frame check sequence (IEEE 802.3 CRC-32), as
//! combinational logic.
//!
//! The register is kept reflected (LSB first, polynomial 0xEDB88320), so `next` is the
//! bitwise LFSR unrolled over the 8 data bits, least significant first. A frame starts with
//! the register at all ones; the FCS is the complement of the final register, sent least
//! significant byte first. Cost: about 100 LUT4 of XOR; depth 8 XOR levels, which the
//! synthesis tool flattens.

use crate::hdl::*;

/// The reflected CRC-32 polynomial of IEEE 802.3.
pub const POLYNOMIAL_REFLECTED: u64 = 0xEDB8_8320_u64;

/// Next CRC register after one byte.
#[derive(LogicBlock)]
pub struct Crc32Byte {
    /// Register before the byte.
    pub register: Signal<In, Bits<32>>,
    /// The byte.
    pub data: Signal<In, Bits<8>>,
    /// Register after the byte.
    pub updated: Signal<Out, Bits<32>>,
    polynomial: Constant<Bits<32>>,
    stage: [Signal<Local, Bits<32>>; 9],
}

impl Default for Crc32Byte {
    fn default() -> Self {
        Self {
            register: Default::default(),
            data: Default::default(),
            updated: Default::default(),
            polynomial: Constant::new(POLYNOMIAL_REFLECTED.into()),
            stage: Default::default(),
        }
    }
}

impl Logic for Crc32Byte {
    #[hdl_gen]
    fn update(&mut self) {
        self.stage[0].next = self.register.val();
        for i in 0..8 {
            if self.stage[i].val().get_bit(0) ^ self.data.val().get_bit(i) {
                self.stage[i + 1].next = (self.stage[i].val() >> 1) ^ self.polynomial.val();
            } else {
                self.stage[i + 1].next = self.stage[i].val() >> 1;
            }
        }
        self.updated.next = self.stage[8].val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fcs(bytes: &[u8]) -> u32 {
        let mut block = Crc32Byte::default();
        block.connect_all();
        let mut crc: u64 = 0xFFFF_FFFF;
        for b in bytes {
            block.register.next = crc.into();
            block.data.next = u64::from(*b).into();
            assert!(simulate(&mut block, 100));
            crc = block.updated.val().to_u64();
        }
        !(crc as u32)
    }

    #[test]
    fn matches_the_crc_crate_on_every_byte_and_a_frame() {
        let oracle = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        for b in 0..=255u8 {
            assert_eq!(fcs(&[b]), oracle.checksum(&[b]), "byte {b:#04x}");
        }
        let frame: Vec<u8> = (0..1500u32).map(|i| (i * 7 + i / 3) as u8).collect();
        assert_eq!(fcs(&frame), oracle.checksum(&frame));
        // the classic check value
        assert_eq!(fcs(b"123456789"), 0xCBF4_3926);
    }
}
