//! InterfaceBox: the whole box for simulation, N UART pins in, GMII out.
//!
//! The [`CellUplink`] takes the ports' UART pins to whole, stamped records (per port a
//! bit-level receiver, one deframing engine for every port, the packet store) and counts
//! every port's events; the [`RecordBatcher`] batches the records. The batcher's records
//! datagrams and the [`StatusReporter`]'s status datagrams meet in the
//! [`DatagramArbiter`], whose output the [`FrameTransmitter`] sends on GMII. The ports stay
//! in reset until the counters are cleared (about 4 us after reset), so no event goes
//! uncounted.
//!
//! Timestamps: a record's tick is the tick of the first clock edge that sampled its
//! packet's first start bit low at the pin (the true falling edge lies in the tick before).

use crate::box_counter_file::BoxCounterFile;
use crate::cell_deframer::{scan_period, MAX_IDLE_GAP_BITS};
use crate::cell_downlink::{frame_bits, pin_scan_clocks, CellDownlink, REFILL_LATENCY};
use crate::cell_uplink::CellUplink;
use crate::command_unit::{CommandUnit, CommandUnitConfig};
use crate::datagram_arbiter::DatagramArbiter;
use crate::frame_parser::FrameParser;
use crate::frame_transmitter::FrameTransmitter;
use crate::geometry::MAX_PORTS;
use crate::hdl::*;
use crate::mac_receiver::MacReceiver;
use crate::receive_rules::{ACTION_ARP, ACTION_COMMAND, ACTION_ECHO, ACTION_NONE};
use crate::record_batcher::RecordBatcher;
use crate::reply_builder::ReplyBuilder;
use crate::status_reporter::StatusReporter;
use crate::stream::{ByteStreamSource, DatagramSource};
use crate::timestamp::TimestampCounter;
use crate::uart_rx::{rate_supported, STAMP_BITS};
const _: () = assert!(STAMP_BITS == 7);
use skinbox_protocol::cell_command::CellCommandFraming;
use skinbox_protocol::{CellFraming, LinkConfig};

/// The datagram arbiter's sources, in their order of precedence after reset: records
/// datagrams (source 0), status datagrams (source 1).
pub const DATAGRAM_SOURCES: usize = 3;

/// Parameters of the box.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct BoxConfig {
    /// UART ports, 1 to 64.
    pub ports: usize,
    /// Box clock, also the GMII clock (125 MHz for Gigabit Ethernet).
    pub clock_hz: u64,
    /// UART rate of the cells.
    pub baud: u64,
    /// A datagram leaves when its first record has waited this long.
    pub flush_timeout_ticks: u64,
    /// Time between status reports.
    pub status_period_ticks: u64,
    /// Time between the box's own time syncs to every cell (0, the default: none;
    /// 12,500,000 = 0.1 s keeps the cells in time: docs/time.md). The first goes out at once
    /// after reset.
    pub sync_period_ticks: u64,
    /// Line idle time, in bit times, that truncates a packet.
    pub idle_gap_bits: u64,
    /// Ethernet, IPv4 and UDP addresses.
    pub link: LinkConfig,
    /// Box id in every datagram.
    pub box_id: u16,
    /// Header and end-of-packet bytes of the cells.
    pub framing: CellFraming,
    /// Boot ids count resets from this value.
    pub boot_seed: u32,
}

impl Default for BoxConfig {
    /// 8 ports, 125 MHz, 4 Mbit/s, 100 us flush timeout, 100 ms status period, a time sync
    /// to every port every 100 ms.
    fn default() -> Self {
        BoxConfig {
            ports: 8,
            clock_hz: crate::CLOCK_HZ,
            baud: crate::CELL_BAUD,
            flush_timeout_ticks: 12_500,
            status_period_ticks: 12_500_000,
            sync_period_ticks: 12_500_000,
            idle_gap_bits: 10,
            link: LinkConfig::DEFAULT,
            box_id: 1,
            framing: CellFraming::DEFAULT,
            boot_seed: 0x5EED_0000,
        }
    }
}

/// A parameter set the box (or its board top) cannot be built with.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// `ports` outside 1 to [`MAX_PORTS`].
    #[error("invalid box parameters: ports = {ports}: the box has 1 to {MAX_PORTS} ports")]
    Ports {
        /// The port count asked for.
        ports: usize,
    },
    /// The clock is below 4 x the baud rate (or the baud rate is 0), or above 64 x.
    #[error("invalid box parameters: clock {clock_hz} Hz must be 4 to 64 x the baud rate {baud} (the UART samples 3 times per bit middle; its bit timer counts to 64)")]
    ClockForBaud {
        /// Box clock, Hz.
        clock_hz: u64,
        /// UART rate.
        baud: u64,
    },
    /// The deframing engine cannot count every event of a port before it can recur.
    #[error("invalid box parameters: {ports} ports at {byte_clocks} clocks per byte: the deframing engine must visit each port 4 times per byte")]
    PortsForCounters {
        /// The port count asked for.
        ports: usize,
        /// Clocks in the shortest byte (5 % fast).
        byte_clocks: u64,
    },
    /// The downlink's refill or pin scan does not fit a bit time: too few clocks per bit
    /// for the port count.
    #[error("invalid box parameters: {ports} ports at {clocks_per_bit} clocks per bit: the downlink's pin scan needs {scan_clocks} clocks of a bit and its refill {refill_clocks} clocks of the stop bits and the last data bit")]
    PortsForDownlink {
        /// The port count asked for.
        ports: usize,
        /// Clocks in the shortest bit.
        clocks_per_bit: u64,
        /// Clocks the pin scan takes after a bit's end.
        scan_clocks: u64,
        /// Clocks the refill takes after the last data bit's start.
        refill_clocks: u64,
    },
    /// `flush_timeout_ticks` outside 1 to 2^31 - 1.
    #[error("invalid box parameters: flush timeout {ticks} ticks: must be 1 to 2^31 - 1")]
    FlushTimeout {
        /// The timeout asked for.
        ticks: u64,
    },
    /// `status_period_ticks` outside 1 to 2^32 - 1.
    #[error("invalid box parameters: status period {ticks} ticks: must be 1 to 2^32 - 1 (34 s)")]
    StatusPeriod {
        /// The period asked for.
        ticks: u64,
    },
    /// `sync_period_ticks` above 2^32 - 1.
    #[error(
        "invalid box parameters: sync period {ticks} ticks: must be 0 (off) to 2^32 - 1 (34 s)"
    )]
    SyncPeriod {
        /// The period asked for.
        ticks: u64,
    },
    /// `idle_gap_bits` outside 2 to [`MAX_IDLE_GAP_BITS`].
    #[error(
        "invalid box parameters: idle gap {bits} bits: must be 2 to {MAX_IDLE_GAP_BITS} bit times"
    )]
    IdleGap {
        /// The gap asked for.
        bits: u64,
    },
    /// The data and event header bytes are equal.
    #[error("invalid box parameters: data and event headers must differ")]
    SameHeaders,
    /// The board's constraints have fewer UART pins than the box has ports.
    #[error(
        "invalid box parameters: {ports} ports, but the {board} constraints have {pins} UART pins"
    )]
    BoardPins {
        /// The port count asked for.
        ports: usize,
        /// The board.
        board: &'static str,
        /// UART pins in its constraints.
        pins: usize,
    },
    /// The board's PLL cannot make the clock from its oscillator.
    #[error("invalid box parameters: the ECP5 PLL cannot make {clock_hz} Hz from the {oscillator_hz} Hz oscillator")]
    Pll {
        /// Box clock asked for, Hz.
        clock_hz: u64,
        /// The board's oscillator, Hz.
        oscillator_hz: u64,
    },
}

impl BoxConfig {
    /// Clocks in one UART bit (31.25 by default).
    pub fn clocks_per_bit(&self) -> f64 {
        self.clock_hz as f64 / self.baud as f64
    }

    /// Checks every parameter: the first that is wrong, and why.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1..=MAX_PORTS).contains(&self.ports) {
            return Err(ConfigError::Ports { ports: self.ports });
        }
        if !rate_supported(self.clock_hz, self.baud) {
            return Err(ConfigError::ClockForBaud {
                clock_hz: self.clock_hz,
                baud: self.baud,
            });
        }
        // The engine counts one event per visit and a byte raises at most four: a port's
        // byte visits (a byte on the fastest line the receiver accepts) must be four
        // visits apart.
        let byte_clocks = 10.0 * self.clocks_per_bit() * 0.95;
        let period = scan_period(self.ports) as f64;
        if 1.0 + ((byte_clocks - period) / period).floor() < 4.0 {
            return Err(ConfigError::PortsForCounters {
                ports: self.ports,
                byte_clocks: byte_clocks as u64,
            });
        }
        // The downlink: every port's next data bit is in place before the bit's end, and
        // every port is refilled between its last data bit and its next start bit.
        let bit_clocks = self.clock_hz / self.baud;
        let scan_clocks = pin_scan_clocks(self.ports);
        let refill_clocks = self.ports as u64 + REFILL_LATENCY;
        if scan_clocks > bit_clocks || refill_clocks >= (frame_bits(self.ports) - 8) * bit_clocks {
            return Err(ConfigError::PortsForDownlink {
                ports: self.ports,
                clocks_per_bit: bit_clocks,
                scan_clocks,
                refill_clocks,
            });
        }
        if !(1..1 << 31).contains(&self.flush_timeout_ticks) {
            return Err(ConfigError::FlushTimeout {
                ticks: self.flush_timeout_ticks,
            });
        }
        if !(1..1 << 32).contains(&self.status_period_ticks) {
            return Err(ConfigError::StatusPeriod {
                ticks: self.status_period_ticks,
            });
        }
        if self.sync_period_ticks >= 1 << 32 {
            return Err(ConfigError::SyncPeriod {
                ticks: self.sync_period_ticks,
            });
        }
        if !(2..=MAX_IDLE_GAP_BITS).contains(&self.idle_gap_bits) {
            return Err(ConfigError::IdleGap {
                bits: self.idle_gap_bits,
            });
        }
        if self.framing.data_header == self.framing.event_header {
            return Err(ConfigError::SameHeaders);
        }
        Ok(())
    }
}

/// Clocks from the `reset` pin to the blocks (one register): box tick 0 is the clock
/// `RESET_LATENCY` after the pin goes low.
pub const RESET_LATENCY: u64 = 1;

/// Clocks from the rising edge that samples a received frame's last byte on `gmii_rxd` to
/// the clock whose tick is the frame's receive tick (the tick of its last beat out of the
/// MAC, which the acknowledgement of a command carries).
pub const RECEIVE_TICK_LAG: u64 = crate::mac_receiver::MAC_LATENCY;

/// The interface box.
#[derive(LogicBlock)]
pub struct InterfaceBox {
    /// The box clock, 125 MHz.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset, active high; the blocks see it [`RESET_LATENCY`] clocks later.
    pub reset: Signal<In, Bit>,
    /// The UART pins of the ports, idle high.
    pub uart_rx: Vec<Signal<In, Bit>>,
    /// The UART transmit pins of the ports, the downlink to the cells, idle high.
    pub uart_tx: Vec<Signal<Out, Bit>>,
    /// The PHY reports the link up (the board top's MDIO master; held low without a PHY).
    pub link_up: Signal<In, Bit>,
    /// The link's speed as the PHY reports it: 0 = 10, 1 = 100, 2 = 1000 Mbit/s, 3 = not
    /// known (hold it at 3 without a PHY).
    pub link_speed: Signal<In, Bits<2>>,
    /// GMII receive data, in the box clock (the board top's clock crossing; in
    /// co-simulation the harness drives it at 125 MHz).
    pub gmii_rxd: Signal<In, Bits<8>>,
    /// GMII receive data valid.
    pub gmii_rx_dv: Signal<In, Bit>,
    /// GMII receive error.
    pub gmii_rx_er: Signal<In, Bit>,
    /// GMII transmit data.
    pub gmii_txd: Signal<Out, Bits<8>>,
    /// GMII transmit enable.
    pub gmii_tx_en: Signal<Out, Bit>,
    /// GMII transmit error.
    pub gmii_tx_er: Signal<Out, Bit>,
    timestamp: TimestampCounter,
    uplink: CellUplink,
    status: StatusReporter,
    batcher: RecordBatcher,
    arbiter: DatagramArbiter,
    transmitter: FrameTransmitter,
    // the receive path: MAC, parser, command unit, box counters, replies
    mac: MacReceiver,
    parser: FrameParser,
    commands: CommandUnit,
    box_counters: BoxCounterFile,
    replies: ReplyBuilder,
    downlink: CellDownlink,
    action_none: Constant<Bits<2>>,
    action_arp: Constant<Bits<2>>,
    action_echo: Constant<Bits<2>>,
    action_command: Constant<Bits<2>>,
    core_reset: DFF<Bit>,
}

impl InterfaceBox {
    /// Builds the box; fails with a message when a parameter is impossible.
    pub fn new(config: &BoxConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let n = config.ports;
        Ok(Self {
            clock: Default::default(),
            reset: Default::default(),
            uart_rx: (0..n).map(|_| Default::default()).collect(),
            uart_tx: (0..n).map(|_| Default::default()).collect(),
            link_up: Default::default(),
            link_speed: Default::default(),
            gmii_rxd: Default::default(),
            gmii_rx_dv: Default::default(),
            gmii_rx_er: Default::default(),
            gmii_txd: Default::default(),
            gmii_tx_en: Default::default(),
            gmii_tx_er: Default::default(),
            timestamp: Default::default(),
            uplink: CellUplink::new(
                n,
                config.clock_hz,
                config.baud,
                config.framing,
                config.idle_gap_bits,
            ),
            status: StatusReporter::new(n, config.boot_seed),
            batcher: RecordBatcher::new(),
            arbiter: DatagramArbiter::new(DATAGRAM_SOURCES),
            transmitter: FrameTransmitter::new(&config.link, config.box_id, n as u8),
            mac: Default::default(),
            parser: FrameParser::new(&config.link),
            commands: CommandUnit::new(CommandUnitConfig {
                link: config.link,
                box_id: config.box_id,
                port_count: n as u8,
                flush_timeout_ticks: config.flush_timeout_ticks as u32,
                status_period_ticks: config.status_period_ticks as u32,
                sync_period_ticks: config.sync_period_ticks as u32,
            }),
            box_counters: Default::default(),
            replies: ReplyBuilder::new(&config.link, config.box_id, n as u8),
            downlink: CellDownlink::new(
                n,
                config.clock_hz,
                config.baud,
                CellCommandFraming::DEFAULT,
            ),
            action_none: Constant::new(u64::from(ACTION_NONE).into()),
            action_arp: Constant::new(u64::from(ACTION_ARP).into()),
            action_echo: Constant::new(u64::from(ACTION_ECHO).into()),
            action_command: Constant::new(u64::from(ACTION_COMMAND).into()),
            core_reset: Default::default(),
        })
    }

    /// The box with every block connected, ready to simulate or generate.
    pub fn connected(config: &BoxConfig) -> Result<Self, ConfigError> {
        let mut b = Self::new(config)?;
        b.connect_all();
        Ok(b)
    }
}

impl Logic for InterfaceBox {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, core_reset);
        // the reset pin drives one register, which drives the blocks: no combinational
        // path from a pin into the core
        self.core_reset.d.next = self.reset.val();
        self.timestamp.clock.next = self.clock.val();
        self.timestamp.reset.next = self.core_reset.q.val();
        // pins -> UARTs -> the deframing engine -> the packet store, events counted
        self.uplink.clock.next = self.clock.val();
        self.uplink.reset.next = self.core_reset.q.val();
        self.uplink.tick.next = self.timestamp.tick.val();
        for i in 0..self.uart_rx.len() {
            self.uplink.uart_rx[i].next = self.uart_rx[i].val();
        }
        self.uplink.counter_address.next = self.status.counter_address.val();

        // store -> batcher: the store's output FIFO holds every beat in flight, so the
        // batcher's ready reaches its FIFO registers only
        self.batcher.clock.next = self.clock.val();
        self.batcher.reset.next = self.core_reset.q.val();
        self.batcher.tick.next = self.timestamp.tick.val();
        self.batcher.flush_timeout_ticks.next = self.commands.flush_timeout_ticks.val();
        ByteStreamSource::join(&mut self.uplink.records, &mut self.batcher.records);

        self.status.clock.next = self.clock.val();
        self.status.reset.next = self.core_reset.q.val();
        self.status.tick.next = self.timestamp.tick.val();
        self.status.time_syncs.next = self.downlink.syncs_on.val();
        self.status.datagrams_sent.next = self.batcher.datagrams_sent.val();
        self.status.records_sent.next = self.batcher.records_sent.val();
        self.status.counters_ready.next = self.uplink.counters_ready.val();
        self.status.counter_data.next = self.uplink.counter_data.val();
        self.status.link_up.next = self.link_up.val();
        self.status.link_speed.next = self.link_speed.val();
        self.status.status_period_ticks.next = self.commands.status_period_ticks.val();
        self.status.restart_period.next = self.commands.status_period_set.val();
        self.status.report_now.next = self.commands.status_now.val();
        self.box_counters.reporter_address.next = self.status.box_counter_address.val();
        self.status.box_counter_data.next = self.box_counters.reporter_data.val();

        // the receive path: GMII -> MAC -> parser (which stores the frame in the reply
        // buffer) -> command unit; replies built in the buffer go out as raw frames
        self.mac.clock.next = self.clock.val();
        self.mac.reset.next = self.core_reset.q.val();
        self.mac.gmii_rxd.next = self.gmii_rxd.val();
        self.mac.gmii_rx_dv.next = self.gmii_rx_dv.val();
        self.mac.gmii_rx_er.next = self.gmii_rx_er.val();
        self.parser.clock.next = self.clock.val();
        self.parser.reset.next = self.core_reset.q.val();
        ByteStreamSource::join(&mut self.mac.frame, &mut self.parser.frame);
        self.parser.length_error.next = self.mac.length_error.val();
        self.parser.buffer_locked.next = self.replies.locked.val();
        self.commands.clock.next = self.clock.val();
        self.commands.reset.next = self.core_reset.q.val();
        self.commands.command.next =
            self.parser.decided.val() & (self.parser.action.val() == self.action_command.val());
        self.commands.peer_mac.next = self.parser.peer_mac.val();
        self.commands.peer_ip.next = self.parser.peer_ip.val();
        self.commands.peer_port.next = self.parser.peer_port.val();
        self.commands.command_box_id.next = self.parser.command_box_id.val();
        self.commands.command_opcode.next = self.parser.command_opcode.val();
        self.commands.command_sequence.next = self.parser.command_sequence.val();
        self.commands.command_argument_length.next = self.parser.command_argument_length.val();
        self.commands.command_arguments.next = self.parser.command_arguments.val();
        // every frame is counted once: by the parser, or for a command by the command unit
        self.box_counters.clock.next = self.clock.val();
        self.box_counters.reset.next = self.core_reset.q.val();
        self.box_counters.count.next = self.commands.done.val()
            | (self.parser.decided.val() & (self.parser.action.val() != self.action_command.val()));
        self.box_counters.counter.next = self.parser.fate.val();
        if self.commands.done.val() {
            self.box_counters.counter.next = self.commands.fate.val();
        }
        self.replies.clock.next = self.clock.val();
        self.replies.reset.next = self.core_reset.q.val();
        self.replies.tick.next = self.timestamp.tick.val();
        self.replies.receive_write_enable.next = self.parser.buffer_write_enable.val();
        self.replies.receive_write_address.next = self.parser.buffer_write_address.val();
        self.replies.receive_write_data.next = self.parser.buffer_write_data.val();
        self.replies.reserve.next =
            self.parser.decided.val() & (self.parser.action.val() != self.action_none.val());
        self.replies.start_arp.next =
            self.parser.decided.val() & (self.parser.action.val() == self.action_arp.val());
        self.replies.start_echo.next =
            self.parser.decided.val() & (self.parser.action.val() == self.action_echo.val());
        self.replies.start_ack.next = self.commands.done.val();
        self.replies.receive_tick_now.next = self.parser.receive_tick_now.val();
        self.replies.ip_total_length.next = self.parser.ip_total_length.val();
        self.replies.icmp_rest_sum.next = self.parser.icmp_rest_sum.val();
        self.replies.result.next = self.commands.result.val();
        self.replies.accepted_stream_to.next = self.commands.accepted_stream_to.val();
        self.replies.accepted_status_now.next = self.commands.accepted_status_now.val();
        self.replies.last_accepted.next = self.commands.last_accepted.val();
        self.replies.destination_mac.next = self.commands.destination_mac.val();
        self.replies.destination_ip.next = self.commands.destination_ip.val();
        self.replies.destination_port.next = self.commands.destination_port.val();
        self.replies.link_up.next = self.link_up.val();
        self.replies.link_speed.next = self.link_speed.val();
        // cell commands: the downlink captures the packet as the frame is stored and queues
        // it when the command unit offers it
        self.downlink.clock.next = self.clock.val();
        self.downlink.reset.next = self.core_reset.q.val();
        self.downlink.capture.next = self.parser.buffer_write_enable.val();
        self.downlink.capture_address.next = self.parser.buffer_write_address.val();
        self.downlink.capture_data.next = self.parser.buffer_write_data.val();
        self.downlink.offer.next = self.commands.downlink_offer.val();
        self.downlink.offer_port.next = self.commands.downlink_port.val();
        self.commands.downlink_busy.next = self.downlink.busy.val();
        self.commands.downlink_full_ports.next = self.downlink.full_ports.val();
        self.downlink.tick.next = self.timestamp.tick.val();
        self.downlink.sync_period.next = self.commands.sync_period_ticks.val();
        self.downlink.sync_restart.next = self.commands.sync_period_set.val();
        for i in 0..self.uart_tx.len() {
            self.uart_tx[i].next = self.downlink.uart_tx[i].val();
        }
        self.box_counters.reply_address.next = self.replies.counters_address.val();
        self.replies.counters_data.next = self.box_counters.reply_data.val();

        // records and status datagrams -> arbiter -> transmitter
        self.arbiter.clock.next = self.clock.val();
        self.arbiter.reset.next = self.core_reset.q.val();
        DatagramSource::join(&mut self.batcher.datagrams, &mut self.arbiter.sources[0]);
        DatagramSource::join(&mut self.status.datagrams, &mut self.arbiter.sources[1]);
        DatagramSource::join(&mut self.replies.replies, &mut self.arbiter.sources[2]);
        self.transmitter.clock.next = self.clock.val();
        self.transmitter.reset.next = self.core_reset.q.val();
        self.transmitter.destination_mac.next = self.commands.destination_mac.val();
        self.transmitter.destination_ip.next = self.commands.destination_ip.val();
        self.transmitter.destination_port.next = self.commands.destination_port.val();
        DatagramSource::join(&mut self.arbiter.datagrams, &mut self.transmitter.datagrams);

        self.gmii_txd.next = self.transmitter.gmii_txd.val();
        self.gmii_tx_en.next = self.transmitter.gmii_tx_en.val();
        self.gmii_tx_er.next = self.transmitter.gmii_tx_er.val();
    }
}

/// The box's Verilog, top module `top`.
pub fn verilog(config: &BoxConfig) -> Result<String, ConfigError> {
    let b = InterfaceBox::connected(config)?;
    Ok(generate_verilog(&b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_parameter_is_refused_with_its_own_error_and_its_limits_are_accepted() {
        let with = |change: fn(&mut BoxConfig)| {
            let mut c = BoxConfig::default();
            change(&mut c);
            c.validate()
        };
        assert_eq!(BoxConfig::default().validate(), Ok(()));
        // Limits: accepted.
        for ok in [
            with(|c| c.ports = 1),
            with(|c| c.ports = 64),
            with(|c| c.clock_hz = 14 * c.baud),
            with(|c| c.flush_timeout_ticks = 1),
            with(|c| c.flush_timeout_ticks = (1 << 31) - 1),
            with(|c| c.status_period_ticks = 1),
            with(|c| c.status_period_ticks = (1 << 32) - 1),
            with(|c| c.idle_gap_bits = 2),
            with(|c| c.idle_gap_bits = 21),
        ] {
            assert_eq!(ok, Ok(()));
        }
        // One past them: refused, each with its variant.
        assert_eq!(with(|c| c.ports = 0), Err(ConfigError::Ports { ports: 0 }));
        assert_eq!(
            with(|c| c.ports = 65),
            Err(ConfigError::Ports { ports: 65 })
        );
        // 8 ports: the pin scan takes 14 clocks of a bit
        assert_eq!(
            with(|c| c.clock_hz = 14 * c.baud - 1),
            Err(ConfigError::PortsForDownlink {
                ports: 8,
                clocks_per_bit: 13,
                scan_clocks: 14,
                refill_clocks: 13
            })
        );
        assert_eq!(
            with(|c| c.clock_hz = 4 * c.baud - 1),
            Err(ConfigError::ClockForBaud {
                clock_hz: 15_999_999,
                baud: 4_000_000
            })
        );
        assert_eq!(
            with(|c| c.baud = 1_000_000),
            Err(ConfigError::ClockForBaud {
                clock_hz: 125_000_000,
                baud: 1_000_000
            })
        );
        // at 4 clocks per bit a fast byte lasts 38 clocks: four visits of 8 ports, two of 16
        assert_eq!(
            with(|c| {
                c.clock_hz = 4 * c.baud;
                c.ports = 16
            }),
            Err(ConfigError::PortsForCounters {
                ports: 16,
                byte_clocks: 38
            })
        );
        assert_eq!(
            with(|c| c.flush_timeout_ticks = 0),
            Err(ConfigError::FlushTimeout { ticks: 0 })
        );
        assert_eq!(
            with(|c| c.flush_timeout_ticks = 1 << 31),
            Err(ConfigError::FlushTimeout { ticks: 1 << 31 })
        );
        assert_eq!(
            with(|c| c.status_period_ticks = 1 << 32),
            Err(ConfigError::StatusPeriod { ticks: 1 << 32 })
        );
        assert_eq!(
            with(|c| c.idle_gap_bits = 22),
            Err(ConfigError::IdleGap { bits: 22 })
        );
        assert_eq!(
            with(|c| c.framing.event_header = c.framing.data_header),
            Err(ConfigError::SameHeaders)
        );
        assert_eq!(
            ConfigError::Ports { ports: 65 }.to_string(),
            "invalid box parameters: ports = 65: the box has 1 to 64 ports"
        );
    }
    use crate::testbench::{bit_period, check_frame, Bench, GmiiCapture, UartLine};
    use skinbox_protocol::box_counters::LinkSpeed;
    use skinbox_protocol::datagram::DatagramBody;
    use skinbox_protocol::status::PortCounter;
    use skinbox_protocol::{BoxCounters, Channel, DataRepr, DatagramRepr, EventRepr};

    /// Runs the box on the pin levels (one list per port, indexed by clock edge, reset
    /// for edges 1 to 3), its link up at 100 Mbit/s, and returns its datagrams with their
    /// box counter blocks, every frame checked.
    fn run_box(config: &BoxConfig, levels: &[Vec<bool>]) -> Vec<DatagramRepr> {
        run_box_with_blocks(config, levels)
            .into_iter()
            .map(|(d, _)| d)
            .collect()
    }

    fn run_box_with_blocks(
        config: &BoxConfig,
        levels: &[Vec<bool>],
    ) -> Vec<(DatagramRepr, Option<BoxCounters>)> {
        let mut bench = Bench::new(InterfaceBox::connected(config).unwrap(), |b| &mut b.clock);
        bench.uut.link_up.next = true;
        bench.uut.link_speed.next = 1.into();
        let mut capture = GmiiCapture::default();
        let clocks = levels.iter().map(Vec::len).max().unwrap_or(0) as u64;
        for e in 1..clocks {
            let u = &mut bench.uut;
            u.reset.next = e <= 3;
            for (port, l) in levels.iter().enumerate() {
                u.uart_rx[port].next = l[e as usize];
            }
            bench.cycle();
            let u = &bench.uut;
            capture.clock(
                e,
                u.gmii_tx_en.val(),
                u.gmii_txd.val().to_u8(),
                u.gmii_tx_er.val(),
            );
        }
        capture
            .frames
            .iter()
            .map(|f| DatagramRepr::parse_box_counters(&check_frame(f).unwrap()).unwrap())
            .collect()
    }

    #[test]
    fn impossible_parameters_are_refused_with_a_reason() {
        let bad = [
            (
                BoxConfig {
                    ports: 0,
                    ..Default::default()
                },
                "ports = 0",
            ),
            (
                BoxConfig {
                    ports: 65,
                    ..Default::default()
                },
                "1 to 64 ports",
            ),
            (
                BoxConfig {
                    baud: 40_000_000,
                    ..Default::default()
                },
                "must be 4 to 64 x the baud rate",
            ),
            (
                BoxConfig {
                    flush_timeout_ticks: 0,
                    ..Default::default()
                },
                "flush timeout",
            ),
            (
                BoxConfig {
                    status_period_ticks: 1 << 33,
                    ..Default::default()
                },
                "status period",
            ),
            (
                BoxConfig {
                    idle_gap_bits: 1,
                    ..Default::default()
                },
                "idle gap",
            ),
            (
                BoxConfig {
                    idle_gap_bits: 22,
                    ..Default::default()
                },
                "idle gap",
            ),
        ];
        for (config, reason) in bad {
            let err = InterfaceBox::new(&config).err().expect("refused");
            assert!(err.to_string().contains(reason), "{err}");
        }
        assert!(InterfaceBox::new(&BoxConfig::default()).is_ok());
    }

    #[test]
    fn packets_on_two_pins_become_stamped_records_and_counted_status() {
        let config = BoxConfig {
            ports: 2,
            flush_timeout_ticks: 2_000,
            status_period_ticks: 20_000,
            ..BoxConfig::default()
        };
        let data = DataRepr::from_raw(17, [3, -2, 260, 1, 0, 9, 450, 61, 0])
            .unwrap()
            .to_bytes();
        let event = EventRepr::new(18, 5, false, &[(Channel::Force2, 33)])
            .unwrap()
            .to_bytes();
        // port 0 at +1 % baud error, port 1 at -2 %; start edges at fractional times
        let mut lines = [UartLine::default(), UartLine::default()];
        let starts = [1000.3, 1400.8];
        lines[0].bytes(&data, starts[0], bit_period(1e4));
        lines[1].bytes(&event, starts[1], bit_period(-2e4));
        let clocks = 23_000;
        let levels: Vec<Vec<bool>> = lines.iter().map(|l| l.levels(clocks)).collect();

        let with_blocks = run_box_with_blocks(&config, &levels);
        // every status datagram carries the link state the box was given, and no records
        // datagram carries a block
        for (d, block) in &with_blocks {
            match d.body {
                DatagramBody::Status(_) => {
                    let b = block
                        .as_ref()
                        .expect("a status datagram's box counter block");
                    assert_eq!((b.link_up, b.link_speed), (true, LinkSpeed::Mbit100));
                    assert!(b.counts.iter().all(|&c| c == 0), "no frame received");
                }
                DatagramBody::Records(_) => assert!(block.is_none()),
            }
        }
        let datagrams: Vec<DatagramRepr> = with_blocks.into_iter().map(|(d, _)| d).collect();
        let kinds: Vec<&str> = datagrams
            .iter()
            .map(|d| match d.body {
                DatagramBody::Records(_) => "records",
                DatagramBody::Status(_) => "status",
            })
            .collect();
        assert_eq!(kinds, ["status", "records", "status"]);
        assert_eq!(
            datagrams.iter().map(|d| d.sequence).collect::<Vec<_>>(),
            [0, 1, 2]
        );

        let DatagramBody::Records(records) = &datagrams[1].body else {
            unreachable!()
        };
        assert_eq!(records.len(), 2);
        // the tick counter reads e - 3 - RESET_LATENCY after edge e (the reset pin held for
        // edges 1..=3); a record's tick is that of the first edge that sampled its start
        // bit low
        for (r, (port, cell, start)) in records
            .iter()
            .zip([(0u8, data, starts[0]), (1, event, starts[1])])
        {
            assert_eq!((r.port, r.flags, r.cell_packet), (port, 0, cell));
            assert_eq!(
                r.tick(datagrams[1].base_tick),
                start.ceil() as u64 - 3 - RESET_LATENCY,
                "port {port}"
            );
        }

        let DatagramBody::Status(boot) = &datagrams[0].body else {
            unreachable!()
        };
        assert_eq!(boot.boot_id, config.boot_seed + 1);
        assert!(
            boot.ports.iter().all(|p| p.0 == [0; 8]),
            "nothing counted yet"
        );
        let DatagramBody::Status(later) = &datagrams[2].body else {
            unreachable!()
        };
        assert_eq!((later.datagrams_sent, later.records_sent), (1, 2));
        for p in &later.ports {
            assert_eq!(p.get(PortCounter::PacketsGood), 1);
            let others: u32 = PortCounter::ALL[1..].iter().map(|c| p.get(*c)).sum();
            assert_eq!(others, 0, "no loss, garbage or error: {p:?}");
        }
    }

    #[test]
    fn injected_faults_reach_the_status_counters() {
        let config = BoxConfig {
            ports: 2,
            flush_timeout_ticks: 2_000,
            status_period_ticks: 45_000,
            ..BoxConfig::default()
        };
        let p = bit_period(0.0);
        let good = |id: u16| {
            DataRepr {
                cell_id: id,
                ..Default::default()
            }
            .to_bytes()
        };
        let mut faulty = UartLine::default();
        // 3 garbage bytes, then a good packet
        let mut t = faulty.bytes(&[0x00, 0x13, 0x37], 1000.0, p);
        t = faulty.bytes(&good(1), t + 3.0 * p, p);
        // a truncated packet: 8 bytes, then the line idles
        t = faulty.bytes(&good(2)[..8], t + 3.0 * p, p);
        t += 40.0 * p;
        // a packet with a framing error in byte 5; the bytes after it are garbage
        let broken = good(3);
        t = faulty.bytes(&broken[..5], t, p);
        t = faulty.frame(broken[5], t, p, false);
        t = faulty.bytes(&broken[6..], t, p);
        // a packet with a wrong end byte, then a good one
        let mut wrong_end = good(4);
        wrong_end[19] = 0x54;
        t = faulty.bytes(&wrong_end, t + 3.0 * p, p);
        faulty.bytes(&good(5), t + 3.0 * p, p);
        let mut clean = UartLine::default();
        clean.bytes(&good(9), 2000.0, p);

        let clocks = 47_000;
        let levels = [faulty.levels(clocks), clean.levels(clocks)];
        let datagrams = run_box(&config, &levels);
        let delivered: Vec<(u8, u8, [u8; 20])> = datagrams
            .iter()
            .filter_map(|d| match &d.body {
                DatagramBody::Records(r) => Some(r.clone()),
                DatagramBody::Status(_) => None,
            })
            .flatten()
            .map(|r| (r.port, r.flags, r.cell_packet))
            .collect();
        // only whole good packets come out, in order of completion; the first of port 0
        // after its losses is flagged
        assert_eq!(
            delivered,
            [(1, 0, good(9)), (0, 0, good(1)), (0, 1, good(5))]
        );
        let status = datagrams
            .iter()
            .rev()
            .find_map(|d| match &d.body {
                DatagramBody::Status(s) => Some(s.clone()),
                DatagramBody::Records(_) => None,
            })
            .unwrap();
        let count = |port: usize, c: PortCounter| status.ports[port].get(c);
        assert_eq!(count(0, PortCounter::PacketsGood), 2);
        assert_eq!(count(0, PortCounter::RejectedTruncated), 1);
        assert_eq!(count(0, PortCounter::RejectedFraming), 1);
        assert_eq!(count(0, PortCounter::RejectedEndByte), 1);
        assert_eq!(count(0, PortCounter::FramingErrors), 1);
        assert_eq!(count(0, PortCounter::DroppedOverflow), 0);
        // 3 leading garbage bytes + 13 of the 14 bytes after the framing error: the low
        // stop bit runs into the next byte's start bit and its zero data bits, so that
        // byte has no falling edge and is never framed
        assert_eq!(count(0, PortCounter::GarbageBytes), 3 + 13);
        // truncated, framing, end byte: three rejections
        assert_eq!(count(0, PortCounter::Resyncs), 3);
        assert_eq!(status.ports[1].0, [1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(status.records_sent, 3);
    }
}
