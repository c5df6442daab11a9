//! BlockRom: a read-only table in block RAM, with the read timing of [`crate::block_ram`]
//! ([`crate::block_ram::READ_LATENCY`]).
//!
//! A read takes two clocks: the address is taken at one edge, the word appears after the
//! next. The Verilog is a memory with its contents in an `initial` block and two output
//! registers; yosys maps it to one ECP5 block RAM (`rom_style = "block"`), whose read
//! register takes the first stage, so the table costs no LUTs; Verilator runs the same
//! text. The contents live in the Verilog itself: no file beside it to lose.

use rust_hdl::prelude::*;

/// A table of 2^N words of W bits, read through two registers.
#[derive(LogicBlock)]
pub struct BlockRom<const W: usize, const N: usize> {
    /// The clock.
    pub clock: Signal<In, Clock>,
    /// Word read.
    pub read_address: Signal<In, Bits<N>>,
    /// The word at `read_address` two edges ago.
    pub read_data: Signal<Out, Bits<W>>,
    _words: Vec<u64>,
    _array_out: Bits<W>,
}

impl<const W: usize, const N: usize> BlockRom<W, N> {
    /// A table holding `words` from address 0 on; the addresses after them hold 0. Panics
    /// when a word does not fit W bits or there are more than 2^N words.
    pub fn new(words: &[u64]) -> Self {
        assert!(W <= 64, "BlockRom: {W}-bit words (at most 64)");
        assert!(N <= 14, "BlockRom: 2^{N} words (at most 2^14)");
        assert!(
            words.len() <= 1 << N,
            "BlockRom: {} words for 2^{N} addresses",
            words.len()
        );
        if let Some(w) = words.iter().find(|&&w| W < 64 && w >> W != 0) {
            panic!("BlockRom: word {w:#x} does not fit {W} bits");
        }
        let mut all = words.to_vec();
        all.resize(1 << N, 0);
        Self {
            clock: Default::default(),
            read_address: Default::default(),
            read_data: Default::default(),
            _words: all,
            _array_out: Bits::<W>::default(),
        }
    }
}

impl<const W: usize, const N: usize> Logic for BlockRom<W, N> {
    fn update(&mut self) {
        if self.clock.pos_edge() {
            self.read_data.next = self._array_out;
            self._array_out = self._words[self.read_address.val().index()].into();
        }
    }

    fn connect(&mut self) {
        self.read_data.connect();
    }

    fn hdl(&self) -> Verilog {
        Verilog::Custom(verilog_body(W, N, &self._words))
    }
}

/// The module body: the table with its contents and its two registers.
fn verilog_body(width: usize, address_bits: usize, words: &[u64]) -> String {
    let contents: String = words
        .iter()
        .enumerate()
        .filter(|(_, &w)| w != 0)
        .map(|(a, w)| format!("    words[{a}] = {width}'h{w:x};\n"))
        .collect();
    format!(
        "(* rom_style = \"block\", ram_style = \"block\" *)\n\
         reg [{w}:0] words [0:{last}];\n\
         reg [{w}:0] array_out;\n\
         integer i;\n\
         initial begin\n\
         \x20   for (i = 0; i <= {last}; i = i + 1) words[i] = {width}'h0;\n\
         {contents}\
         end\n\
         always @(posedge clock) begin\n\
         \x20   array_out <= words[read_address];\n\
         \x20   read_data <= array_out;\n\
         end\n",
        w = width - 1,
        last = (1usize << address_bits) - 1,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    #[test]
    fn reads_take_two_clocks() {
        let table: Vec<u64> = (0..20u64).map(|a| a * 37 % 256).collect();
        let mut bench = Bench::new(BlockRom::<8, 5>::new(&table), |b| &mut b.clock);
        let addresses: Vec<u64> = (0..32u64).rev().chain([3, 3, 19, 0]).collect();
        let mut seen = Vec::new();
        for &a in &addresses {
            bench.uut.read_address.next = a.into();
            bench.cycle();
            seen.push(bench.uut.read_data.val().to_u64());
        }
        // the word of the address presented before edge k appears after edge k + 1
        let expected: Vec<u64> = addresses
            .iter()
            .map(|&a| table.get(a as usize).copied().unwrap_or(0))
            .collect();
        assert_eq!(&seen[1..], &expected[..expected.len() - 1]);
    }

    #[test]
    fn verilog_holds_the_contents_and_asks_for_block_ram() {
        let body = verilog_body(8, 7, &[0x55, 0, 0xD5]);
        assert!(body.contains("rom_style = \"block\""));
        assert!(body.contains("words[0] = 8'h55;"));
        assert!(body.contains("words[2] = 8'hd5;"));
        assert!(!body.contains("words[1] = 8'h"), "zeros come from the loop");
        assert!(body.contains("reg [7:0] words [0:127];"));
    }

    #[test]
    #[should_panic(expected = "does not fit 8 bits")]
    fn a_word_too_wide_is_refused() {
        BlockRom::<8, 4>::new(&[0x100]);
    }
}
