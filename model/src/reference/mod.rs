//! The reference model: the box's frames predicted in pure Rust, without Verilator and
//! without a clock loop, from the same pin transitions the RTL co-simulation plays.
//!
//! - Front end, per port ([`front`]): the UART receiver's decisions are arithmetic on the
//!   transition list: the first low sample of a start bit, the accumulator's carries at the
//!   ten bit middles, the majority of the three samples there; the deframer follows the
//!   bytes, the idle gap (counted in receiver bit times) and its rejections. Out come the packets with their stamps and the
//!   cycles their first and last beats are offered to the packet store, and the counter
//!   events.
//! - Back end ([`back`]): packet store (write ring, slots, reader), framer, transmitter,
//!   status reporter and counter file, run only through the clocks in which a record moves or a datagram
//!   closes or starts; the stretches between are skipped (only free-running counters
//!   advance there, and they are advanced arithmetically).
//!
//! It predicts every frame byte for byte and the cycle of its first byte on GMII; the tests
//! compare it with the RTL on the regression scenes. Its latencies are the timing contract's
//! ([`crate::timing`]) and the protocol crate's sizes; the few clock latencies that
//! are properties of the register structure (two clocks from a start edge to the
//! accumulator, two from a transmitter start to GMII, and so on) are written in the two
//! modules with the reasoning, and the byte-for-byte tests hold them to the RTL.

mod back;
mod front;
mod receive;

use crate::control::{udp_frame, BoxControl, ControlConfig};
use crate::downlink::PinChange;
use crate::frame::{Frame, HostFrame};
use crate::inputs::{LINK_SPEED, LINK_UP};
use crate::pins::Transition;
use crate::timing::{
    bit_middles, scan_period, truncation_clocks, BODY_START, BUILD_ACK_CLOCKS, BUILD_ARP_CLOCKS,
    BUILD_ECHO_CLOCKS, COMMAND_LATENCY, FATE_VISIBLE_AFTER, FRAMES_RECEIVED_VISIBLE_AFTER,
    MAC_LATENCY, PARSER_DECISION_LATENCY, PORTS_PER_STATUS, PORT_COUNTERS_CLEAR_CLOCKS,
    RECEIVE_TICK_LAG, TAKE_TO_FIRST_BYTE, TICK_ZERO_CYCLE, UNLOCK_AFTER_LAST_TAKE,
};
use back::{Back, BackTiming, Sent};
use front::{port_front, FrontTiming, PortFront};
use receive::{ReceiveSide, ReceiveTiming};
use skinbox_gateware::interface_box::{BoxConfig, ConfigError};
use skinbox_protocol::command::Destination;
use skinbox_protocol::link::PREAMBLE_LEN;
use skinbox_protocol::link::{FCS_LEN, INTER_FRAME_GAP};

/// The fixed numbers of front and back end for `config`.
fn timings(config: &BoxConfig) -> (FrontTiming, BackTiming) {
    // counters clear for PORT_COUNTERS_CLEAR_CLOCKS after the blocks leave reset; the ports
    // leave reset a clock later
    let counters_ready_from = TICK_ZERO_CYCLE + PORT_COUNTERS_CLEAR_CLOCKS;
    let front = FrontTiming {
        middles: bit_middles(config.clock_hz, config.baud),
        scan_period: scan_period(config.ports) as u64,
        scan_origin: TICK_ZERO_CYCLE,
        truncation: truncation_clocks(config.clock_hz, config.baud, config.idle_gap_bits),
        framing: config.framing,
        port_reset_until: counters_ready_from + 1,
        tick_offset: TICK_ZERO_CYCLE,
    };
    let back = BackTiming {
        ports: config.ports,
        tick_offset: TICK_ZERO_CYCLE,
        counters_ready_from,
        flush_timeout: config.flush_timeout_ticks,
        status_period: config.status_period_ticks,
        sync_period: config.sync_period_ticks,
        ports_per_status: PORTS_PER_STATUS,
        // the boot id counts the reset the run starts with
        boot_id: config.boot_seed.wrapping_add(1),
        box_id: config.box_id,
        body_start: BODY_START,
        frame_tail: (FCS_LEN + INTER_FRAME_GAP) as u64,
        start_to_first_byte: TAKE_TO_FIRST_BYTE,
        scan_period: scan_period(config.ports) as u64,
    };
    (front, back)
}

/// The reference model's front end computed for a whole run, ready to be played in time
/// slices by [`PreparedReference::start`] (the box emulator plays it in real time and
/// changes the run-time configuration between slices).
pub struct PreparedReference {
    fronts: Vec<PortFront>,
    front_timing: FrontTiming,
    end: u64,
    back_timing: BackTiming,
    destination: Destination,
}

/// Prepares the reference model of `config` for pins carrying `lines` up to cycle `end`
/// (as [`predict_frames`] takes them); past `end` the ports are idle.
pub fn prepare(
    config: &BoxConfig,
    lines: &[Vec<Transition>],
    end: u64,
) -> Result<PreparedReference, ConfigError> {
    config.validate()?;
    let (front_timing, back_timing) = timings(config);
    let mut fronts: Vec<PortFront> = lines
        .iter()
        .enumerate()
        .map(|(port, l)| port_front(l, port, &front_timing, end))
        .collect();
    fronts.resize_with(config.ports, PortFront::default);
    let link = &config.link;
    Ok(PreparedReference {
        fronts,
        front_timing,
        end,
        back_timing,
        destination: Destination {
            mac: link.host_mac,
            ip: link.host_ip,
            port: link.host_port,
        },
    })
}

impl PreparedReference {
    /// The box leaving reset: a back end at cycle [`TICK_ZERO_CYCLE`].
    pub fn start(&self) -> SlicedReference<'_> {
        SlicedReference {
            back: Back::new(
                self.back_timing.clone(),
                &self.fronts,
                self.destination,
                None,
            ),
            done: TICK_ZERO_CYCLE,
            taken: 0,
            front_timing: self.front_timing,
            end: self.end,
        }
    }
}

/// A datagram the box starts to send, and the cycle of its first byte on GMII.
#[derive(Debug, Clone)]
pub struct SlicedDatagram {
    /// Cycle of the frame's first preamble byte.
    pub first_cycle: u64,
    /// The datagram.
    pub datagram: skinbox_protocol::DatagramRepr,
    /// A status datagram's box counter block.
    pub box_counters: Option<skinbox_protocol::BoxCounters>,
}

impl SlicedDatagram {
    /// The UDP payload: the datagram, with its box counter block if it has one.
    pub fn payload(&self) -> Vec<u8> {
        payload(&self.datagram, self.box_counters.as_ref())
    }
}

/// The reference model run slice by slice.
pub struct SlicedReference<'a> {
    back: Back<'a>,
    done: u64,
    taken: usize,
    front_timing: FrontTiming,
    end: u64,
}

impl SlicedReference<'_> {
    /// Runs the box up to cycle `cycle` (exclusive) and returns the datagrams it started
    /// since the last call.
    pub fn run_until(&mut self, cycle: u64) -> Vec<SlicedDatagram> {
        if cycle > self.done {
            self.back.run(self.done, cycle);
            self.done = cycle;
        }
        let new = self.back.frames[self.taken..]
            .iter()
            .filter_map(|f| match &f.content {
                Sent::Datagram {
                    datagram,
                    box_counters,
                    ..
                } => Some(SlicedDatagram {
                    first_cycle: f.first_cycle,
                    datagram: datagram.clone(),
                    box_counters: *box_counters,
                }),
                // (the sliced reference has no receive side: the emulator answers)
                Sent::Reply(_) => None,
            })
            .collect();
        self.taken = self.back.frames.len();
        new
    }

    /// The cycle the box has run to.
    pub fn cycle(&self) -> u64 {
        self.done
    }

    /// Datagrams opened from now on close after `ticks`.
    pub fn set_flush_timeout_ticks(&mut self, ticks: u64) {
        self.back.set_flush_timeout(ticks);
    }

    /// Status reports every `ticks` from now on: the next one a period from now.
    pub fn set_status_period_ticks(&mut self, ticks: u64) {
        self.back.set_status_period(ticks, self.done);
    }

    /// The box's time syncs every `ticks` (0: none) from now on (status datagrams say
    /// whether they are on).
    pub fn set_sync_period_ticks(&mut self, ticks: u64) {
        self.back.set_sync_period(ticks);
    }

    /// A status report as soon as the reporter is idle.
    pub fn request_status(&mut self) {
        self.back.request_status();
    }

    /// Port `port`'s pin carries `transitions` (up to the prepared end) from now on: the
    /// cycles run so far stay as they were. Fails when the new transitions change what the
    /// port's receiver had decided before now.
    pub fn replace_port(&mut self, port: usize, transitions: &[Transition]) -> Result<(), String> {
        let front = port_front(transitions, port, &self.front_timing, self.end);
        self.back.replace_front(port, front, self.done)
    }
}

/// The receive path's fixed numbers.
fn receive_timing() -> ReceiveTiming {
    ReceiveTiming {
        // the preamble and SFD, then the MAC's registers
        first_beat_after_edge: PREAMBLE_LEN as u64 + MAC_LATENCY,
        decided_after_last_edge: MAC_LATENCY + PARSER_DECISION_LATENCY,
        receive_tick_after_last_edge: RECEIVE_TICK_LAG,
        command_latency: COMMAND_LATENCY,
        frames_received_visible_after: FRAMES_RECEIVED_VISIBLE_AFTER,
        fate_visible_after: FATE_VISIBLE_AFTER,
        // the command unit's registers hold the new values in its `done` clock; the
        // status reporter registers a report asked for now
        config_after_done: 0,
        report_now_after_done: 1,
        build_arp: BUILD_ARP_CLOCKS,
        build_echo: BUILD_ECHO_CLOCKS,
        build_ack: BUILD_ACK_CLOCKS,
        unlock_after_last_take: UNLOCK_AFTER_LAST_TAKE,
    }
}

/// The frames the box sends when its pins carry `lines` (one transition list per port, as
/// the RTL harness plays them, after [`crate::timing::RESET_CYCLES`] of reset) for `cycles` clocks: each
/// frame preamble to FCS with the cycle of its first byte, cut where the run ends.
pub fn predict_frames(
    config: &BoxConfig,
    lines: &[Vec<Transition>],
    cycles: u64,
) -> Result<Vec<Frame>, ConfigError> {
    Ok(predict_with_host_frames(config, lines, &[], cycles, &mut |_, _| {})?.0)
}

/// As [`predict_frames`], with the frames the host sends the box (the receive path answers
/// them and carries out their commands), calling `progress(cycles done, cycles in all)` as
/// it goes; also returns the downlink, every change of a UART transmit pin.
pub fn predict_with_host_frames(
    config: &BoxConfig,
    lines: &[Vec<Transition>],
    host_frames: &[HostFrame],
    end: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Vec<Frame>, Vec<PinChange>), ConfigError> {
    let prepared = prepare(config, lines, end)?;
    // the receive side and its downlink: for the host's frames, and for the box's own syncs
    let receive = (!host_frames.is_empty() || config.sync_period_ticks > 0).then(|| {
        let mut control = BoxControl::new(ControlConfig::of(config));
        control.counters.link_up = LINK_UP;
        control.counters.link_speed = LINK_SPEED;
        ReceiveSide::new(
            receive_timing(),
            TICK_ZERO_CYCLE,
            control,
            host_frames.to_vec(),
        )
    });
    let mut back = Back::new(
        prepared.back_timing.clone(),
        &prepared.fronts,
        prepared.destination,
        receive,
    );
    let step = 1 << 24;
    let mut done = TICK_ZERO_CYCLE;
    while done < end {
        let to = (done + step).min(end);
        back.run(done, to);
        done = to;
        progress(done, end);
    }
    let uart_tx = back.downlink_changes(end - TICK_ZERO_CYCLE);
    let link = &config.link;
    let mut frames = Vec::with_capacity(back.frames.len());
    for f in &back.frames {
        let mut bytes = match &f.content {
            Sent::Datagram {
                datagram,
                box_counters,
                destination,
            } => udp_frame(link, destination, &payload(datagram, box_counters.as_ref())),
            Sent::Reply(wire) => wire.clone(),
        };
        // the run ends at cycle `end`: a frame still going is cut there, as on the pins
        let room = (end + 1).saturating_sub(f.first_cycle) as usize;
        bytes.truncate(room);
        if !bytes.is_empty() {
            frames.push(Frame {
                first_cycle: f.first_cycle,
                bytes,
            });
        }
    }
    Ok((frames, uart_tx))
}

/// The UDP payload of a predicted datagram, with its box counter block if it has one.
fn payload(
    datagram: &skinbox_protocol::DatagramRepr,
    block: Option<&skinbox_protocol::BoxCounters>,
) -> Vec<u8> {
    match block {
        Some(block) => datagram.to_bytes_with_box_counters(block),
        None => datagram.to_bytes(),
    }
}
