//! BlockRam: a simple dual-port RAM with a registered output, for ECP5 block RAM.
//!
//! One write port, one read port, one clock. A read takes two clocks: the address is
//! taken at one edge, the data appears after the next (the RAM array's output goes
//! through the block RAM's own output register). On an ECP5 that register is inside the
//! DP16KD (`REGMODE_B = "OUTREG"`), so the slow clock-to-output of the array (about
//! 5.8 ns) stays inside the block and the data leaves a register (about 1 ns): the
//! inferred block RAM of yosys cannot use that register.
//!
//! The Verilog has two bodies: with the macro [`ECP5_MACRO`] defined (the synthesis flow
//! defines it) it instantiates DP16KD primitives in the width mode the depth needs (1024
//! x 18, 2048 x 9, 4096 x 4, 8192 x 2, 16384 x 1), side by side for wider data; without
//! it, a behavioural model with the same timing (Verilator, other tools). A read of the
//! address written in the same clock returns the old data in the model; the users never
//! do that.
//!
//! A RAM may start with contents ([`BlockRam::with_contents`]; a table that is never
//! written is a ROM): the model loads them in an `initial` block, the DP16KD instances
//! carry them in their `INITVAL_xx` parameters (in the 1024 x 18 mode: 16 words of 18 bits
//! per parameter, each in 20 bits, as yosys lays out the block RAMs it infers).

use crate::hdl::*;

/// Verilog macro selecting the DP16KD instances.
pub const ECP5_MACRO: &str = "SKINBOX_ECP5_BRAM";

/// Read latency in clocks: address at edge k, data valid after edge k + 2.
pub const READ_LATENCY: u64 = 2;

/// RAM of 2^N words of W bits with a registered output.
#[derive(LogicBlock)]
pub struct BlockRam<const W: usize, const N: usize> {
    /// The clock of both ports.
    pub clock: Signal<In, Clock>,
    /// Write `write_data` at `write_address` at the next edge.
    pub write_enable: Signal<In, Bit>,
    /// Word written.
    pub write_address: Signal<In, Bits<N>>,
    /// Data written.
    pub write_data: Signal<In, Bits<W>>,
    /// Word read.
    pub read_address: Signal<In, Bits<N>>,
    /// The word at `read_address` two edges ago.
    pub read_data: Signal<Out, Bits<W>>,
    _words: Vec<Bits<W>>,
    _array_out: Bits<W>,
    _contents: Vec<u64>,
}

impl<const W: usize, const N: usize> Default for BlockRam<W, N> {
    fn default() -> Self {
        assert!(W <= 64, "BlockRam: {W}-bit words (at most 64)");
        assert!(N <= 14, "BlockRam: 2^{N} words (at most 2^14)");
        Self {
            clock: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            read_address: Default::default(),
            read_data: Default::default(),
            _words: vec![Bits::<W>::default(); 1 << N],
            _array_out: Bits::<W>::default(),
            _contents: Vec::new(),
        }
    }
}

impl<const W: usize, const N: usize> BlockRam<W, N> {
    /// A RAM holding `words` from address 0 on (the addresses after them hold 0). Panics
    /// when a word does not fit W bits, there are more than 2^N words, or the depth needs
    /// a DP16KD mode narrower than 18 bits (more than 2^10 words).
    pub fn with_contents(words: &[u64]) -> Self {
        assert!(
            N <= 10,
            "BlockRam: contents are supported up to 2^10 words (the 1024 x 18 mode)"
        );
        assert!(
            words.len() <= 1 << N,
            "BlockRam: {} words for 2^{N} addresses",
            words.len()
        );
        if let Some(w) = words.iter().find(|&&w| W < 64 && w >> W != 0) {
            panic!("BlockRam: word {w:#x} does not fit {W} bits");
        }
        let mut ram = Self::default();
        for (a, &w) in words.iter().enumerate() {
            ram._words[a] = w.into();
        }
        ram._contents = words.to_vec();
        ram
    }
}

impl<const W: usize, const N: usize> Logic for BlockRam<W, N> {
    fn update(&mut self) {
        if self.clock.pos_edge() {
            self.read_data.next = self._array_out;
            self._array_out = self._words[self.read_address.val().index()];
            if self.write_enable.val() {
                self._words[self.write_address.val().index()] = self.write_data.val();
            }
        }
    }

    fn connect(&mut self) {
        self.read_data.connect();
    }

    fn hdl(&self) -> Verilog {
        Verilog::Custom(verilog_body(W, N, &self._contents))
    }
}

/// DP16KD data width for a depth of 2^`address_bits` words, and the lowest address pin
/// the word address uses (the pins below select bytes or are unused).
fn dp16kd_mode(address_bits: usize) -> (usize, usize) {
    match address_bits {
        0..=10 => (18, 4),
        11 => (9, 3),
        12 => (4, 2),
        13 => (2, 1),
        _ => (1, 0),
    }
}

/// A standalone Verilog module `block_ram` of a [`BlockRam`] of `width`-bit words and
/// `address_bits` address bits starting with `contents` (the body the block generates), for
/// checks with other tools.
pub fn module_verilog(width: usize, address_bits: usize, contents: &[u64]) -> String {
    format!(
        "module block_ram(clock, write_enable, write_address, write_data, read_address, \
         read_data);\n\
         input wire clock;\n\
         input wire write_enable;\n\
         input wire [{n}:0] write_address;\n\
         input wire [{w}:0] write_data;\n\
         input wire [{n}:0] read_address;\n\
         output reg [{w}:0] read_data;\n\
         {body}\
         endmodule\n",
        n = address_bits - 1,
        w = width - 1,
        body = verilog_body(width, address_bits, contents),
    )
}

/// `INITVAL_xx` parameters of the 1024 x 18 DP16KD holding bits `first..first + 18` of
/// `words`: word a is in parameter a / 16, at bit 20 (a % 16); all-zero parameters are left
/// out (zero is their default).
fn dp16kd_initvals(words: &[u64], first: usize) -> String {
    words
        .chunks(16)
        .enumerate()
        .filter_map(|(slice, chunk)| {
            // 320 bits as 80 hex digits, most significant first
            let mut bits = [false; 320];
            for (i, &w) in chunk.iter().enumerate() {
                for b in 0..18 {
                    bits[i * 20 + b] = first + b < 64 && (w >> (first + b)) & 1 == 1;
                }
            }
            if !bits.contains(&true) {
                return None;
            }
            let hex: String = (0..80)
                .rev()
                .map(|digit| {
                    let nibble = (0..4).fold(0, |n, b| n | (usize::from(bits[digit * 4 + b]) << b));
                    char::from_digit(nibble as u32, 16).unwrap()
                })
                .collect();
            Some(format!(".INITVAL_{slice:02X}(320'h{hex}), "))
        })
        .collect()
}

/// The module body: DP16KD instances under [`ECP5_MACRO`], else the model; both start
/// with `contents`.
fn verilog_body(width: usize, address_bits: usize, contents: &[u64]) -> String {
    let (mode, low_pin) = dp16kd_mode(address_bits);
    let blocks = width.div_ceil(mode);
    let mut ecp5 = String::new();
    for block in 0..blocks {
        let first = block * mode;
        let bits = mode.min(width - first);
        let address = |name: &str, write: bool| -> String {
            (0..14)
                .map(|pin| {
                    let port = if write { "A" } else { "B" };
                    let net = if pin >= low_pin && pin - low_pin < address_bits {
                        format!("{name}[{}]", pin - low_pin)
                    } else if write && mode == 18 && pin < 2 {
                        // byte enables of the 18-bit mode
                        "1'b1".to_string()
                    } else {
                        "1'b0".to_string()
                    };
                    format!(".AD{port}{pin}({net})")
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        let data_in: String = (0..18)
            .map(|pin| {
                let net = if pin < bits {
                    format!("write_data[{}]", first + pin)
                } else {
                    "1'b0".to_string()
                };
                format!(".DIA{pin}({net}), .DIB{pin}(1'b0)")
            })
            .collect::<Vec<_>>()
            .join(", ");
        let data_out: String = (0..bits)
            .map(|pin| format!(".DOB{pin}(block_out_{block}[{pin}])"))
            .collect::<Vec<_>>()
            .join(", ");
        ecp5.push_str(&format!(
            "wire [{top}:0] block_out_{block};\n\
             DP16KD #({initvals}.DATA_WIDTH_A({mode}), .DATA_WIDTH_B({mode}), .REGMODE_A(\"NOREG\"), \
             .REGMODE_B(\"OUTREG\"), .RESETMODE(\"SYNC\"), .ASYNC_RESET_RELEASE(\"SYNC\"), \
             .CSDECODE_A(\"0b000\"), .CSDECODE_B(\"0b000\"), .WRITEMODE_A(\"NORMAL\"), \
             .WRITEMODE_B(\"NORMAL\"), .GSR(\"DISABLED\")) block_{block} (\n\
             .CLKA(clock), .CEA(1'b1), .OCEA(1'b1), .WEA(write_enable), .RSTA(1'b0), \
             .CSA0(1'b0), .CSA1(1'b0), .CSA2(1'b0),\n{write_address},\n{data_in},\n\
             .CLKB(clock), .CEB(1'b1), .OCEB(1'b1), .WEB(1'b0), .RSTB(1'b0), \
             .CSB0(1'b0), .CSB1(1'b0), .CSB2(1'b0),\n{read_address},\n{data_out});\n",
            top = bits - 1,
            initvals = dp16kd_initvals(contents, first),
            write_address = address("write_address", true),
            read_address = address("read_address", false),
        ));
    }
    let initial: String = if contents.is_empty() {
        String::new()
    } else {
        let words: String = contents
            .iter()
            .enumerate()
            .filter(|(_, &w)| w != 0)
            .map(|(a, w)| format!("\x20   words[{a}] = {width}'h{w:x};\n"))
            .collect();
        format!(
            "integer i;\n\
             initial begin\n\
             \x20   for (i = 0; i < {depth}; i = i + 1) words[i] = {width}'h0;\n\
             {words}\
             end\n",
            depth = 1usize << address_bits
        )
    };
    let joined: Vec<String> = (0..blocks)
        .rev()
        .map(|b| format!("block_out_{b}"))
        .collect();
    format!(
        "`ifdef {ECP5_MACRO}\n\
         {ecp5}\
         always @(*) read_data = {{{joined}}};\n\
         `else\n\
         (* ram_style = \"block\" *)\n\
         reg [{w}:0] words [0:{last}];\n\
         reg [{w}:0] array_out;\n\
         {initial}\
         always @(posedge clock) begin\n\
         \x20   if (write_enable) words[write_address] <= write_data;\n\
         \x20   array_out <= words[read_address];\n\
         \x20   read_data <= array_out;\n\
         end\n\
         `endif\n",
        joined = joined.join(", "),
        w = width - 1,
        last = (1usize << address_bits) - 1,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    #[test]
    fn reads_take_two_clocks_and_see_earlier_writes() {
        let mut bench = Bench::new(BlockRam::<12, 5>::default(), |b| &mut b.clock);
        for a in 0..32u64 {
            bench.uut.write_enable.next = true;
            bench.uut.write_address.next = a.into();
            bench.uut.write_data.next = (a * 97 % 4096).into();
            bench.cycle();
        }
        bench.uut.write_enable.next = false;
        let mut seen = Vec::new();
        for a in (0..32u64).rev() {
            bench.uut.read_address.next = a.into();
            bench.cycle();
            seen.push(bench.uut.read_data.val().to_u64());
        }
        bench.cycle();
        seen.push(bench.uut.read_data.val().to_u64());
        // the data of address a appears two edges after a was presented
        let expected: Vec<u64> = (0..32u64).rev().map(|a| a * 97 % 4096).collect();
        assert_eq!(&seen[1..], &expected[..]);
    }

    #[test]
    fn ecp5_body_uses_the_width_mode_of_the_depth() {
        // 4096 x 8: two 4096 x 4 blocks; 512 x 32: two 1024 x 18 blocks
        let body = verilog_body(8, 12, &[]);
        assert_eq!(body.matches("DP16KD #").count(), 2);
        assert!(body.contains(".DATA_WIDTH_A(4)"));
        assert!(body.contains(".ADA2(write_address[0])"));
        assert!(body.contains(".ADB13(read_address[11])"));
        assert!(body.contains(".DIA3(write_data[7])"));
        let body = verilog_body(32, 9, &[]);
        assert_eq!(body.matches("DP16KD #").count(), 2);
        assert!(
            body.contains(".ADA0(1'b1)"),
            "byte enables of the 18-bit mode"
        );
        assert!(body.contains(".ADA12(write_address[8]), .ADA13(1'b0)"));
        assert!(body.contains(".DOB13(block_out_1[13])"));
        assert!(!body.contains("block_out_1[14]"));
        assert!(body.contains("read_data = {block_out_1, block_out_0}"));
    }

    #[test]
    fn contents_are_read_in_two_clocks_until_overwritten() {
        let table: Vec<u64> = (0..20u64).map(|a| a * 37 % 256).collect();
        let mut bench = Bench::new(BlockRam::<8, 5>::with_contents(&table), |b| &mut b.clock);
        let addresses: Vec<u64> = (0..32u64).rev().chain([3, 3, 19, 0]).collect();
        let mut seen = Vec::new();
        for &a in &addresses {
            bench.uut.read_address.next = a.into();
            bench.cycle();
            seen.push(bench.uut.read_data.val().to_u64());
        }
        bench.cycle();
        seen.push(bench.uut.read_data.val().to_u64());
        let expected: Vec<u64> = addresses
            .iter()
            .map(|&a| table.get(a as usize).copied().unwrap_or(0))
            .collect();
        assert_eq!(&seen[1..], &expected[..]);
        // a write replaces a word of the contents
        bench.uut.write_enable.next = true;
        bench.uut.write_address.next = 3.into();
        bench.uut.write_data.next = 0xEE.into();
        bench.uut.read_address.next = 3.into();
        bench.cycles(3);
        assert_eq!(bench.uut.read_data.val().to_u64(), 0xEE);
    }

    #[test]
    fn contents_go_to_the_model_and_the_dp16kd_parameters() {
        // word 0 = 1, word 1 = 3 (bits 20, 21 of INITVAL_00), word 17 = 0x2_0001 (bit 0
        // and bit 17 of its 20-bit place in INITVAL_01: bits 20 and 37)
        let mut words = vec![0u64; 18];
        words[0] = 1;
        words[1] = 3;
        words[17] = 0x2_0001;
        let body = verilog_body(18, 7, &words);
        let zeros = |n: usize| "0".repeat(n);
        assert!(
            body.contains(&format!(".INITVAL_00(320'h{}300001)", zeros(74))),
            "{body}"
        );
        assert!(body.contains(&format!(".INITVAL_01(320'h{}2000100000)", zeros(70))));
        assert!(!body.contains("INITVAL_02"), "zero parameters are left out");
        assert!(body.contains("words[17] = 18'h20001;"));
        assert!(!body.contains("words[2] = "), "zeros come from the loop");
        // 36-bit words: the second block holds bits 18..36
        let body = verilog_body(36, 4, &[1 << 18]);
        let initval = format!(".INITVAL_00(320'h{}1)", zeros(79));
        assert_eq!(body.matches(&initval).count(), 1, "{body}");
        assert!(body.find(&initval) > body.find("wire [17:0] block_out_1;"));
    }

    #[test]
    #[should_panic(expected = "does not fit 8 bits")]
    fn a_word_too_wide_is_refused() {
        BlockRam::<8, 4>::with_contents(&[0x100]);
    }
}
