//! DownlinkPinScan: puts every downlink port's next data bit in place during the bit
//! before it.
//!
//! The ports' frame bytes are in block RAM banks of [`DOWNLINK_BANK_PORTS`] ports (port `p`
//! at word `p % DOWNLINK_BANK_PORTS` of bank `p / DOWNLINK_BANK_PORTS`). Two clocks after a
//! bit's end the frame timer's decodes say what the next bit is; before a data bit the scan
//! reads a word of every bank a clock (`read_word`), and [`READ_LATENCY`] clocks later
//! `take` is high with the word (`take_word`, one-hot) and bit `b` of `values` the data bit
//! of that word's port in bank `b`. Every port's next data bit is taken
//! [`pin_scan_clocks`] after the bit's end: the bit shifting of every transmitter is one
//! shared bit index and a RAM read.

use crate::block_ram::READ_LATENCY;
use crate::geometry::DOWNLINK_BANK_PORTS;
use crate::hdl::*;

/// Clocks of the pin scan after a bit's end before its last port's next data bit is in
/// place: the frame decode (2), the scan of a bank's words, the RAM (2), the value and
/// its write (2).
pub fn pin_scan_clocks(ports: usize) -> u64 {
    2 + ports.min(DOWNLINK_BANK_PORTS) as u64 + READ_LATENCY + 2
}

/// The pin scan of N ports' frame bytes.
#[derive(LogicBlock)]
pub struct DownlinkPinScan {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no scan under way.
    pub reset: Signal<In, Bit>,
    /// The frame timer's bit end.
    pub bit_end: Signal<In, Bit>,
    /// The frame timer's decode: the next bit is a data bit...
    pub next_is_data: Signal<In, Bit>,
    /// ... this one.
    pub next_data_bit: Signal<In, Bits<3>>,
    /// Word read from every bank.
    pub read_word: Signal<Out, Bits<4>>,
    /// Per bank: the word read ([`READ_LATENCY`] clocks after its `read_word`).
    pub bank_data: Vec<Signal<In, Bits<8>>>,
    /// The ports of word `take_word` take their next data bit from `values`.
    pub take: Signal<Out, Bit>,
    /// The word taken, one-hot.
    pub take_word: Signal<Out, Bits<16>>,
    /// Bit `b`: the next data bit of the port at that word of bank `b`.
    pub values: Signal<Out, Bits<4>>,
    bank_bit: Vec<Constant<Bits<4>>>,
    first_word: Constant<Bits<16>>,
    last_word: Constant<Bits<4>>,
    after_bit_end_1: DFF<Bit>,
    after_bit_end_2: DFF<Bit>,
    scanning: DFF<Bit>,
    word: DFF<Bits<4>>,
    visit_1: DFF<Bit>,
    word_1: DFF<Bits<4>>,
    visit_2: DFF<Bit>,
    word_2: DFF<Bits<4>>,
    taking: DFF<Bit>,
    taken_word: DFF<Bits<16>>,
    taken_values: DFF<Bits<4>>,
    bank_byte: Signal<Local, Bits<8>>,
    bank_values: Signal<Local, Bits<4>>,
}

impl DownlinkPinScan {
    /// The scan of `ports` ports' banks.
    pub fn new(ports: usize) -> Self {
        let banks = ports.div_ceil(DOWNLINK_BANK_PORTS);
        Self {
            clock: Default::default(),
            reset: Default::default(),
            bit_end: Default::default(),
            next_is_data: Default::default(),
            next_data_bit: Default::default(),
            read_word: Default::default(),
            bank_data: each(banks),
            take: Default::default(),
            take_word: Default::default(),
            values: Default::default(),
            bank_bit: (0..banks)
                .map(|b| Constant::new((1u64 << b).into()))
                .collect(),
            first_word: Constant::new(1.into()),
            last_word: Constant::new((ports.min(DOWNLINK_BANK_PORTS) as u64 - 1).into()),
            after_bit_end_1: Default::default(),
            after_bit_end_2: Default::default(),
            scanning: Default::default(),
            word: Default::default(),
            visit_1: Default::default(),
            word_1: Default::default(),
            visit_2: Default::default(),
            word_2: Default::default(),
            taking: Default::default(),
            taken_word: Default::default(),
            taken_values: Default::default(),
            bank_byte: Default::default(),
            bank_values: Default::default(),
        }
    }
}

impl Logic for DownlinkPinScan {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            after_bit_end_1,
            after_bit_end_2,
            scanning,
            word,
            visit_1,
            word_1,
            visit_2,
            word_2,
            taking,
            taken_word,
            taken_values
        );
        self.after_bit_end_1.d.next = self.bit_end.val();
        self.after_bit_end_2.d.next = self.after_bit_end_1.q.val();
        if self.scanning.q.val() {
            self.word.d.next = self.word.q.val() + 1;
            if self.word.q.val() == self.last_word.val() {
                self.scanning.d.next = false;
            }
        }
        if self.after_bit_end_2.q.val() & self.next_is_data.val() {
            self.scanning.d.next = true;
            self.word.d.next = 0.into();
        }
        self.read_word.next = self.word.q.val();
        self.visit_1.d.next = self.scanning.q.val();
        self.word_1.d.next = self.word.q.val();
        self.visit_2.d.next = self.visit_1.q.val();
        self.word_2.d.next = self.word_1.q.val();
        self.taking.d.next = self.visit_2.q.val();
        self.taken_word.d.next = self.first_word.val() << self.word_2.q.val();
        self.bank_values.next = 0.into();
        for b in 0..self.bank_data.len() {
            self.bank_byte.next = self.bank_data[b].val() >> self.next_data_bit.val();
            if self.bank_byte.val().get_bit(0) {
                self.bank_values.next = self.bank_values.val() | self.bank_bit[b].val();
            }
        }
        self.taken_values.d.next = self.bank_values.val();
        self.take.next = self.taking.q.val();
        self.take_word.next = self.taken_word.q.val();
        self.values.next = self.taken_values.q.val();
        if self.reset.val() {
            self.scanning.d.next = false;
            self.visit_1.d.next = false;
            self.visit_2.d.next = false;
            self.taking.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block_ram::BlockRam;
    use crate::testbench::{Bench, TestRng};

    /// The scan with the banks it reads, holding random bytes.
    #[derive(LogicBlock)]
    struct ScanWithBanks {
        clock: Signal<In, Clock>,
        scan: DownlinkPinScan,
        banks: Vec<BlockRam<8, 4>>,
    }

    impl Logic for ScanWithBanks {
        #[hdl_gen]
        fn update(&mut self) {
            self.scan.clock.next = self.clock.val();
            for b in 0..self.banks.len() {
                self.banks[b].clock.next = self.clock.val();
                self.banks[b].read_address.next = self.scan.read_word.val();
                self.scan.bank_data[b].next = self.banks[b].read_data.val();
            }
        }
    }

    /// After a bit's end before data bit `k`, every port of 40 gets bit `k` of its byte,
    /// each port exactly once, within [`pin_scan_clocks`].
    #[test]
    fn every_port_gets_its_next_data_bit_once_in_time() {
        let ports: usize = 40;
        let mut rng = TestRng::new(3);
        let bytes: Vec<u8> = (0..ports).map(|_| rng.byte()).collect();
        let banks = (0..ports.div_ceil(DOWNLINK_BANK_PORTS))
            .map(|b| {
                let words: Vec<u64> = (0..DOWNLINK_BANK_PORTS)
                    .map(|w| u64::from(*bytes.get(b * DOWNLINK_BANK_PORTS + w).unwrap_or(&0)))
                    .collect();
                BlockRam::with_contents(&words)
            })
            .collect();
        let uut = ScanWithBanks {
            clock: Default::default(),
            scan: DownlinkPinScan::new(ports),
            banks,
        };
        let mut bench = Bench::new(uut, |b| &mut b.clock);
        bench.uut.scan.reset.next = true;
        bench.cycle();
        bench.uut.scan.reset.next = false;
        for k in 0..8u64 {
            bench.uut.scan.next_is_data.next = true;
            bench.uut.scan.next_data_bit.next = k.into();
            bench.uut.scan.bit_end.next = true;
            bench.cycle();
            bench.uut.scan.bit_end.next = false;
            let mut got = vec![None; ports];
            for clock in 1..40 {
                bench.cycle();
                let scan = &bench.uut.scan;
                if !scan.take.val() {
                    continue;
                }
                assert!(clock <= pin_scan_clocks(ports), "bit {k} taken late");
                let word = scan.take_word.val().to_u32();
                assert_eq!(word.count_ones(), 1);
                let word = word.trailing_zeros() as usize;
                for (p, got) in got.iter_mut().enumerate() {
                    if p % DOWNLINK_BANK_PORTS == word {
                        assert!(got.is_none(), "port {p} taken twice");
                        let bank = p / DOWNLINK_BANK_PORTS;
                        *got = Some(scan.values.val().get_bit(bank));
                    }
                }
            }
            for (p, got) in got.iter().enumerate() {
                assert_eq!(*got, Some(bytes[p] >> k & 1 == 1), "port {p}, bit {k}");
            }
        }
    }
}
