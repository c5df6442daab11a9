//! LutRam: a small simple dual-port RAM with a registered, enabled read.
//!
//! At an edge with `read_enable` high, `read_data` takes the word at `read_address`;
//! otherwise it holds. Writes land at the edge with `write_enable`. A read of the word
//! written at the same edge returns the old word. yosys maps it to distributed RAM (ECP5
//! TRELLIS_DPR16X4) and a flip-flop whose clock enable is `read_enable`, so a read stall
//! costs no multiplexer in front of the RAM's address.

use crate::hdl::*;

/// RAM of 2^N words of W bits, read through an enabled register.
#[derive(LogicBlock)]
pub struct LutRam<const W: usize, const N: usize> {
    /// The clock of both ports.
    pub clock: Signal<In, Clock>,
    /// Write `write_data` at `write_address` at the next edge.
    pub write_enable: Signal<In, Bit>,
    /// Word written.
    pub write_address: Signal<In, Bits<N>>,
    /// Data written.
    pub write_data: Signal<In, Bits<W>>,
    /// Load `read_data` at the next edge.
    pub read_enable: Signal<In, Bit>,
    /// Word read.
    pub read_address: Signal<In, Bits<N>>,
    /// The word at `read_address` at the last edge with `read_enable`.
    pub read_data: Signal<Out, Bits<W>>,
    _words: Vec<Bits<W>>,
}

impl<const W: usize, const N: usize> Default for LutRam<W, N> {
    fn default() -> Self {
        assert!(W <= 64, "LutRam: {W}-bit words (at most 64)");
        assert!(N <= 10, "LutRam: 2^{N} words (at most 2^10)");
        Self {
            clock: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            read_enable: Default::default(),
            read_address: Default::default(),
            read_data: Default::default(),
            _words: vec![Bits::<W>::default(); 1 << N],
        }
    }
}

impl<const W: usize, const N: usize> Logic for LutRam<W, N> {
    fn update(&mut self) {
        if self.clock.pos_edge() {
            if self.read_enable.val() {
                self.read_data.next = self._words[self.read_address.val().index()];
            }
            if self.write_enable.val() {
                self._words[self.write_address.val().index()] = self.write_data.val();
            }
        }
    }

    fn connect(&mut self) {
        self.read_data.connect();
    }

    fn hdl(&self) -> Verilog {
        Verilog::Custom(format!(
            "reg [{w}:0] words [0:{last}];\n\
             always @(posedge clock) begin\n\
             \x20   if (write_enable) words[write_address] <= write_data;\n\
             \x20   if (read_enable) read_data <= words[read_address];\n\
             end\n",
            w = W - 1,
            last = (1usize << N) - 1,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    #[test]
    fn reads_when_enabled_and_holds_otherwise() {
        let mut bench = Bench::new(LutRam::<9, 6>::default(), |b| &mut b.clock);
        for a in 0..64u64 {
            bench.uut.write_enable.next = true;
            bench.uut.write_address.next = a.into();
            bench.uut.write_data.next = (a * 5 + 100).into();
            bench.cycle();
        }
        bench.uut.write_enable.next = false;
        for a in [5u64, 63, 0, 17] {
            bench.uut.read_enable.next = true;
            bench.uut.read_address.next = a.into();
            bench.cycle();
            assert_eq!(bench.uut.read_data.val().to_u64(), a * 5 + 100);
            // disabled: the address moves, the data stays
            bench.uut.read_enable.next = false;
            bench.uut.read_address.next = (a ^ 1).into();
            bench.cycles(3);
            assert_eq!(bench.uut.read_data.val().to_u64(), a * 5 + 100);
        }
        // a read of the word being written returns the old word
        bench.uut.write_enable.next = true;
        bench.uut.write_address.next = 9u64.into();
        bench.uut.write_data.next = 1u64.into();
        bench.uut.read_enable.next = true;
        bench.uut.read_address.next = 9u64.into();
        bench.cycle();
        assert_eq!(bench.uut.read_data.val().to_u64(), 9 * 5 + 100);
        bench.uut.write_enable.next = false;
        bench.cycle();
        assert_eq!(bench.uut.read_data.val().to_u64(), 1);
    }
}
