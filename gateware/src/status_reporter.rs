//! StatusReporter: builds the status datagrams, so the host sees every drop and reset.
//!
//! Right after reset (once the counters are cleared) and then every `status_period_ticks`
//! it writes a status body into its own 2 KB memory: boot id, records datagrams and
//! records sent, first port, then the eight counters of up to 32 ports (one datagram per
//! 32 ports), then the box counter block (`skinbox_protocol::box_counters`, header flag
//! `FLAG_BOX_COUNTERS`): the link state from `link_up` and `link_speed`, and the receive
//! side's counters, read from the box counter file like the port counters. It sums the body's 16-bit words while writing, offers the datagram's
//! descriptor on `datagrams`, streams the body from its memory once the descriptor was
//! taken ([`BodyReader`]), and after the last body byte was taken goes on with the next
//! ports or waits for the next period. Building a page of 32 ports takes 1,960 clocks
//! (seven per word: the counter memory's output is registered twice before it is summed).
//!
//! The boot id is a seed parameter plus the number of resets since configuration, so
//! each reset is visible; a power cycle restarts the count (the host also sees the
//! sequence number restart at 0).

use crate::block_ram::BlockRam;
use crate::body_reader::BodyReader;
use crate::hdl::*;
use crate::stream::DatagramSource;
use skinbox_protocol::box_counters::BOX_COUNTERS_LEN;
use skinbox_protocol::datagram::{DatagramKind, FLAG_BOX_COUNTERS, FLAG_TIME_SYNCS};

/// Words of a page before the port counters: boot id, datagrams, records, first port.
pub const HEADER_WORDS: usize = 4;
/// Words of the box counter block after the port counters.
pub const BOX_COUNTER_WORDS: usize = BOX_COUNTERS_LEN / 4;

/// Clocks per 32-bit word of the status body: the address, the memory read, its register,
/// the word into the shift register, four bytes out.
pub const CLOCKS_PER_WORD: u64 = 7;

/// Clock of a word (from its first) in which the batcher's counts are taken (into a register
/// the word's value is loaded from a clock later); counters come from the memory, read at
/// the address of the word's first clock.
pub const WORD_VALUE_CLOCK: u64 = 1;

/// Ports per status datagram.
pub const PORTS_PER_STATUS: usize = 32;

/// Periodic status datagram builder.
#[derive(LogicBlock)]
pub struct StatusReporter {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Box time.
    pub tick: Signal<In, Bits<64>>,
    /// The box sends its own time syncs: a report started now has `FLAG_TIME_SYNCS`.
    pub time_syncs: Signal<In, Bit>,
    /// Records datagrams sent since reset.
    pub datagrams_sent: Signal<In, Bits<32>>,
    /// Records sent since reset.
    pub records_sent: Signal<In, Bits<32>>,
    /// The counter file finished clearing.
    pub counters_ready: Signal<In, Bit>,
    /// Counter to read: port * 8 + counter.
    pub counter_address: Signal<Out, Bits<9>>,
    /// The counter, two clocks after its address.
    pub counter_data: Signal<In, Bits<32>>,
    /// The PHY reports the link up (the board's MDIO master; low without a PHY).
    pub link_up: Signal<In, Bit>,
    /// The link's speed: 0 = 10, 1 = 100, 2 = 1000 Mbit/s, 3 = unknown.
    pub link_speed: Signal<In, Bits<2>>,
    /// Box counter to read (`skinbox_protocol::box_counters::BoxCounter` index).
    pub box_counter_address: Signal<Out, Bits<5>>,
    /// The box counter, two clocks after its address.
    pub box_counter_data: Signal<In, Bits<32>>,
    /// Status period in ticks, 1 to 2^32 - 1 (run-time configuration).
    pub status_period_ticks: Signal<In, Bits<32>>,
    /// One clock: the period changed; the next report is due a period from then.
    pub restart_period: Signal<In, Bit>,
    /// One clock: a report is due now (it starts when the reporter waits).
    pub report_now: Signal<In, Bit>,
    /// The status datagrams: base tick the time of the report, one entry per port, the box
    /// counter block after the port blocks.
    pub datagrams: DatagramSource,
    memory: BlockRam<8, 11>,
    reader: BodyReader,
    status_kind: Constant<Bits<8>>,
    box_counters_flag: Constant<Bits<8>>,
    time_syncs_flag: Constant<Bits<8>>,
    // the page's first counter word, and its last word less 8 per port
    first_counter_word: Constant<Bits<9>>,
    last_word_over_ports: Constant<Bits<9>>,
    // the box counter block's first word; the word is in the block, at its first word
    block_start: DFF<Bits<9>>,
    in_block: DFF<Bit>,
    at_block: DFF<Bit>,
    // the box counter of the block's next counter word, stepped with `word` in the block
    box_counter_word: DFF<Bits<5>>,
    word_from_box_counters: DFF<Bit>,
    ports: Constant<Bits<7>>,
    ports_per_page: Constant<Bits<7>>,
    boot_seed: Constant<Bits<32>>,
    timer: DFF<Bits<32>>,
    // timer == 0, kept in a register
    timer_zero: DFF<Bit>,
    due: DFF<Bit>,
    state: DFF<ReportState>,
    // state == Request, kept in a register (the descriptor's `valid`)
    requesting: DFF<Bit>,
    first_port: DFF<Bits<7>>,
    page_ports: DFF<Bits<7>>,
    word: DFF<Bits<9>>,
    // `word` is the page's last (registered: a word holds for seven clocks)
    last_word: DFF<Bit>,
    // the counter of word `word` (from word 4 on): first_port * 8 + word - 4, stepped with
    // `word` (no adder in front of the memory's address)
    counter_word: DFF<Bits<9>>,
    phase: DFF<Bits<3>>,
    shift: DFF<Bits<32>>,
    offset: DFF<Bits<11>>,
    sum: DFF<Bits<32>>,
    tick_held: DFF<Bits<64>>,
    syncs_held: DFF<Bit>,
    resets: DFF<Bits<32>>,
    reset_seen: DFF<Bit>,
    // the value of word 0 to 3 for the current word, and whether it is a counter instead
    // (both registered: the shift register loads from registers only)
    header_word: DFF<Bits<32>>,
    word_from_memory: DFF<Bit>,
    remaining: Signal<Local, Bits<7>>,
    word_value: Signal<Local, Bits<32>>,
    tx_byte: Signal<Local, Bits<8>>,
    // a byte of the page is written (Build, phases 3 to 6), registered a clock ahead
    write: DFF<Bit>,
}

/// What the reporter is doing.
#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
enum ReportState {
    /// Waiting for the next period (the first variant is the reset state).
    Wait,
    /// Setting up a page of ports.
    Start,
    /// Writing the body.
    Build,
    /// Offering the descriptor.
    Request,
    /// The body streams out.
    Sending,
}

impl StatusReporter {
    /// A reporter for `ports` ports (1 to 64), one report every `status_period_ticks` (its
    /// input), with boot ids counting from `boot_seed`.
    pub fn new(ports: usize, boot_seed: u32) -> Self {
        assert!(
            (1..=64).contains(&ports),
            "StatusReporter: {ports} ports, must be 1 to 64"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            tick: Default::default(),
            datagrams_sent: Default::default(),
            records_sent: Default::default(),
            counters_ready: Default::default(),
            counter_address: Default::default(),
            counter_data: Default::default(),
            link_up: Default::default(),
            link_speed: Default::default(),
            box_counter_address: Default::default(),
            box_counter_data: Default::default(),
            status_period_ticks: Default::default(),
            restart_period: Default::default(),
            report_now: Default::default(),
            datagrams: Default::default(),
            memory: Default::default(),
            reader: Default::default(),
            status_kind: Constant::new((DatagramKind::Status as u64).into()),
            box_counters_flag: Constant::new(u64::from(FLAG_BOX_COUNTERS).into()),
            time_syncs_flag: Constant::new(u64::from(FLAG_TIME_SYNCS).into()),
            first_counter_word: Constant::new((HEADER_WORDS as u64).into()),
            last_word_over_ports: Constant::new(
                ((HEADER_WORDS + BOX_COUNTER_WORDS - 1) as u64).into(),
            ),
            block_start: Default::default(),
            in_block: Default::default(),
            at_block: Default::default(),
            box_counter_word: Default::default(),
            word_from_box_counters: Default::default(),
            ports: Constant::new((ports as u64).into()),
            ports_per_page: Constant::new((PORTS_PER_STATUS as u64).into()),
            boot_seed: Constant::new(u64::from(boot_seed).into()),
            timer: Default::default(),
            timer_zero: Default::default(),
            due: Default::default(),
            state: Default::default(),
            requesting: Default::default(),
            first_port: Default::default(),
            page_ports: Default::default(),
            word: Default::default(),
            last_word: Default::default(),
            counter_word: Default::default(),
            phase: Default::default(),
            shift: Default::default(),
            offset: Default::default(),
            sum: Default::default(),
            tick_held: Default::default(),
            syncs_held: Default::default(),
            time_syncs: Default::default(),
            resets: Default::default(),
            reset_seen: Default::default(),
            header_word: Default::default(),
            word_from_memory: Default::default(),
            remaining: Default::default(),
            word_value: Default::default(),
            tx_byte: Default::default(),
            write: Default::default(),
        }
    }
}

// Words of a page: 0 boot id, 1 datagrams sent, 2 records sent, 3 first port and reserved,
// 4.. the counters (port-major). Each word takes seven clocks (CLOCKS_PER_WORD): address,
// memory read, its register, the value into the shift register, then four bytes.
impl Logic for StatusReporter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            timer,
            write,
            timer_zero,
            due,
            state,
            requesting,
            first_port,
            page_ports,
            word,
            last_word,
            counter_word,
            phase,
            shift,
            offset,
            sum,
            tick_held,
            syncs_held,
            resets,
            reset_seen,
            header_word,
            word_from_memory,
            block_start,
            in_block,
            at_block,
            box_counter_word,
            word_from_box_counters
        );
        self.memory.clock.next = self.clock.val();
        self.reader.clock.next = self.clock.val();
        self.reader.reset.next = self.reset.val();
        self.memory.read_address.next = self.reader.read_address.val();
        self.reader.read_data.next = self.memory.read_data.val();
        self.reader.start.next = self.requesting.q.val() & self.datagrams.ready.val();
        if self.requesting.q.val() & self.datagrams.ready.val() {
            self.requesting.d.next = false;
        }
        self.reader.length.next = self.offset.q.val();
        self.datagrams.body.valid.next = self.reader.body.valid.val();
        self.datagrams.body.data.next = self.reader.body.data.val();
        self.datagrams.body.last.next = self.reader.body.last.val();
        self.datagrams.body.error.next = self.reader.body.error.val();
        self.reader.body.ready.next = self.datagrams.body.ready.val();

        // A report is due every period, counted from report start to report start; one
        // that comes due while the previous is still going starts right after it.
        if self.timer_zero.q.val() {
            self.timer.d.next = self.status_period_ticks.val() - 1;
            self.timer_zero.d.next = self.status_period_ticks.val() == 1;
            self.due.d.next = true;
        } else {
            self.timer.d.next = self.timer.q.val() - 1;
            self.timer_zero.d.next = self.timer.q.val() == 1;
        }
        // a new period counts from its change; a report asked for now is due now
        if self.restart_period.val() {
            self.timer.d.next = self.status_period_ticks.val() - 1;
            self.timer_zero.d.next = self.status_period_ticks.val() == 1;
        }

        self.remaining.next = self.ports.val() - self.first_port.q.val();
        // (in Build the phase steps from 2..=5 to 3..=6 and the state stays)
        self.write.d.next = (self.state.q.val() == ReportState::Build)
            & (self.phase.q.val().get_bit(2) != self.phase.q.val().get_bit(1));
        self.counter_address.next = self.counter_word.q.val();
        // the counter memory answers two clocks after the address (its output register)
        // (by the word's low two bits alone: from word 4 on the counter is taken instead)
        self.header_word.d.next = bit_cast::<32, 7>(self.first_port.q.val()) << 24;
        if self.word.q.val().get_bits::<2>(0) == 0 {
            self.header_word.d.next = self.boot_seed.val() + self.resets.q.val();
        } else if self.word.q.val().get_bits::<2>(0) == 1 {
            self.header_word.d.next = self.datagrams_sent.val();
        } else if self.word.q.val().get_bits::<2>(0) == 2 {
            self.header_word.d.next = self.records_sent.val();
        }
        // the box counter block after the port blocks: the link word, then the receive
        // side's counters (from the box counter file)
        self.block_start.d.next =
            (bit_cast::<9, 7>(self.page_ports.q.val()) << 3) + self.first_counter_word.val();
        // (the word's tests against the block are registered: a word holds for seven
        // clocks and its value is taken from its second on)
        self.in_block.d.next = self.word.q.val() >= self.block_start.q.val();
        self.at_block.d.next = self.word.q.val() == self.block_start.q.val();
        if self.in_block.q.val() {
            self.header_word.d.next = 0.into();
            if self.at_block.q.val() {
                self.header_word.d.next = (bit_cast::<32, 1>(self.link_up.val().into()) << 24)
                    | (bit_cast::<32, 2>(self.link_speed.val()) << 16);
            }
        }
        self.word_from_memory.d.next =
            (self.word.q.val() >= self.first_counter_word.val()) & !self.in_block.q.val();
        // the block's counters come from the box counter file, read like the port counters
        self.word_from_box_counters.d.next = self.in_block.q.val() & !self.at_block.q.val();
        self.box_counter_address.next = self.box_counter_word.q.val();
        self.last_word.d.next = self.word.q.val()
            == (bit_cast::<9, 7>(self.page_ports.q.val()) << 3) + self.last_word_over_ports.val();
        self.word_value.next = self.header_word.q.val();
        if self.word_from_memory.q.val() {
            self.word_value.next = self.counter_data.val();
        }
        if self.word_from_box_counters.q.val() {
            self.word_value.next = self.box_counter_data.val();
        }
        self.tx_byte.next = self.shift.q.val().get_bits::<8>(24);

        match self.state.q.val() {
            ReportState::Wait => {
                if self.due.q.val() & self.counters_ready.val() {
                    self.due.d.next = false;
                    self.first_port.d.next = 0.into();
                    self.state.d.next = ReportState::Start;
                }
            }
            ReportState::Start => {
                self.state.d.next = ReportState::Build;
                self.word.d.next = 0.into();
                self.counter_word.d.next = (bit_cast::<9, 7>(self.first_port.q.val()) << 3) - 4;
                self.box_counter_word.d.next = 0.into();
                self.phase.d.next = 0.into();
                self.offset.d.next = 0.into();
                self.sum.d.next = 0.into();
                self.tick_held.d.next = self.tick.val();
                self.syncs_held.d.next = self.time_syncs.val();
                self.page_ports.d.next = self.ports_per_page.val();
                if self.remaining.val() < self.ports_per_page.val() {
                    self.page_ports.d.next = self.remaining.val();
                }
            }
            ReportState::Build => {
                self.phase.d.next = self.phase.q.val() + 1;
                if self.phase.q.val() == 2 {
                    self.shift.d.next = self.word_value.val();
                } else if self.phase.q.val() >= 3 {
                    self.shift.d.next = self.shift.q.val() << 8;
                }
                if self.phase.q.val() == 6 {
                    self.phase.d.next = 0.into();
                    self.word.d.next = self.word.q.val() + 1;
                    self.counter_word.d.next = self.counter_word.q.val() + 1;
                    if self.in_block.q.val() & !self.at_block.q.val() {
                        self.box_counter_word.d.next = self.box_counter_word.q.val() + 1;
                    }
                    if self.last_word.q.val() {
                        self.state.d.next = ReportState::Request;
                        self.requesting.d.next = true;
                    }
                }
            }
            ReportState::Request => {
                // taken a clock ago (the state's enable comes from a register, not from
                // the arbiter's grant; the reader is busy from the clock after the take)
                if !self.requesting.q.val() {
                    self.state.d.next = ReportState::Sending;
                }
            }
            ReportState::Sending => {
                // the page was sent: next ports, or wait for the next period
                if !self.reader.busy.val() {
                    self.first_port.d.next = self.first_port.q.val() + self.page_ports.q.val();
                    if self.first_port.q.val() + self.page_ports.q.val() == self.ports.val() {
                        self.state.d.next = ReportState::Wait;
                    } else {
                        self.state.d.next = ReportState::Start;
                    }
                }
            }
        }

        // (after the state machine: a report asked for in the clock Wait takes the last due
        // one is due again)
        if self.report_now.val() {
            self.due.d.next = true;
        }

        self.memory.write_enable.next = self.write.q.val();
        self.memory.write_address.next = self.offset.q.val();
        self.memory.write_data.next = self.tx_byte.val();
        if self.write.q.val() {
            self.offset.d.next = self.offset.q.val() + 1;
            if self.offset.q.val().get_bit(0) {
                self.sum.d.next = self.sum.q.val() + bit_cast::<32, 8>(self.tx_byte.val());
            } else {
                self.sum.d.next = self.sum.q.val() + (bit_cast::<32, 8>(self.tx_byte.val()) << 8);
            }
        }

        self.datagrams.valid.next = self.requesting.q.val();
        self.datagrams.kind.next = self.status_kind.val();
        self.datagrams.flags.next = self.box_counters_flag.val();
        if self.syncs_held.q.val() {
            self.datagrams.flags.next = self.box_counters_flag.val() | self.time_syncs_flag.val();
        }
        self.datagrams.entry_count.next = bit_cast::<16, 7>(self.page_ports.q.val());
        self.datagrams.base_tick.next = self.tick_held.q.val();
        self.datagrams.body_len.next = self.offset.q.val();
        self.datagrams.body_sum.next = self.sum.q.val();

        self.reset_seen.d.next = self.reset.val();
        if self.reset.val() {
            self.state.d.next = ReportState::Wait;
            self.requesting.d.next = false;
            self.write.d.next = false;
            self.timer.d.next = 0.into();
            self.timer_zero.d.next = true;
            self.due.d.next = false;
            if !self.reset_seen.q.val() {
                self.resets.d.next = self.resets.q.val() + 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame_transmitter::word_sum;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::box_counters::LinkSpeed;
    use skinbox_protocol::datagram::DatagramBody;
    use skinbox_protocol::{BoxCounters, DatagramRepr, PortCounters, StatusRepr};

    fn counter(port: usize, c: usize) -> u32 {
        (port as u32) << 16 | (c as u32) << 8 | 0x5A
    }

    /// A page as it was sent: (its base tick, entries, body, sum).
    type Page = (u64, u16, Vec<u8>, u64);

    /// Runs the reporter; its descriptors are taken a few clocks after they are offered and
    /// its bodies read with random backpressure (`last` checked on every beat).
    fn box_counter(c: usize) -> u32 {
        0xB0C0_0000 | ((c as u32) * 3)
    }

    fn run(ports: usize, period: u64, clocks: u64) -> Vec<Page> {
        run_with(ports, period, clocks, |_, _| {})
    }

    /// As [`run`], calling `drive(clock, reporter)` before every clock's settle (for the
    /// period and report-now inputs).
    fn run_with(
        ports: usize,
        period: u64,
        clocks: u64,
        mut drive: impl FnMut(u64, &mut StatusReporter),
    ) -> Vec<Page> {
        let mut bench = Bench::new(StatusReporter::new(ports, 0x1000), |b| &mut b.clock);
        bench.uut.status_period_ticks.next = period.into();
        let mut rng = TestRng::new(ports as u64);
        bench.uut.reset.next = true;
        bench.cycles(3);
        bench.uut.reset.next = false;
        let mut pages = vec![];
        // the counter addresses of the last two clocks: the counter file answers two late
        let mut counter_reads = [0usize; 2];
        let mut box_counter_reads = [0usize; 2];
        let mut reading: Option<(u64, u16, u64, u64, Vec<u8>)> = None;
        for clock in 0..clocks {
            let take_descriptor = rng.chance(0.3);
            let take_body = rng.chance(0.6);
            let u = &mut bench.uut;
            u.tick.next = clock.into();
            u.datagrams_sent.next = 77.into();
            u.records_sent.next = 4242.into();
            u.counters_ready.next = true;
            // the link comes up at 1000 Mbit/s after 9,000 clocks
            u.link_up.next = clock >= 9_000;
            u.link_speed.next = if clock >= 9_000 { 2 } else { 3 }.into();
            let read = counter_reads[1];
            u.counter_data.next = u64::from(counter(read / 8, read % 8)).into();
            u.box_counter_data.next = u64::from(box_counter(box_counter_reads[1])).into();
            u.restart_period.next = false;
            u.report_now.next = false;
            drive(clock, u);
            u.datagrams.ready.next = take_descriptor && reading.is_none();
            u.datagrams.body.ready.next = take_body;
            bench.settle();
            let u = &bench.uut;
            counter_reads = [u.counter_address.val().index(), counter_reads[0]];
            box_counter_reads = [u.box_counter_address.val().index(), box_counter_reads[0]];
            if let Some((_, _, len, _, body)) = &mut reading {
                assert!(!u.datagrams.valid.val(), "one datagram at a time");
                if take_body && u.datagrams.body.valid.val() {
                    body.push(u.datagrams.body.data.val().to_u8());
                    assert_eq!(u.datagrams.body.last.val(), body.len() as u64 == *len);
                    if body.len() as u64 == *len {
                        let (at, n, _, sum, body) = reading.take().unwrap();
                        pages.push((at, n, body, sum));
                    }
                }
            } else {
                assert!(
                    !u.datagrams.body.valid.val(),
                    "no body before its descriptor"
                );
                if u.datagrams.valid.val() && take_descriptor {
                    assert_eq!(u.datagrams.kind.val().to_u8(), DatagramKind::Status as u8);
                    assert_eq!(u.datagrams.flags.val().to_u8(), FLAG_BOX_COUNTERS);
                    reading = Some((
                        u.datagrams.base_tick.val().to_u64(),
                        u.datagrams.entry_count.val().to_u16(),
                        u.datagrams.body_len.val().to_u64(),
                        u.datagrams.body_sum.val().to_u64(),
                        vec![],
                    ));
                }
            }
            bench.cycle();
        }
        pages
    }

    /// The page as a status datagram: its status and its box counter block.
    fn parse(ports: usize, page: &Page) -> (StatusRepr, BoxCounters) {
        let mut header = DatagramRepr {
            box_id: 1,
            port_count: ports as u8,
            flags: FLAG_BOX_COUNTERS,
            sequence: 0,
            base_tick: 0,
            body: DatagramBody::Status(StatusRepr {
                ports: vec![PortCounters::default(); usize::from(page.1)],
                ..Default::default()
            }),
        }
        .to_bytes();
        header.truncate(24);
        header[skinbox_protocol::datagram::field::FLAGS] = FLAG_BOX_COUNTERS;
        header.extend(&page.2);
        let (d, block) = DatagramRepr::parse_box_counters(&header).unwrap();
        match d.body {
            DatagramBody::Status(s) => (s, block.expect("the box counter block")),
            DatagramBody::Records(_) => unreachable!(),
        }
    }

    #[test]
    fn reports_every_counter_of_40_ports_in_two_pages_every_period() {
        let period = 8_000;
        let pages = run(40, period, 2 * period + 6_000);
        assert_eq!(
            pages.len(),
            6,
            "two pages at reset, after one and two periods"
        );
        for (i, page) in pages.iter().enumerate() {
            let (status, block) = parse(40, page);
            // the link came up after the first period's pages were written, before the
            // second period's first page reached its block (about 1,800 clocks in)
            let up = i >= 2;
            assert_eq!(block.link_up, up, "page {i}");
            let speed = if up {
                LinkSpeed::Mbit1000
            } else {
                LinkSpeed::Unknown
            };
            assert_eq!(block.link_speed, speed, "page {i}");
            let expected: Vec<u32> = (0..block.counts.len()).map(box_counter).collect();
            assert_eq!(block.counts.to_vec(), expected, "box counters of page {i}");
            let first = if i % 2 == 0 { 0 } else { 32 };
            assert_eq!(usize::from(status.first_port), first, "page {i}");
            assert_eq!(status.ports.len(), if i % 2 == 0 { 32 } else { 8 });
            assert_eq!(status.boot_id, 0x1001, "seed + one reset");
            assert_eq!((status.datagrams_sent, status.records_sent), (77, 4242));
            for (k, p) in status.ports.iter().enumerate() {
                let expected: Vec<u32> = (0..8).map(|c| counter(first + k, c)).collect();
                assert_eq!(p.0.to_vec(), expected, "page {i} port {}", first + k);
            }
            assert_eq!(page.3, word_sum(&page.2), "body sum of page {i}");
        }
        // one report per period
        assert!(
            pages[2].0 >= period && pages[2].0 < period + 2_000,
            "{}",
            pages[2].0
        );
        assert_eq!(
            pages[4].0 - pages[2].0,
            period,
            "reports start one period apart"
        );
    }

    #[test]
    fn a_single_port_box_reports_one_block() {
        let pages = run(1, 100_000, 3_000);
        assert_eq!(pages.len(), 1);
        let (status, _) = parse(1, &pages[0]);
        assert_eq!(
            status.ports,
            vec![PortCounters(
                [0, 1, 2, 3, 4, 5, 6, 7].map(|c| counter(0, c))
            )]
        );
    }

    #[test]
    fn report_now_and_a_new_period_move_the_reports() {
        // period 8,000; a report asked for at clock 3,000; at 12,000 the period becomes
        // 5,000, counted from then
        let pages = run_with(8, 8_000, 25_000, |clock, u| {
            if clock == 3_000 {
                u.report_now.next = true;
            }
            if clock >= 12_000 {
                u.status_period_ticks.next = 5_000.into();
            }
            if clock == 12_000 {
                u.restart_period.next = true;
            }
        });
        let ticks: Vec<u64> = pages.iter().map(|p| p.0).collect();
        let expected = [0, 3_000, 8_000, 17_000, 22_000];
        assert_eq!(ticks.len(), expected.len(), "report ticks {ticks:?}");
        for (t, e) in ticks.iter().zip(expected) {
            assert!(
                (e..e + 4).contains(t),
                "report ticks {ticks:?}, expected about {expected:?}"
            );
        }
    }
}
