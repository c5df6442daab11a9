//! FcsOutput: the frame transmitter's output stage, the Ethernet layer's transmit end: each
//! byte through a register, the CRC-32 computed from that register, and the frame check
//! sequence put in at the output register.
//!
//! In each clock of a frame (`valid`) the transmitter gives the byte (`data`), and whether
//! the FCS covers it (`covered`, from the byte after the SFD to the frame's last data
//! byte) or the FCS replaces it (`fcs`, the four bytes after the data). `crc_start` (the
//! clock the SFD is in the stage) sets the CRC register to all ones. The byte goes into the
//! stage register, the CRC is computed from it, and the output register takes the byte or
//! the FCS's next byte (the complement of the CRC register, least significant byte first):
//! `gmii_txd`/`gmii_tx_en` follow the inputs by [`OUTPUT_LATENCY`] clocks, and no path runs
//! from the transmitter's byte selection through the CRC. A body beat that was missing when
//! due (`beat_missing`, in its byte's clock) sets `gmii_tx_er` with its byte.

use crate::crc32::Crc32Byte;
use crate::hdl::*;

/// Clocks from a byte at the input to the byte on `gmii_txd`.
pub const OUTPUT_LATENCY: u64 = 2;

/// The output stage with the FCS.
#[derive(LogicBlock, Default)]
pub struct FcsOutput {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing sent.
    pub reset: Signal<In, Bit>,
    /// A frame's byte is at the input.
    pub valid: Signal<In, Bit>,
    /// The byte.
    pub data: Signal<In, Bits<8>>,
    /// The FCS covers the byte.
    pub covered: Signal<In, Bit>,
    /// The byte's place holds an FCS byte.
    pub fcs: Signal<In, Bit>,
    /// The CRC starts again (the SFD is in the stage register).
    pub crc_start: Signal<In, Bit>,
    /// The byte is a body byte whose beat was missing.
    pub beat_missing: Signal<In, Bit>,
    /// GMII transmit data.
    pub gmii_txd: Signal<Out, Bits<8>>,
    /// GMII transmit enable.
    pub gmii_tx_en: Signal<Out, Bit>,
    /// GMII transmit error.
    pub gmii_tx_er: Signal<Out, Bit>,
    crc: Crc32Byte,
    crc_register: DFF<Bits<32>>,
    stage_byte: DFF<Bits<8>>,
    stage_valid: DFF<Bit>,
    stage_crc: DFF<Bit>,
    stage_fcs: DFF<Bit>,
    // a body beat was missing: the byte in the output stage, then at the output
    stage_error: DFF<Bit>,
    txd: DFF<Bits<8>>,
    tx_en: DFF<Bit>,
    tx_er: DFF<Bit>,
}

impl Logic for FcsOutput {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            crc_register,
            stage_byte,
            stage_valid,
            stage_crc,
            stage_fcs,
            stage_error,
            txd,
            tx_en,
            tx_er
        );
        self.stage_error.d.next = self.beat_missing.val();
        self.tx_er.d.next = self.stage_valid.q.val() & self.stage_error.q.val();
        self.stage_valid.d.next = self.valid.val();
        self.stage_byte.d.next = self.data.val();
        self.stage_crc.d.next = self.covered.val();
        self.stage_fcs.d.next = self.fcs.val();
        self.crc.register.next = self.crc_register.q.val();
        self.crc.data.next = self.stage_byte.q.val();
        self.tx_en.d.next = self.stage_valid.q.val();
        self.txd.d.next = self.stage_byte.q.val();
        if self.stage_valid.q.val() & self.stage_crc.q.val() {
            self.crc_register.d.next = self.crc.updated.val();
        } else if self.stage_valid.q.val() & self.stage_fcs.q.val() {
            self.txd.d.next = !self.crc_register.q.val().get_bits::<8>(0);
            self.crc_register.d.next = self.crc_register.q.val() >> 8;
        }
        if self.crc_start.val() {
            self.crc_register.d.next = 0xFFFF_FFFF_u64.into();
        }
        if self.reset.val() {
            self.stage_valid.d.next = false;
            self.tx_en.d.next = false;
            self.tx_er.d.next = false;
        }
        self.gmii_txd.next = self.txd.q.val();
        self.gmii_tx_en.next = self.tx_en.q.val();
        self.gmii_tx_er.next = self.tx_er.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Random frames with a preamble, the FCS computed by the `crc` crate; some with a
    /// missing body beat.
    #[test]
    fn frames_get_their_fcs_and_missing_beats_their_error() {
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let mut bench = Bench::new(FcsOutput::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xFC5);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..100 {
            let data: Vec<u8> = (0..60 + rng.next_u64() % 100).map(|_| rng.byte()).collect();
            let missing = (round % 3 == 0).then(|| rng.next_u64() as usize % data.len());
            let mut sent = vec![0x55; 7];
            sent.push(0xD5);
            sent.extend(&data);
            let total = sent.len() + 4;
            let (mut out, mut errors) = (Vec::new(), Vec::new());
            for clock in 0..total as u64 + OUTPUT_LATENCY + 2 {
                let at = clock as usize;
                let u = &mut bench.uut;
                u.valid.next = at < total;
                u.data.next = u64::from(*sent.get(at).unwrap_or(&0)).into();
                u.covered.next = (8..sent.len()).contains(&at);
                u.fcs.next = (sent.len()..total).contains(&at);
                // the SFD (byte 7) is in the stage register in byte 8's clock
                u.crc_start.next = at == 8;
                u.beat_missing.next = missing.is_some_and(|m| at == 8 + m);
                bench.settle();
                if bench.uut.gmii_tx_en.val() {
                    out.push(bench.uut.gmii_txd.val().to_u64() as u8);
                    errors.push(bench.uut.gmii_tx_er.val());
                }
                bench.cycle();
            }
            let mut want = sent.clone();
            want.extend(crc.checksum(&data).to_le_bytes());
            assert_eq!(out, want, "round {round}");
            let error_at: Vec<usize> = (0..errors.len()).filter(|&i| errors[i]).collect();
            assert_eq!(
                error_at,
                missing.map(|m| 8 + m).into_iter().collect::<Vec<_>>()
            );
        }
    }
}
