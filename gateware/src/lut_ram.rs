//! LutRam: a small RAM with a synchronous write and an asynchronous read, for the
//! distributed RAM of an ECP5's logic slices.
//!
//! One write port, one read port, one clock. `read_data` is the word at `read_address` in
//! the same clock (no register): after the edge that writes a word, a read of it returns
//! the new data. Yosys maps the array to `TRELLIS_DPR16X4` cells (16 words of 4 bits each),
//! so a table of a few wide words costs a few slices of LUTs instead of a flip-flop per
//! bit. Its contents after power-up are not defined: the users keep a valid bit per word in
//! a register.

use crate::hdl::*;

/// RAM of 2^N words of W bits, read without a register.
#[derive(LogicBlock)]
pub struct LutRam<const W: usize, const N: usize> {
    /// The clock of the write port.
    pub clock: Signal<In, Clock>,
    /// Write `write_data` at `write_address` at the next edge.
    pub write_enable: Signal<In, Bit>,
    /// Word written.
    pub write_address: Signal<In, Bits<N>>,
    /// Data written.
    pub write_data: Signal<In, Bits<W>>,
    /// Word read.
    pub read_address: Signal<In, Bits<N>>,
    /// The word at `read_address`, now.
    pub read_data: Signal<Out, Bits<W>>,
    _words: Vec<Bits<W>>,
}

impl<const W: usize, const N: usize> Default for LutRam<W, N> {
    fn default() -> Self {
        assert!(
            N <= 6,
            "LutRam: 2^{N} words (at most 64: a distributed RAM)"
        );
        Self {
            clock: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            read_address: Default::default(),
            read_data: Default::default(),
            _words: vec![Bits::<W>::default(); 1 << N],
        }
    }
}

impl<const W: usize, const N: usize> Logic for LutRam<W, N> {
    fn update(&mut self) {
        if self.clock.pos_edge() && self.write_enable.val() {
            self._words[self.write_address.val().index()] = self.write_data.val();
        }
        self.read_data.next = self._words[self.read_address.val().index()];
    }

    fn connect(&mut self) {
        self.read_data.connect();
    }

    fn hdl(&self) -> Verilog {
        Verilog::Custom(format!(
            "reg [{w}:0] ram_words [0:{last}];\n\
             always @(posedge clock) begin\n\
             \x20   if (write_enable) ram_words[write_address] <= write_data;\n\
             end\n\
             always @(*) read_data = ram_words[read_address];\n",
            w = W - 1,
            last = (1usize << N) - 1,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    #[test]
    fn reads_see_the_words_written_at_earlier_edges() {
        let mut bench = Bench::new(LutRam::<40, 2>::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(7);
        let mut words = [None::<u64>; 4];
        for _ in 0..200 {
            let write = rng.chance(0.5);
            let address = rng.next_u64() % 4;
            let data = rng.next_u64() & ((1 << 40) - 1);
            let read = rng.next_u64() % 4;
            bench.uut.write_enable.next = write;
            bench.uut.write_address.next = address.into();
            bench.uut.write_data.next = data.into();
            bench.uut.read_address.next = read.into();
            bench.settle();
            // the read is of the words before this clock's write
            if let Some(want) = words[read as usize] {
                assert_eq!(bench.uut.read_data.val().to_u64(), want, "address {read}");
            }
            bench.cycle();
            if write {
                words[address as usize] = Some(data);
            }
            bench.settle();
            if let Some(want) = words[read as usize] {
                assert_eq!(bench.uut.read_data.val().to_u64(), want, "address {read}");
            }
        }
    }

    #[test]
    fn verilog_is_an_array_with_an_asynchronous_read() {
        let uut = LutRam::<64, 2>::default();
        let Verilog::Custom(body) = uut.hdl() else {
            panic!("custom Verilog expected");
        };
        assert!(body.contains("reg [63:0] ram_words [0:3];"));
        assert!(body.contains("always @(*) read_data = ram_words[read_address];"));
    }
}
