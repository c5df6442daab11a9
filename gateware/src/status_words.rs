//! StatusWords: the value of each 32-bit word of a status page, and which word is its last.
//!
//! Words of a page: 0 the boot id, 1 records datagrams sent, 2 records sent, 3 the first
//! port (top byte) and reserved bits, from [`HEADER_WORDS`] on the port counters (eight per
//! port, from the counter file: `counter_data`), then the box counter block of
//! [`BOX_COUNTER_WORDS`] words: the link word (`link_up` in bit 24, `link_speed` in bits
//! 16-17), then the box counters (from the box counter file: `box_counter_data`, read at
//! `box_counter_address`, which steps with the words of the block from 0 at the link word).
//! A word holds for several clocks (`next_word` moves on): the tests of the word against
//! the page's layout are registered a clock after the word, the header value and the source
//! a clock after them, so `value` is the word's from its third clock on (the counters' as
//! the memories answer their address). Cost: 32 + 9 + 5 + 5 flip-flops.

use crate::hdl::*;
use skinbox_protocol::box_counters::BOX_COUNTERS_LEN;

/// Words of a page before the port counters: boot id, datagrams, records, first port.
pub const HEADER_WORDS: usize = 4;
/// Words of the box counter block after the port counters.
pub const BOX_COUNTER_WORDS: usize = BOX_COUNTERS_LEN / 4;

/// The words of a status page.
#[derive(LogicBlock)]
pub struct StatusWords {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The word's last clock: the next word follows.
    pub next_word: Signal<In, Bit>,
    /// The word of the page.
    pub word: Signal<In, Bits<9>>,
    /// The page's first port.
    pub first_port: Signal<In, Bits<7>>,
    /// The page's port count.
    pub page_ports: Signal<In, Bits<7>>,
    /// Word 0.
    pub boot_id: Signal<In, Bits<32>>,
    /// Word 1.
    pub datagrams_sent: Signal<In, Bits<32>>,
    /// Word 2.
    pub records_sent: Signal<In, Bits<32>>,
    /// The port counter of the word (read by the reporter two clocks before).
    pub counter_data: Signal<In, Bits<32>>,
    /// The link is up (the link word).
    pub link_up: Signal<In, Bit>,
    /// The link's speed (the link word).
    pub link_speed: Signal<In, Bits<2>>,
    /// The box counter to read for the word.
    pub box_counter_address: Signal<Out, Bits<5>>,
    /// That box counter, two clocks after its address.
    pub box_counter_data: Signal<In, Bits<32>>,
    /// The word's value (from the word's third clock).
    pub value: Signal<Out, Bits<32>>,
    /// The word is the page's last (from its second clock).
    pub last_word: Signal<Out, Bit>,
    // the page's first counter word, and its last word less 8 per port
    first_counter_word: Constant<Bits<9>>,
    last_word_over_ports: Constant<Bits<9>>,
    // the box counter block's first word; the word is in the block, at its first word
    block_start: DFF<Bits<9>>,
    in_block: DFF<Bit>,
    at_block: DFF<Bit>,
    // the box counter of the block's next counter word, stepped with the word in the block
    box_counter_word: DFF<Bits<5>>,
    // the value of word 0 to 3 or the link word, and whether a counter is the word instead
    // (registered: the reporter's shift register loads from registers only)
    header_word: DFF<Bits<32>>,
    word_from_memory: DFF<Bit>,
    word_from_box_counters: DFF<Bit>,
    // the word is the page's last
    page_last_word: DFF<Bit>,
}

impl Default for StatusWords {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            next_word: Default::default(),
            word: Default::default(),
            first_port: Default::default(),
            page_ports: Default::default(),
            boot_id: Default::default(),
            datagrams_sent: Default::default(),
            records_sent: Default::default(),
            counter_data: Default::default(),
            link_up: Default::default(),
            link_speed: Default::default(),
            box_counter_address: Default::default(),
            box_counter_data: Default::default(),
            value: Default::default(),
            last_word: Default::default(),
            first_counter_word: Constant::new((HEADER_WORDS as u64).into()),
            last_word_over_ports: Constant::new(
                ((HEADER_WORDS + BOX_COUNTER_WORDS - 1) as u64).into(),
            ),
            block_start: Default::default(),
            in_block: Default::default(),
            at_block: Default::default(),
            box_counter_word: Default::default(),
            header_word: Default::default(),
            word_from_memory: Default::default(),
            word_from_box_counters: Default::default(),
            page_last_word: Default::default(),
        }
    }
}

impl Logic for StatusWords {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            block_start,
            in_block,
            at_block,
            box_counter_word,
            header_word,
            word_from_memory,
            word_from_box_counters,
            page_last_word
        );
        // (by the word's low two bits alone: from word 4 on a counter is taken instead)
        self.header_word.d.next = bit_cast::<32, 7>(self.first_port.val()) << 24;
        if self.word.val().get_bits::<2>(0) == 0 {
            self.header_word.d.next = self.boot_id.val();
        } else if self.word.val().get_bits::<2>(0) == 1 {
            self.header_word.d.next = self.datagrams_sent.val();
        } else if self.word.val().get_bits::<2>(0) == 2 {
            self.header_word.d.next = self.records_sent.val();
        }
        // the box counter block after the port blocks: the link word, then the receive
        // side's counters (from the box counter file)
        self.block_start.d.next =
            (bit_cast::<9, 7>(self.page_ports.val()) << 3) + self.first_counter_word.val();
        self.in_block.d.next = self.word.val() >= self.block_start.q.val();
        self.at_block.d.next = self.word.val() == self.block_start.q.val();
        if self.in_block.q.val() {
            self.header_word.d.next = 0.into();
            if self.at_block.q.val() {
                self.header_word.d.next = (bit_cast::<32, 1>(self.link_up.val().into()) << 24)
                    | (bit_cast::<32, 2>(self.link_speed.val()) << 16);
            }
        }
        self.word_from_memory.d.next =
            (self.word.val() >= self.first_counter_word.val()) & !self.in_block.q.val();
        // the block's counters come from the box counter file, read like the port counters
        self.word_from_box_counters.d.next = self.in_block.q.val() & !self.at_block.q.val();
        // (back at the first counter during the link word: no path from the page's start)
        if self.at_block.q.val() {
            self.box_counter_word.d.next = 0.into();
        }
        if self.next_word.val() & self.in_block.q.val() & !self.at_block.q.val() {
            self.box_counter_word.d.next = self.box_counter_word.q.val() + 1;
        }
        self.box_counter_address.next = self.box_counter_word.q.val();
        self.page_last_word.d.next = self.word.val()
            == (bit_cast::<9, 7>(self.page_ports.val()) << 3) + self.last_word_over_ports.val();
        self.last_word.next = self.page_last_word.q.val();
        self.value.next = self.header_word.q.val();
        if self.word_from_memory.q.val() {
            self.value.next = self.counter_data.val();
        }
        if self.word_from_box_counters.q.val() {
            self.value.next = self.box_counter_data.val();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    fn counter(address: u64) -> u64 {
        0xC000_0000 | address
    }

    fn box_counter(address: u64) -> u64 {
        0xB000_0000 | address
    }

    /// Pages of 1, 13 and 32 ports, each word held for seven clocks with the counter
    /// memories answering two clocks after their address: every word's value from its third
    /// clock, the last word flagged, the box counters read in order.
    #[test]
    fn every_word_of_a_page_has_its_value_from_its_third_clock() {
        let mut bench = Bench::new(StatusWords::default(), |b| &mut b.clock);
        for (first_port, page_ports) in [(0u64, 32u64), (32, 13), (5, 1)] {
            let u = &mut bench.uut;
            u.first_port.next = first_port.into();
            u.page_ports.next = page_ports.into();
            u.boot_id.next = 0x1234_5678.into();
            u.datagrams_sent.next = 77.into();
            u.records_sent.next = 4242.into();
            u.link_up.next = true;
            u.link_speed.next = 2.into();
            u.word.next = 0.into();
            u.next_word.next = false;
            bench.cycle();
            let words = HEADER_WORDS as u64 + 8 * page_ports + BOX_COUNTER_WORDS as u64;
            let block = HEADER_WORDS as u64 + 8 * page_ports;
            // the box counter addresses of the last two clocks: the file answers two late
            let mut box_reads = [0u64; 2];
            for word in 0..words {
                for clock in 0..7 {
                    let u = &mut bench.uut;
                    u.word.next = word.into();
                    u.next_word.next = clock == 6;
                    // the port counter at the word's address, two clocks late
                    u.counter_data.next = counter(if clock >= 2 { word } else { 0 }).into();
                    u.box_counter_data.next = box_counter(box_reads[1]).into();
                    bench.settle();
                    let u = &bench.uut;
                    if clock >= 2 {
                        let expected = match word {
                            0 => 0x1234_5678,
                            1 => 77,
                            2 => 4242,
                            3 => first_port << 24,
                            w if w < block => counter(w),
                            w if w == block => 1 << 24 | 2 << 16,
                            w => box_counter(w - block - 1),
                        };
                        assert_eq!(
                            u.value.val().to_u64(),
                            expected,
                            "page {first_port}+{page_ports}, word {word}, clock {clock}"
                        );
                    }
                    if clock >= 1 {
                        assert_eq!(u.last_word.val(), word == words - 1, "word {word}");
                    }
                    box_reads = [u.box_counter_address.val().to_u64(), box_reads[0]];
                    bench.cycle();
                }
            }
        }
    }
}
