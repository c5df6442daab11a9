//! ReplySequencer: the reply builder's phases and its program ROM: idle until a `start_*`,
//! building (one ROM word per clock from the reply's program), offering the descriptor,
//! and for an acknowledgement patching (the patch program from the take on).
//!
//! A start is accepted while idle, no ROM word is in flight and the body reader is not
//! busy (`starting`); the step register then holds the program's first address (ARP,
//! echo, or one of the three acknowledgements by the accepted command). A word is valid
//! two clocks after its address (`word_valid`, the ROM's read latency); the end marker
//! (bit 30) stops the program and drops the two words read after it: a build goes on to
//! offer the descriptor, the patch back to idle. The take (`offering & ready`) is
//! registered (`took`: the arbiter's grant reaches one flip-flop); in that clock the offer
//! ends, and an acknowledgement's patch starts (`patch_starts`).
//!
//! Latency: the first word of a program is valid [`START_TO_WORD`] clocks after the start.
//! Cost: one DP16KD (the ROM), the 10-bit step, the two phase bits, the two word flags, the
//! acknowledgement flag and the registered take.

use crate::block_ram::{BlockRam, READ_LATENCY};
use crate::hdl::*;

/// Bits of a ROM word (a step of a program).
pub const STEP_BITS: usize = 35;
/// Address bits of the program ROM.
pub const ROM_ADDRESS_BITS: usize = 10;

/// Clocks from a `start_*` to the first step's ROM word (the step register, the ROM's
/// two-clock read).
pub const START_TO_WORD: u64 = 1 + READ_LATENCY;

/// The builder's phase.
#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
pub enum ReplyPhase {
    /// No reply under way (the reset state).
    Idle,
    /// The reply's program runs.
    Building,
    /// The descriptor is offered.
    Offering,
    /// An acknowledgement's patch program runs (send tick, UDP checksum).
    Patching,
}

/// The ROM's start addresses of the programs.
#[derive(Debug, Clone, Copy)]
pub struct ProgramStarts {
    /// ARP reply.
    pub arp: usize,
    /// Echo reply.
    pub echo: usize,
    /// Acknowledgement without a reply, with the destination, with the counters.
    pub ack: [usize; 3],
    /// The acknowledgement's patch.
    pub patch: usize,
}

/// The builder's phases and program ROM.
#[derive(LogicBlock)]
pub struct ReplySequencer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: idle.
    pub reset: Signal<In, Bit>,
    /// One clock: build an ARP reply.
    pub start_arp: Signal<In, Bit>,
    /// One clock: build an ICMP echo reply.
    pub start_echo: Signal<In, Bit>,
    /// One clock: build a command acknowledgement.
    pub start_ack: Signal<In, Bit>,
    /// The command was an accepted stream-to.
    pub accepted_stream_to: Signal<In, Bit>,
    /// The command was an accepted status-now.
    pub accepted_status_now: Signal<In, Bit>,
    /// The body reader is busy with the previous reply.
    pub reader_busy: Signal<In, Bit>,
    /// The descriptor's `ready`.
    pub ready: Signal<In, Bit>,
    /// A start is accepted in this clock.
    pub starting: Signal<Out, Bit>,
    /// The ROM word.
    pub word: Signal<Out, Bits<STEP_BITS>>,
    /// The ROM word is a step of the running program.
    pub word_valid: Signal<Out, Bit>,
    /// The descriptor is offered.
    pub offering: Signal<Out, Bit>,
    /// The descriptor was taken at the last edge.
    pub took: Signal<Out, Bit>,
    /// The descriptor was taken at the last edge, and the reply is an acknowledgement.
    pub patch_starts: Signal<Out, Bit>,
    rom: BlockRam<STEP_BITS, ROM_ADDRESS_BITS>,
    arp_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    echo_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    ack_none_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    ack_destination_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    ack_counters_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    patch_start: Constant<Bits<ROM_ADDRESS_BITS>>,
    step: DFF<Bits<ROM_ADDRESS_BITS>>,
    phase: DFF<ReplyPhase>,
    read_1: DFF<Bit>,
    read_2: DFF<Bit>,
    is_ack: DFF<Bit>,
    taken: DFF<Bit>,
    running: Signal<Local, Bit>,
    idle: Signal<Local, Bit>,
}

impl ReplySequencer {
    /// A sequencer with these ROM words and programs.
    pub fn new(words: &[u64], starts: ProgramStarts) -> Self {
        assert!(
            words.len() <= 1 << ROM_ADDRESS_BITS,
            "{} steps",
            words.len()
        );
        let [ack_none, ack_destination, ack_counters] = starts.ack;
        Self {
            clock: Default::default(),
            reset: Default::default(),
            start_arp: Default::default(),
            start_echo: Default::default(),
            start_ack: Default::default(),
            accepted_stream_to: Default::default(),
            accepted_status_now: Default::default(),
            reader_busy: Default::default(),
            ready: Default::default(),
            starting: Default::default(),
            word: Default::default(),
            word_valid: Default::default(),
            offering: Default::default(),
            took: Default::default(),
            patch_starts: Default::default(),
            rom: BlockRam::with_contents(words),
            arp_start: constant(starts.arp as u64),
            echo_start: constant(starts.echo as u64),
            ack_none_start: constant(ack_none as u64),
            ack_destination_start: constant(ack_destination as u64),
            ack_counters_start: constant(ack_counters as u64),
            patch_start: constant(starts.patch as u64),
            step: Default::default(),
            phase: Default::default(),
            read_1: Default::default(),
            read_2: Default::default(),
            is_ack: Default::default(),
            taken: Default::default(),
            running: Default::default(),
            idle: Default::default(),
        }
    }
}

impl Logic for ReplySequencer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, step, phase, read_1, read_2, is_ack, taken);
        self.rom.clock.next = self.clock.val();
        self.rom.write_enable.next = false;
        self.rom.write_address.next = 0.into();
        self.rom.write_data.next = 0.into();
        self.running.next = (self.phase.q.val() == ReplyPhase::Building)
            | (self.phase.q.val() == ReplyPhase::Patching);
        // One ROM word per clock from `step`; a word is valid two clocks after its address
        // (`read_2`); the end marker stops the program and drops the two words read after
        // it: a build ends with the descriptor, the patch with nothing.
        self.rom.read_address.next = self.step.q.val();
        self.read_1.d.next = self.running.val();
        self.read_2.d.next = self.read_1.q.val();
        if self.running.val() {
            self.step.d.next = self.step.q.val() + 1;
        }
        if self.read_2.q.val() & self.rom.read_data.val().get_bit(30) {
            self.read_1.d.next = false;
            self.read_2.d.next = false;
            if self.phase.q.val() == ReplyPhase::Patching {
                self.phase.d.next = ReplyPhase::Idle;
            } else {
                self.phase.d.next = ReplyPhase::Offering;
            }
        }
        // Starts: only when no reply is under way.
        self.idle.next = (self.phase.q.val() == ReplyPhase::Idle)
            & !self.read_2.q.val()
            & !self.reader_busy.val();
        self.starting.next =
            self.idle.val() & (self.start_arp.val() | self.start_echo.val() | self.start_ack.val());
        if self.starting.val() {
            self.phase.d.next = ReplyPhase::Building;
            self.is_ack.d.next = self.start_ack.val();
            if self.start_arp.val() {
                self.step.d.next = self.arp_start.val();
            } else if self.start_echo.val() {
                self.step.d.next = self.echo_start.val();
            } else if self.accepted_stream_to.val() {
                self.step.d.next = self.ack_destination_start.val();
            } else if self.accepted_status_now.val() {
                self.step.d.next = self.ack_counters_start.val();
            } else {
                self.step.d.next = self.ack_none_start.val();
            }
        }
        // the take is registered first; the offer ends a clock later, and an
        // acknowledgement's patch starts
        self.offering.next = self.phase.q.val() == ReplyPhase::Offering;
        self.taken.d.next = self.offering.val() & self.ready.val();
        if self.taken.q.val() {
            self.phase.d.next = ReplyPhase::Idle;
            if self.is_ack.q.val() {
                self.phase.d.next = ReplyPhase::Patching;
                self.step.d.next = self.patch_start.val();
            }
        }
        if self.reset.val() {
            self.phase.d.next = ReplyPhase::Idle;
            self.read_1.d.next = false;
            self.read_2.d.next = false;
            self.is_ack.d.next = false;
            self.taken.d.next = false;
        }
        self.word.next = self.rom.read_data.val();
        self.word_valid.next = self.read_2.q.val();
        self.took.next = self.taken.q.val();
        self.patch_starts.next = self.taken.q.val() & self.is_ack.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    const END: u64 = 1 << 30;

    /// Programs of numbered words: each start runs its program's words in order, one per
    /// clock from [`START_TO_WORD`] clocks after the start, and its end marker, then offers
    /// the descriptor; an
    /// acknowledgement's take runs the patch; a start while a reply is under way is
    /// ignored.
    #[test]
    fn each_start_runs_its_program_then_offers() {
        // program k at 10 k: words 10 k + 1 .. 10 k + 1 + len, then the end marker
        let lens = [3usize, 5, 1, 4, 6, 2];
        let mut words = vec![0; 60];
        for (k, &len) in lens.iter().enumerate() {
            for i in 0..len {
                words[10 * k + i] = (100 * k + i) as u64;
            }
            words[10 * k + len] = END;
        }
        let starts = ProgramStarts {
            arp: 0,
            echo: 10,
            ack: [20, 30, 40],
            patch: 50,
        };
        let mut bench = Bench::new(ReplySequencer::new(&words, starts), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        // (kind, accepted stream-to, accepted status-now) -> program
        let cases = [
            (0, false, false, 0),
            (1, false, false, 1),
            (2, false, false, 2),
            (2, true, false, 3),
            (2, false, true, 4),
        ];
        for (kind, stream_to, status_now, program) in cases {
            let u = &mut bench.uut;
            u.start_arp.next = kind == 0;
            u.start_echo.next = kind == 1;
            u.start_ack.next = kind == 2;
            u.accepted_stream_to.next = stream_to;
            u.accepted_status_now.next = status_now;
            bench.settle();
            assert!(bench.uut.starting.val(), "program {program}");
            bench.cycle();
            let mut seen = vec![];
            let mut clock = 1;
            // a second start is ignored while the program runs
            while !bench.uut.offering.val() {
                bench.settle();
                assert!(!bench.uut.starting.val());
                if bench.uut.word_valid.val() {
                    seen.push((clock, bench.uut.word.val().to_u64()));
                }
                bench.cycle();
                bench.uut.start_arp.next = false;
                bench.uut.start_echo.next = false;
                bench.uut.start_ack.next = false;
                clock += 1;
                assert!(clock < 20);
            }
            // the words and the end marker, a step that writes nothing
            let want: Vec<(u64, u64)> = (0..lens[program])
                .map(|i| (START_TO_WORD + i as u64, (100 * program + i) as u64))
                .chain([(START_TO_WORD + lens[program] as u64, END)])
                .collect();
            assert_eq!(seen, want, "program {program}");
            // offered until a clock after the take
            bench.cycles(3);
            assert!(bench.uut.offering.val());
            bench.uut.ready.next = true;
            bench.cycle();
            bench.uut.ready.next = false;
            let u = &bench.uut;
            assert!(u.took.val() && u.offering.val());
            assert_eq!(u.patch_starts.val(), kind == 2);
            bench.cycle();
            assert!(!bench.uut.offering.val());
            let mut patch = vec![];
            for _ in 0..10 {
                if bench.uut.word_valid.val() {
                    patch.push(bench.uut.word.val().to_u64());
                }
                bench.cycle();
            }
            let want: Vec<u64> = if kind == 2 {
                (0..lens[5])
                    .map(|i| (500 + i) as u64)
                    .chain([END])
                    .collect()
            } else {
                vec![]
            };
            assert_eq!(patch, want, "program {program}");
        }
    }
}
