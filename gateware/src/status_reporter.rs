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
//! Its parts are blocks of their own: when a report is due ([`ReportTimer`]), the ports of
//! the page ([`StatusPages`]: the ports left are a register beside the first port, so the
//! page's port count is chosen from registers only), the value of each word
//! ([`StatusWords`]) and the page's write into the memory with its sum
//! ([`StatusPageWriter`]); the reporter's `ReportState` sequences them.
//!
//! The boot id is a seed parameter plus the number of resets since configuration, so
//! each reset is visible; a power cycle restarts the count (the host also sees the
//! sequence number restart at 0).

use crate::block_ram::BlockRam;
use crate::body_reader::BodyReader;
use crate::hdl::*;
use crate::report_timer::ReportTimer;
use crate::status_page_writer::StatusPageWriter;
use crate::status_pages::StatusPages;
use crate::status_words::StatusWords;
use crate::stream::DatagramSource;
use skinbox_protocol::datagram::{DatagramKind, FLAG_BOX_COUNTERS, FLAG_TIME_SYNCS};

pub use crate::status_page_writer::CLOCKS_PER_WORD;
pub use crate::status_pages::PORTS_PER_STATUS;
pub use crate::status_words::{BOX_COUNTER_WORDS, HEADER_WORDS};

/// Clock of a word (from its first) in which the batcher's counts are taken (into a register
/// the word's value is loaded from a clock later); counters come from the memory, read at
/// the address of the word's first clock.
pub const WORD_VALUE_CLOCK: u64 = 1;

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
    report_timer: ReportTimer,
    pages: StatusPages,
    words: StatusWords,
    writer: StatusPageWriter,
    status_kind: Constant<Bits<8>>,
    box_counters_flag: Constant<Bits<8>>,
    time_syncs_flag: Constant<Bits<8>>,
    boot_seed: Constant<Bits<32>>,
    state: DFF<ReportState>,
    // state == Request, kept in a register (the descriptor's `valid`)
    requesting: DFF<Bit>,
    word: DFF<Bits<9>>,
    // the counter of word `word` (from word 4 on): first_port * 8 + word - 4, stepped with
    // `word` (no adder in front of the memory's address)
    counter_word: DFF<Bits<9>>,
    tick_held: DFF<Bits<64>>,
    syncs_held: DFF<Bit>,
    resets: DFF<Bits<32>>,
    reset_seen: DFF<Bit>,
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
            report_timer: Default::default(),
            pages: StatusPages::new(ports),
            words: Default::default(),
            writer: Default::default(),
            status_kind: Constant::new((DatagramKind::Status as u64).into()),
            box_counters_flag: Constant::new(u64::from(FLAG_BOX_COUNTERS).into()),
            time_syncs_flag: Constant::new(u64::from(FLAG_TIME_SYNCS).into()),
            boot_seed: Constant::new(u64::from(boot_seed).into()),
            state: Default::default(),
            requesting: Default::default(),
            word: Default::default(),
            counter_word: Default::default(),
            tick_held: Default::default(),
            syncs_held: Default::default(),
            time_syncs: Default::default(),
            resets: Default::default(),
            reset_seen: Default::default(),
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
            state,
            requesting,
            word,
            counter_word,
            tick_held,
            syncs_held,
            resets,
            reset_seen
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
        self.reader.length.next = self.writer.length.val();
        self.datagrams.body.valid.next = self.reader.body.valid.val();
        self.datagrams.body.data.next = self.reader.body.data.val();
        self.datagrams.body.last.next = self.reader.body.last.val();
        self.datagrams.body.error.next = self.reader.body.error.val();
        self.reader.body.ready.next = self.datagrams.body.ready.val();

        // A report is due every period, counted from report start to report start; one
        // that comes due while the previous is still going starts right after it; a new
        // period counts from its change; a report asked for now is due now.
        self.report_timer.clock.next = self.clock.val();
        self.report_timer.reset.next = self.reset.val();
        self.report_timer.period_ticks.next = self.status_period_ticks.val();
        self.report_timer.restart.next = self.restart_period.val();
        self.report_timer.now.next = self.report_now.val();
        self.report_timer.taken.next = false;

        self.pages.clock.next = self.clock.val();
        self.pages.rewind.next = false;
        self.pages.load.next = self.state.q.val() == ReportState::Start;
        self.pages.advance.next = false;
        self.counter_address.next = self.counter_word.q.val();
        // the counter memory answers two clocks after the address (its output register)
        self.words.clock.next = self.clock.val();
        self.words.next_word.next = self.writer.word_done.val();
        self.words.word.next = self.word.q.val();
        self.words.first_port.next = self.pages.first_port.val();
        self.words.page_ports.next = self.pages.page_ports.val();
        self.words.boot_id.next = self.boot_seed.val() + self.resets.q.val();
        self.words.datagrams_sent.next = self.datagrams_sent.val();
        self.words.records_sent.next = self.records_sent.val();
        self.words.counter_data.next = self.counter_data.val();
        self.words.link_up.next = self.link_up.val();
        self.words.link_speed.next = self.link_speed.val();
        self.box_counter_address.next = self.words.box_counter_address.val();
        self.words.box_counter_data.next = self.box_counter_data.val();
        self.writer.clock.next = self.clock.val();
        self.writer.reset.next = self.reset.val();
        self.writer.start.next = self.state.q.val() == ReportState::Start;
        self.writer.build.next = self.state.q.val() == ReportState::Build;
        self.writer.value.next = self.words.value.val();
        self.memory.write_enable.next = self.writer.memory_write.val();
        self.memory.write_address.next = self.writer.memory_address.val();
        self.memory.write_data.next = self.writer.memory_data.val();

        match self.state.q.val() {
            ReportState::Wait => {
                if self.report_timer.due.val() & self.counters_ready.val() {
                    self.report_timer.taken.next = true;
                    self.pages.rewind.next = true;
                    self.state.d.next = ReportState::Start;
                }
            }
            ReportState::Start => {
                self.state.d.next = ReportState::Build;
                self.word.d.next = 0.into();
                self.counter_word.d.next = (bit_cast::<9, 7>(self.pages.first_port.val()) << 3) - 4;
                self.tick_held.d.next = self.tick.val();
                self.syncs_held.d.next = self.time_syncs.val();
            }
            ReportState::Build => {
                if self.writer.word_done.val() {
                    self.word.d.next = self.word.q.val() + 1;
                    self.counter_word.d.next = self.counter_word.q.val() + 1;
                    if self.words.last_word.val() {
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
                    self.pages.advance.next = true;
                    if self.pages.last_page.val() {
                        self.state.d.next = ReportState::Wait;
                    } else {
                        self.state.d.next = ReportState::Start;
                    }
                }
            }
        }

        self.datagrams.valid.next = self.requesting.q.val();
        self.datagrams.kind.next = self.status_kind.val();
        self.datagrams.flags.next = self.box_counters_flag.val();
        if self.syncs_held.q.val() {
            self.datagrams.flags.next = self.box_counters_flag.val() | self.time_syncs_flag.val();
        }
        self.datagrams.entry_count.next = bit_cast::<16, 7>(self.pages.page_ports.val());
        self.datagrams.base_tick.next = self.tick_held.q.val();
        self.datagrams.body_len.next = self.writer.length.val();
        self.datagrams.body_sum.next = self.writer.body_sum.val();

        self.reset_seen.d.next = self.reset.val();
        if self.reset.val() {
            self.state.d.next = ReportState::Wait;
            self.requesting.d.next = false;
            if !self.reset_seen.q.val() {
                self.resets.d.next = self.resets.q.val() + 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{is_body_sum_of, Bench, TestRng};
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
            assert!(is_body_sum_of(page.3, &page.2), "body sum of page {i}");
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

    /// The reporter's Verilog, with its blocks, passes Verilator's lint with the box's
    /// waivers.
    #[test]
    fn verilog_lints_clean() {
        let mut uut = StatusReporter::new(40, 0x1000);
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir = std::env::temp_dir().join(format!(
            "skinbox-lint-status-reporter-{}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).unwrap_or_else(|e| panic!("{e}"));
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
