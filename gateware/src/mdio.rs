//! MdioMaster: configures the board's Ethernet PHY over MDIO (IEEE 802.3 clause 22) and
//! reads its link state.
//!
//! After its reset (the board top holds it in reset with the PHY) and a start-up wait it
//! writes three registers of the PHY at [`MdioMaster::new`]'s address, each a standard
//! clause 22 register the Broadcom B50612D implements:
//!
//! 1. register 4, auto-negotiation advertisement: [`ADVERTISE_NO_10_100`] (selector field
//!    00001 = IEEE 802.3, bits 5-8 clear: no 10BASE-T or 100BASE-TX ability, no pause);
//! 2. register 9, 1000BASE-T control: [`GIGABIT_CONTROL_FULL_ONLY`] (bit 9 set: 1000BASE-T
//!    full duplex advertised, bit 8 clear: half duplex not);
//! 3. register 0, control: [`CONTROL_RESTART_AN_1000_FULL`] (bit 12 auto-negotiation on, bit
//!    9 restart it, bit 8 full duplex, bits 6 and 13 = 10: 1000 Mbit/s).
//!
//! So the PHY links only with a Gigabit full-duplex partner; a 100 Mbit/s partner gets no
//! link instead of garbage. Then, at once and every `poll_periods` MDC periods after, it
//! reads register
//! 1 (status, bit 2 link status) and the vendor's register 19h (auxiliary status summary,
//! bits 10:8 the auto-negotiation highest common denominator: 111 1000BASE-T full duplex,
//! 110 half, 101 100BASE-TX full, 100 100BASE-T4, 011 100BASE-TX half, 010 10BASE-T full,
//! 001 half, 000 none; the layout of Broadcom's BCM54xx PHYs as U-Boot's
//! `drivers/net/phy/broadcom.c` reads it, `MIIM_BCM54xx_AUXSTATUS` and its link-mode field
//! 0x0700; 100 = 100BASE-T4, which U-Boot does not list, is taken as 100 Mbit/s). The outputs
//! [`MdioMaster::link_up`] and [`MdioMaster::link_speed`] change only after both reads.
//!
//! Timing: MDC is the clock divided by [`MDC_DIVIDER`] (1.95 MHz at 125 MHz, below
//! clause 22's 2.5 MHz), low for the first half of each bit, high for the second. The
//! master changes MDIO as MDC falls, so the PHY, which samples on the rising edge, sees it
//! stable for half a period either side. Read data, which the PHY drives after a rising
//! edge (at most 300 ns later, clause 22), is sampled in the last clock before the next
//! rising edge (504 ns after the previous one). Every frame has a preamble of 32 ones. A
//! read whose turnaround bit reads high was answered by no PHY: then `link_up` is low and
//! `link_speed` [`SPEED_UNKNOWN`].

use crate::hdl::*;

/// Box clocks per MDC period.
pub const MDC_DIVIDER: u64 = 64;

/// Register 0, control: auto-negotiation enabled and restarted, 1000 Mbit/s, full duplex.
pub const CONTROL_RESTART_AN_1000_FULL: u16 = (1 << 12) | (1 << 9) | (1 << 8) | (1 << 6);
/// Register 4, advertisement: IEEE 802.3 selector, no 10/100 ability, no pause.
pub const ADVERTISE_NO_10_100: u16 = 0x0001;
/// Register 9, 1000BASE-T control: 1000BASE-T full duplex advertised, half duplex not.
pub const GIGABIT_CONTROL_FULL_ONLY: u16 = 1 << 9;

/// Clause 22 register numbers used.
pub const REG_CONTROL: u8 = 0;
/// Status register (bit 2: link status).
pub const REG_STATUS: u8 = 1;
/// Auto-negotiation advertisement register.
pub const REG_ADVERTISE: u8 = 4;
/// 1000BASE-T control register.
pub const REG_GIGABIT_CONTROL: u8 = 9;
/// Broadcom auxiliary status summary register (bits 10:8 the negotiated mode).
pub const REG_AUX_STATUS: u8 = 0x19;

/// `link_speed` for 10 Mbit/s.
pub const SPEED_10: u64 = 0;
/// `link_speed` for 100 Mbit/s.
pub const SPEED_100: u64 = 1;
/// `link_speed` for 1000 Mbit/s.
pub const SPEED_1000: u64 = 2;
/// `link_speed` before the first read, when no PHY answered or nothing was negotiated.
pub const SPEED_UNKNOWN: u64 = 3;

/// The writes of the configuration, in order: (register, value).
pub const CONFIGURATION: [(u8, u16); 3] = [
    (REG_ADVERTISE, ADVERTISE_NO_10_100),
    (REG_GIGABIT_CONTROL, GIGABIT_CONTROL_FULL_ONLY),
    (REG_CONTROL, CONTROL_RESTART_AN_1000_FULL),
];

/// The 32 bits after the preamble of a clause 22 frame: start 01, op (01 write, 10 read),
/// PHY address, register address, turnaround 10 (ignored for reads), data.
pub fn frame_word(write: bool, phy: u8, register: u8, data: u16) -> u32 {
    let op: u32 = if write { 0b01 } else { 0b10 };
    (0b01 << 30)
        | (op << 28)
        | (u32::from(phy & 31) << 23)
        | (u32::from(register & 31) << 18)
        | (0b10 << 16)
        | u32::from(data)
}

/// `link_speed` for the auxiliary status summary's negotiated mode (bits 10:8).
pub fn speed_of_aux_status(aux: u16) -> u64 {
    match (aux >> 8) & 7 {
        7 | 6 => SPEED_1000,
        3..=5 => SPEED_100,
        2 | 1 => SPEED_10,
        _ => SPEED_UNKNOWN,
    }
}

/// The master's transaction: the three writes once after reset, then the two reads in
/// every poll.
#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
enum MdioStep {
    /// Register 4, the advertisement (the first variant is the reset state).
    WriteAdvertise,
    /// Register 9, 1000BASE-T control.
    WriteGigabit,
    /// Register 0, control: auto-negotiation restarted.
    WriteControl,
    /// Register 1, status: the link bit.
    ReadStatus,
    /// Register 19h, auxiliary status: the negotiated speed.
    ReadAux,
}

/// Clock-divided clause 22 master: configures the PHY for Gigabit only, then polls its
/// link status.
#[derive(LogicBlock)]
pub struct MdioMaster {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset (with the PHY's reset).
    pub reset: Signal<In, Bit>,
    /// The MDIO pin as read.
    pub mdio_in: Signal<In, Bit>,
    /// MDC.
    pub mdc: Signal<Out, Bit>,
    /// The level the master drives on MDIO when `mdio_oe` is high.
    pub mdio_out: Signal<Out, Bit>,
    /// High while the master drives MDIO (released otherwise; the pin has a pull-up).
    pub mdio_oe: Signal<Out, Bit>,
    /// The PHY reported its link up (status register bit 2) in the last poll.
    pub link_up: Signal<Out, Bit>,
    /// Negotiated speed of the last poll: [`SPEED_10`], [`SPEED_100`], [`SPEED_1000`] or
    /// [`SPEED_UNKNOWN`].
    pub link_speed: Signal<Out, Bits<2>>,
    word_advertise: Constant<Bits<32>>,
    word_gigabit: Constant<Bits<32>>,
    word_control: Constant<Bits<32>>,
    word_status: Constant<Bits<32>>,
    word_aux: Constant<Bits<32>>,
    startup_periods: Constant<Bits<20>>,
    poll_periods: Constant<Bits<20>>,
    divider: DFF<Bits<6>>,
    busy: DFF<Bit>,
    bit_index: DFF<Bits<6>>,
    // the tests of `bit_index`, registered: it changes only at `at_fall`, 64 clocks apart,
    // so each holds from the clock after a change (no compare in front of the frame's
    // registers)
    bit_is_47: DFF<Bit>,
    bit_is_63: DFF<Bit>,
    bit_from_31: DFF<Bit>,
    bit_from_45: DFF<Bit>,
    bit_from_48: DFF<Bit>,
    step: DFF<MdioStep>,
    /// MDC periods left to wait, minus one: the wait is over when it has gone below zero
    /// (bit 19 set), so no comparison with zero sits in front of the decisions.
    countdown: DFF<Bits<20>>,
    /// High in the clock before MDC falls (divider 63): the bit boundary.
    at_fall: DFF<Bit>,
    /// High in the clock before MDC rises (divider 31): read data is sampled.
    at_sample: DFF<Bit>,
    shift: DFF<Bits<32>>,
    out: DFF<Bit>,
    oe: DFF<Bit>,
    sampled: DFF<Bit>,
    data: DFF<Bits<16>>,
    turnaround_low: DFF<Bit>,
    status_link: DFF<Bit>,
    status_answered: DFF<Bit>,
    link_up_out: DFF<Bit>,
    link_speed_out: DFF<Bits<2>>,
    reading: Signal<Local, Bit>,
    next_bit: Signal<Local, Bits<6>>,
    mode: Signal<Local, Bits<3>>,
    speed: Signal<Local, Bits<2>>,
}

impl MdioMaster {
    /// A master for the PHY at `phy_address` that starts about `startup_periods` MDC
    /// periods ([`MDC_DIVIDER`] clocks each) after its reset and polls the link every
    /// `poll_periods` periods (both 1 to 2^19). Panics beyond those limits.
    pub fn new(phy_address: u8, startup_periods: u64, poll_periods: u64) -> Self {
        assert!(phy_address < 32, "MDIO PHY address {phy_address} above 31");
        assert!(
            (1..=1 << 19).contains(&startup_periods) && (1..=1 << 19).contains(&poll_periods),
            "MdioMaster waits 1 to 2^19 MDC periods"
        );
        let word = |write, register, data| {
            Constant::new(u64::from(frame_word(write, phy_address, register, data)).into())
        };
        Self {
            clock: Default::default(),
            reset: Default::default(),
            mdio_in: Default::default(),
            mdc: Default::default(),
            mdio_out: Default::default(),
            mdio_oe: Default::default(),
            link_up: Default::default(),
            link_speed: Default::default(),
            word_advertise: word(true, REG_ADVERTISE, ADVERTISE_NO_10_100),
            word_gigabit: word(true, REG_GIGABIT_CONTROL, GIGABIT_CONTROL_FULL_ONLY),
            word_control: word(true, REG_CONTROL, CONTROL_RESTART_AN_1000_FULL),
            word_status: word(false, REG_STATUS, 0),
            word_aux: word(false, REG_AUX_STATUS, 0),
            startup_periods: Constant::new((startup_periods - 1).into()),
            poll_periods: Constant::new((poll_periods - 1).into()),
            divider: Default::default(),
            busy: Default::default(),
            bit_index: Default::default(),
            bit_is_47: Default::default(),
            bit_is_63: Default::default(),
            bit_from_31: Default::default(),
            bit_from_45: Default::default(),
            bit_from_48: Default::default(),
            step: Default::default(),
            countdown: Default::default(),
            at_fall: Default::default(),
            at_sample: Default::default(),
            shift: Default::default(),
            out: Default::default(),
            oe: Default::default(),
            sampled: Default::default(),
            data: Default::default(),
            turnaround_low: Default::default(),
            status_link: Default::default(),
            status_answered: Default::default(),
            link_up_out: Default::default(),
            link_speed_out: Default::default(),
            reading: Default::default(),
            next_bit: Default::default(),
            mode: Default::default(),
            speed: Default::default(),
        }
    }
}

impl Logic for MdioMaster {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            divider,
            busy,
            bit_index,
            bit_is_47,
            bit_is_63,
            bit_from_31,
            bit_from_45,
            bit_from_48,
            step,
            countdown,
            at_fall,
            at_sample,
            shift,
            out,
            oe,
            sampled,
            data,
            turnaround_low,
            status_link,
            status_answered,
            link_up_out,
            link_speed_out
        );
        self.divider.d.next = self.divider.q.val() + 1;
        self.sampled.d.next = self.mdio_in.val();
        self.reading.next =
            (self.step.q.val() == MdioStep::ReadStatus) | (self.step.q.val() == MdioStep::ReadAux);
        self.next_bit.next = self.bit_index.q.val() + 1;
        self.bit_is_47.d.next = self.bit_index.q.val() == 47;
        self.bit_is_63.d.next = self.bit_index.q.val() == 63;
        self.bit_from_31.d.next = self.bit_index.q.val() >= 31;
        self.bit_from_45.d.next = self.bit_index.q.val() >= 45;
        self.bit_from_48.d.next = self.bit_index.q.val() >= 48;
        self.mode.next = self.data.q.val().get_bits::<3>(8);
        // the SPEED_ codes as literals (the Verilog has no Rust constants)
        self.speed.next = 3.into();
        if (self.mode.val() == 7) | (self.mode.val() == 6) {
            self.speed.next = 2.into();
        } else if (self.mode.val() == 5) | (self.mode.val() == 4) | (self.mode.val() == 3) {
            self.speed.next = 1.into();
        } else if (self.mode.val() == 2) | (self.mode.val() == 1) {
            self.speed.next = 0.into();
        }
        self.at_fall.d.next = self.divider.q.val() == 62;
        self.at_sample.d.next = self.divider.q.val() == 30;
        if self.at_fall.q.val() & !self.busy.q.val() & !self.countdown.q.val().get_bit(19) {
            self.countdown.d.next = self.countdown.q.val() - 1;
        }
        // the last clock before MDC rises: read data is sampled here
        if self.at_sample.q.val() & self.busy.q.val() & self.reading.val() {
            if self.bit_is_47.q.val() {
                self.turnaround_low.d.next = !self.sampled.q.val();
            }
            if self.bit_from_48.q.val() {
                self.data.d.next =
                    (self.data.q.val() << 1) | bit_cast::<16, 1>(self.sampled.q.val().into());
            }
        }
        // the last clock before MDC falls: the next bit goes out with the falling edge
        if self.at_fall.q.val() {
            if self.busy.q.val() {
                if self.bit_is_63.q.val() {
                    self.busy.d.next = false;
                    self.oe.d.next = false;
                    self.out.d.next = true;
                    match self.step.q.val() {
                        MdioStep::WriteAdvertise => self.step.d.next = MdioStep::WriteGigabit,
                        MdioStep::WriteGigabit => self.step.d.next = MdioStep::WriteControl,
                        MdioStep::WriteControl => self.step.d.next = MdioStep::ReadStatus,
                        MdioStep::ReadStatus => {
                            self.step.d.next = MdioStep::ReadAux;
                            self.status_link.d.next = self.data.q.val().get_bit(2);
                            self.status_answered.d.next = self.turnaround_low.q.val();
                        }
                        MdioStep::ReadAux => self.step.d.next = MdioStep::ReadStatus,
                    }
                    if self.step.q.val() == MdioStep::ReadAux {
                        self.countdown.d.next = self.poll_periods.val();
                        self.link_up_out.d.next = self.status_link.q.val()
                            & self.status_answered.q.val()
                            & self.turnaround_low.q.val();
                        if self.status_answered.q.val() & self.turnaround_low.q.val() {
                            self.link_speed_out.d.next = self.speed.val();
                        } else {
                            self.link_speed_out.d.next = 3.into();
                        }
                    }
                } else {
                    self.bit_index.d.next = self.next_bit.val();
                    self.out.d.next = true;
                    // the next bit is bit_index + 1: the tests compare bit_index itself, so
                    // no adder sits in front of MDIO's registers
                    if self.bit_from_31.q.val() {
                        self.out.d.next = self.shift.q.val().get_bit(31);
                        self.shift.d.next = self.shift.q.val() << 1;
                    }
                    // a read releases MDIO from the turnaround (bit 46) on
                    self.oe.d.next = !(self.reading.val() & self.bit_from_45.q.val());
                }
            } else if self.countdown.q.val().get_bit(19) {
                self.busy.d.next = true;
                self.bit_index.d.next = 0.into();
                self.out.d.next = true;
                self.oe.d.next = true;
                self.data.d.next = 0.into();
                self.turnaround_low.d.next = false;
                match self.step.q.val() {
                    MdioStep::WriteAdvertise => self.shift.d.next = self.word_advertise.val(),
                    MdioStep::WriteGigabit => self.shift.d.next = self.word_gigabit.val(),
                    MdioStep::WriteControl => self.shift.d.next = self.word_control.val(),
                    MdioStep::ReadStatus => self.shift.d.next = self.word_status.val(),
                    MdioStep::ReadAux => self.shift.d.next = self.word_aux.val(),
                }
            }
        }
        if self.reset.val() {
            self.divider.d.next = 0.into();
            self.busy.d.next = false;
            self.oe.d.next = false;
            self.out.d.next = true;
            self.step.d.next = MdioStep::WriteAdvertise;
            self.countdown.d.next = self.startup_periods.val();
            self.at_fall.d.next = false;
            self.at_sample.d.next = false;
            self.link_up_out.d.next = false;
            self.link_speed_out.d.next = 3.into();
        }
        self.mdc.next = self.divider.q.val().get_bit(5);
        self.mdio_out.next = self.out.q.val();
        self.mdio_oe.next = self.oe.q.val();
        self.link_up.next = self.link_up_out.q.val();
        self.link_speed.next = self.link_speed_out.q.val();
    }
}

/// The master's Verilog as module `name` (its submodules prefixed with `name$`), for a
/// board top to instantiate beside the box's `top`.
pub fn module_verilog(mut master: MdioMaster, name: &str) -> String {
    master.connect_all();
    check_all(&master).expect("the MDIO master is a complete block");
    let mut defines = ModuleDefines::default();
    master.accept(name, &mut defines);
    defines.defines()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// A clause 22 PHY as the wire sees it: it samples MDIO on each rising MDC edge, finds
    /// the preamble (32 ones) and the start bits, and answers reads by driving the
    /// turnaround's second bit low and the 16 data bits, each after a rising edge.
    struct PhyModel {
        address: u8,
        registers: [u16; 32],
        writes: Vec<(u8, u16)>,
        reads: Vec<u8>,
        ones: u32,
        frame: Option<Vec<bool>>,
        answer: u16,
        drive: Option<bool>,
        mdc: bool,
        rises: Vec<u64>,
        falls: Vec<u64>,
    }

    impl PhyModel {
        fn new(address: u8) -> Self {
            PhyModel {
                address,
                registers: [0; 32],
                writes: vec![],
                reads: vec![],
                ones: 0,
                frame: None,
                answer: 0,
                drive: None,
                mdc: false,
                rises: vec![],
                falls: vec![],
            }
        }

        fn field(bits: &[bool]) -> u16 {
            bits.iter().fold(0, |v, &b| (v << 1) | u16::from(b))
        }

        /// One clock: the MDC level and the MDIO line as they are now.
        fn clock(&mut self, cycle: u64, mdc: bool, line: bool) {
            let rising = mdc && !self.mdc;
            if !mdc && self.mdc {
                self.falls.push(cycle);
            }
            self.mdc = mdc;
            if !rising {
                return;
            }
            self.rises.push(cycle);
            let Some(bits) = self.frame.as_mut() else {
                if line {
                    self.ones += 1;
                } else {
                    if self.ones >= 32 {
                        self.frame = Some(vec![false]);
                    }
                    self.ones = 0;
                }
                return;
            };
            bits.push(line);
            let n = bits.len();
            let read = n >= 4 && bits[2..4] == [true, false];
            let phy = if n >= 9 {
                Self::field(&bits[4..9]) as u8
            } else {
                0
            };
            let ours = phy == self.address;
            if n == 14 {
                assert_eq!(&bits[..2], &[false, true], "start bits 01");
                if read && ours {
                    let register = Self::field(&bits[9..14]) as u8;
                    self.reads.push(register);
                    self.answer = self.registers[register as usize];
                }
            }
            if read && ours {
                // after the edge of bit k the PHY drives bit k + 1: the turnaround's 0
                // (bit 15), then data bits 16..31
                self.drive = match n {
                    15 => Some(false),
                    16..=31 => Some(self.answer >> (31 - n) & 1 == 1),
                    _ => None,
                };
            }
            if n == 32 {
                if !read && ours {
                    assert_eq!(&bits[14..16], &[true, false], "write turnaround 10");
                    let register = Self::field(&bits[9..14]) as u8;
                    let value = Self::field(&bits[16..32]);
                    self.writes.push((register, value));
                    self.registers[register as usize] = value;
                }
                self.frame = None;
                self.drive = None;
            }
        }
    }

    /// Waits in MDC periods.
    const STARTUP: u64 = 2;
    const POLL: u64 = 40;

    fn master() -> Bench<MdioMaster> {
        let mut bench = Bench::new(MdioMaster::new(0, STARTUP, POLL), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.mdio_in.next = true;
        bench.cycles(3);
        bench.uut.reset.next = false;
        bench
    }

    /// Runs `cycles` clocks with `phy` on the wire (pull-up when nobody drives).
    fn run(bench: &mut Bench<MdioMaster>, phy: &mut PhyModel, cycles: u64) {
        for _ in 0..cycles {
            let master_drives = bench.uut.mdio_oe.val();
            assert!(
                !(master_drives && phy.drive.is_some()),
                "master and PHY drive MDIO at once (cycle {})",
                bench.cycles
            );
            let line = if master_drives {
                bench.uut.mdio_out.val()
            } else {
                phy.drive.unwrap_or(true)
            };
            phy.clock(bench.cycles, bench.uut.mdc.val(), line);
            let line = if master_drives {
                line
            } else {
                phy.drive.unwrap_or(true)
            };
            bench.uut.mdio_in.next = line;
            bench.cycle();
        }
    }

    /// Clocks for the three writes and the two reads: five frames of 64 MDC periods, one
    /// idle period after each.
    const SEQUENCE: u64 = (STARTUP + 1 + 5 * 65) * MDC_DIVIDER + 200;

    #[test]
    fn configures_gigabit_full_duplex_only_then_reads_the_link() {
        let mut bench = master();
        let mut phy = PhyModel::new(0);
        // link up (status bit 2), negotiated 1000BASE-T full duplex (aux bits 10:8 = 111)
        phy.registers[1] = 0x796D;
        phy.registers[0x19] = 0x0700 | 0x0004;
        assert_eq!(
            bench.uut.link_speed.val().to_u64(),
            3,
            "unknown before a read"
        );
        run(&mut bench, &mut phy, SEQUENCE);
        // IEEE 802.3 clause 22: register 4 = selector 00001 only; register 9 bit 9
        // (1000BASE-T full duplex); register 0 bits 12 (AN enable), 9 (restart AN),
        // 8 (full duplex), 6 (speed 1000 with bit 13 clear)
        assert_eq!(phy.writes, [(4, 0x0001), (9, 0x0200), (0, 0x1340)]);
        assert_eq!(phy.reads, [1, 0x19]);
        assert!(bench.uut.link_up.val());
        assert_eq!(bench.uut.link_speed.val().to_u64(), 2);
        // MDC: 64 clocks per period (1.95 MHz at 125 MHz), high for half of it
        let periods: Vec<u64> = phy.rises.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(periods.iter().all(|&p| p == 64), "{periods:?}");
        assert!(phy
            .rises
            .iter()
            .zip(&phy.falls)
            .all(|(r, f)| f > r && f - r == 32));
    }

    #[test]
    fn reports_the_speed_the_phy_negotiated_and_a_link_that_went_down() {
        let mut bench = master();
        let mut phy = PhyModel::new(0);
        phy.registers[1] = 0x0004;
        phy.registers[0x19] = 0x0500; // 100BASE-TX full duplex
        run(&mut bench, &mut phy, SEQUENCE);
        assert!(bench.uut.link_up.val());
        assert_eq!(bench.uut.link_speed.val().to_u64(), 1);
        // the next poll: link down, nothing negotiated
        phy.registers[1] = 0x0000;
        phy.registers[0x19] = 0x0000;
        run(&mut bench, &mut phy, (POLL + 1 + 2 * 65) * MDC_DIVIDER);
        assert_eq!(phy.reads, [1, 0x19, 1, 0x19]);
        assert_eq!(phy.writes.len(), 3, "the configuration is written once");
        assert!(!bench.uut.link_up.val());
        assert_eq!(bench.uut.link_speed.val().to_u64(), 3);
        // 10BASE-T half duplex
        phy.registers[1] = 0x0004;
        phy.registers[0x19] = 0x0100;
        run(&mut bench, &mut phy, (POLL + 1 + 2 * 65) * MDC_DIVIDER);
        assert!(bench.uut.link_up.val());
        assert_eq!(bench.uut.link_speed.val().to_u64(), 0);
    }

    #[test]
    fn a_phy_that_does_not_answer_leaves_the_link_down_and_the_speed_unknown() {
        let mut bench = master();
        // the PHY sits at address 1: nobody answers address 0, the pull-up reads high
        let mut phy = PhyModel::new(1);
        phy.registers[1] = 0x0004;
        phy.registers[0x19] = 0x0700;
        run(&mut bench, &mut phy, SEQUENCE);
        assert!(phy.writes.is_empty() && phy.reads.is_empty());
        assert!(!bench.uut.link_up.val());
        assert_eq!(bench.uut.link_speed.val().to_u64(), 3);
    }

    #[test]
    fn speeds_follow_the_auxiliary_status_summary() {
        let expected = [3, 0, 0, 1, 1, 1, 2, 2];
        for (mode, want) in expected.iter().enumerate() {
            assert_eq!(
                speed_of_aux_status((mode as u16) << 8),
                *want,
                "mode {mode}"
            );
        }
    }

    #[test]
    fn module_verilog_names_the_module() {
        let text = module_verilog(MdioMaster::new(0, 10, 10), "skinbox_mdio");
        assert!(text.contains("module skinbox_mdio("), "{text}");
        assert!(!text.contains("module top"));
    }
}
