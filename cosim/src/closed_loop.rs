//! The loop closed: the cells hear the box's actual transmit pins.
//!
//! A scene's cells are generated ahead for the whole run, as without a box, and their
//! packets drive the box's receive pins. The box runs in steps; after each, the cells' UART
//! receivers ([`skinbox_model::cell_uart`]) decode the transmit pin changes of the step,
//! and every cell command packet received on port `p` joins bus `p`'s downlink: the scene is
//! generated again with it, and port `p`'s transitions not yet driven are replaced by the
//! new ones. The cell models are deterministic and causal, so the new stream must equal the
//! old one up to the command's earliest effect; [`Cells::receive`] checks that (it is what
//! makes regeneration sound). Without host commands and with the box's sync generator
//! off nothing is regenerated: a scene without downlink traffic costs what it did
//! open-loop.
//!
//! The step is short enough that a command reaches the cells before they act on it
//! ([`step_cycles`]): a packet is received at its last stop bit's middle, `19 x frame + 9.5`
//! bits after its first start bit left the box (49.875 us at 4 Mbit/s with 10-bit frames);
//! the cells' model has it complete in the root 50 us after it left
//! ([`DOWNLINK_PACKET_NS`]), and the root's first packet after that reaches the pin
//! a processing time later. The step is that margin (the bus's processing time and
//! 0.125 us, less the jitter), so the step that sees a packet whole ends before the first
//! pin transition it can change.
//!
//! The reference fidelity closes the loop the same way, in one regeneration: the box's
//! downlink depends on the host's frames only, not on what its receive pins carry, so the
//! reference model's downlink (the control model's, [`skinbox_model::downlink`]) is run
//! first on idle pins, decoded, and the cells generated with it; the run with the cells'
//! packets must then put the same changes on the transmit pins (checked).

use crate::error::CosimError;
use crate::harness::{Player, PROGRESS_STEP};
use crate::line::Transition;
use crate::model::{default_cache_dir, Model};
use crate::run::{analyse, cycles, line, SentPacket, SimRun, SimSpec, RESET_CYCLES};
use crate::scene::{
    downlink_before, generate_with, plan_downlink, scene_ns_of_tick, sent_packets, sim_duration_ns,
};
use crate::sim::{uart_tx_changes, Fidelity};
use crate::Dut;
use skinbox_cells::bus::DOWNLINK_PACKET_NS;
use skinbox_cells::scene::{BusDownlink, GenerateOptions, Generated, Scene};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_model::cell_uart::{CellUartReceiver, ReceivedPacket, ReceiverCounts};
use skinbox_model::downlink::PinChange;
use skinbox_model::timing::{frame_bits, TICK_ZERO_CYCLE};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::TICK_NS;
use std::time::Instant;

/// A scene run with the loop closed.
#[derive(Debug, Clone)]
pub struct ClosedLoopSpec {
    /// The scene.
    pub scene: Scene,
    /// Scene time at which the box starts to listen, ns.
    pub from_ns: u64,
    /// Scene time the box listens, ns.
    pub duration_ns: u64,
    /// The run: box, host frames, pcap, trace, jitter, duration (its `ports` are the cells').
    pub sim: SimSpec,
    /// Test hook: bit `.1` (in bit times from the first start bit) of the first packet on
    /// port `.0` inverted on its way to the cells (the box's pins are left as they are).
    pub corrupt_uart_tx: Option<(usize, u64)>,
}

impl ClosedLoopSpec {
    /// `scene` from scene time `from_ns` for `duration_ns` on a box of `config` (one port
    /// per bus), the host sending the scene's `[[commands]]` in the window
    /// ([`plan_downlink`]'s frames: a time sync carries the tick the control model says
    /// its packet leaves at, as the gateware sends the bytes it is given); no pcap, trace or
    /// jitter.
    pub fn new(scene: &Scene, config: BoxConfig, from_ns: u64, duration_ns: u64) -> Self {
        let host_frames = plan_downlink(scene, &config, from_ns, duration_ns).host_frames;
        ClosedLoopSpec {
            scene: scene.clone(),
            from_ns,
            duration_ns,
            sim: SimSpec {
                duration_ns: sim_duration_ns(&config, duration_ns),
                ports: vec![vec![]; config.ports],
                config,
                pcap: None,
                vcd: None,
                jitter: crate::line::Jitter::NONE,
                host_frames,
            },
            corrupt_uart_tx: None,
        }
    }
}

/// What came of a closed-loop run.
#[derive(Debug, Clone)]
pub struct ClosedLoopRun {
    /// The run, its packets those the cells sent.
    pub run: SimRun,
    /// The spec as run: the cells' packets on every port.
    pub spec: SimSpec,
    /// The cells as they ran, with what they received.
    pub generated: Generated,
    /// Every cell command packet the cells' receivers took from the transmit pins, in tick
    /// order (ties by port).
    pub received: Vec<ReceivedPacket>,
    /// What the receivers took and rejected.
    pub receiver: ReceiverCounts,
    /// Times the cells were generated (1: no command reached them).
    pub generations: usize,
}

/// The cells of a closed-loop run: their downlink so far and what they send.
#[derive(Clone)]
pub struct Cells {
    spec: ClosedLoopSpec,
    downlink: Vec<BusDownlink>,
    generated: Generated,
    /// Per port, the packets on the pin and the pin's transitions and true start edges.
    ports: Vec<Vec<SentPacket>>,
    lines: Vec<(Vec<Transition>, Vec<f64>)>,
    received: Vec<ReceivedPacket>,
    generations: usize,
}

impl Cells {
    /// The cells with the commands sent before the window only.
    pub fn new(spec: &ClosedLoopSpec) -> Result<Cells, CosimError> {
        let ports = spec.sim.config.ports;
        let downlink = downlink_before(&spec.scene, &spec.sim.config, spec.from_ns);
        let mut cells = Cells {
            spec: spec.clone(),
            generated: generate(spec, &downlink)?,
            downlink,
            ports: vec![],
            lines: vec![],
            received: vec![],
            generations: 1,
        };
        cells.ports = cells.sent(0..ports);
        cells.lines = (0..ports).map(|p| cells.line(p)).collect();
        Ok(cells)
    }

    fn sent(&self, ports: std::ops::Range<usize>) -> Vec<Vec<SentPacket>> {
        let s = &self.spec;
        self.generated.buses[ports]
            .iter()
            .map(|bus| sent_packets(bus, s.from_ns, s.duration_ns))
            .collect()
    }

    fn line(&self, port: usize) -> (Vec<Transition>, Vec<f64>) {
        line(&self.ports[port], &self.spec.sim.jitter, port)
    }

    /// Port `port`'s pin transitions now.
    pub fn transitions(&self, port: usize) -> &[Transition] {
        &self.lines[port].0
    }

    /// Takes the packets the cells' receivers decoded, at simulation cycle `cycle`: each
    /// joins its bus's downlink, the cells are generated again, and the ports whose
    /// packets changed are returned. Fails when a port's packets changed before the
    /// command's earliest effect or before `cycle` (the pin was already driven).
    pub fn receive(
        &mut self,
        packets: &[ReceivedPacket],
        cycle: u64,
    ) -> Result<Vec<usize>, CosimError> {
        if packets.is_empty() {
            return Ok(vec![]);
        }
        let from_ns = self.spec.from_ns;
        for p in packets {
            let leave_ns = scene_ns_of_tick(p.tick, from_ns);
            self.downlink[p.port].push((leave_ns, p.bytes));
        }
        self.received.extend_from_slice(packets);
        self.generated = generate(&self.spec, &self.downlink)?;
        self.generations += 1;
        let mut changed = vec![];
        for port in 0..self.ports.len() {
            let new = self.sent(port..port + 1).remove(0);
            let Some(first) = (0..new.len().max(self.ports[port].len()))
                .find(|&i| new.get(i) != self.ports[port].get(i))
            else {
                continue;
            };
            let earliest_ns = packets
                .iter()
                .filter(|p| p.port == port)
                .map(|p| (p.tick + TICK_ZERO_CYCLE) * TICK_NS + DOWNLINK_PACKET_NS)
                .min()
                .map_or(f64::INFINITY, |ns| ns as f64);
            let at_ns = [&new, &self.ports[port]]
                .iter()
                .filter_map(|l| l.get(first))
                .map(|p| p.start_ns)
                .fold(f64::INFINITY, f64::min);
            if at_ns < earliest_ns || at_ns < (cycle * TICK_NS) as f64 {
                return Err(CosimError::ClosedLoop(format!(
                    "port {port}: the cells' packet {first} changed at {at_ns} ns, before the \
                     command's earliest effect ({earliest_ns} ns) or the cycle reached \
                     ({cycle}): regeneration is not causal"
                )));
            }
            self.ports[port] = new;
            self.lines[port] = self.line(port);
            changed.push(port);
        }
        Ok(changed)
    }

    /// The spec with the cells' packets, their transitions' true start edges, and the
    /// rest of what came of them.
    fn finish(
        self,
    ) -> (
        SimSpec,
        Vec<Vec<f64>>,
        Generated,
        Vec<ReceivedPacket>,
        usize,
    ) {
        let mut spec = self.spec.sim.clone();
        spec.ports = self.ports;
        let mut received = self.received;
        received.sort_by_key(|p| (p.tick, p.port));
        let starts = self.lines.into_iter().map(|l| l.1).collect();
        (spec, starts, self.generated, received, self.generations)
    }
}

/// The scene's cells over the run's window with `downlink` (per bus).
fn generate(spec: &ClosedLoopSpec, downlink: &[BusDownlink]) -> Result<Generated, CosimError> {
    Ok(generate_with(
        &spec.scene,
        (spec.from_ns + spec.duration_ns) as f64 * 1e-9,
        &GenerateOptions {
            downlink: Some(downlink.to_vec()),
            ..Default::default()
        },
    )?)
}

/// Clock cycles of one step of a closed-loop run of a box of `config` on the buses of
/// `scene` with edge jitter `jitter_ns`: the margin between a command's last stop bit's
/// middle on the pin and the first pin transition it can change (module doc). Fails when
/// there is none (a scene whose cells act on a command before it is on the pin whole).
pub fn step_cycles(config: &BoxConfig, scene: &Scene, jitter_ns: f64) -> Result<u64, CosimError> {
    let bit_ns = 1e9 / config.baud as f64;
    let received_ns = ((PACKET_LEN as f64 - 1.0) * frame_bits(config.ports) as f64 + 9.5) * bit_ns;
    let margin_ns = (DOWNLINK_PACKET_NS + scene.config.bus.processing_ns) as f64
        - received_ns
        - jitter_ns
        - 2.0 * TICK_NS as f64;
    let cycles = (margin_ns / TICK_NS as f64).floor();
    if cycles < 1.0 {
        return Err(CosimError::ClosedLoop(format!(
            "the cells act on a command {margin_ns:.0} ns before its last stop bit is on the pin"
        )));
    }
    Ok((cycles as u64).min(PROGRESS_STEP))
}

/// Runs `spec` with the loop closed at `fidelity`, calling `progress(cycles done, cycles in
/// all)` as it goes.
pub fn run_closed_loop(
    spec: &ClosedLoopSpec,
    fidelity: Fidelity,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ClosedLoopRun, CosimError> {
    match fidelity {
        Fidelity::Rtl => run_rtl(spec, progress),
        Fidelity::Reference => run_reference(spec, progress),
    }
}

/// The cells' receivers, with the test hook's inversion between the pins and them.
struct Receivers {
    rx: CellUartReceiver,
    corrupt: Option<Corruption>,
    buffer: Vec<PinChange>,
}

impl Receivers {
    fn new(spec: &ClosedLoopSpec) -> Receivers {
        let c = &spec.sim.config;
        Receivers {
            rx: CellUartReceiver::new(c.ports, c.clock_hz, c.baud),
            corrupt: spec.corrupt_uart_tx.map(|(port, bit)| Corruption {
                port,
                bit,
                bit_ticks: c.clock_hz as f64 / c.baud as f64,
                raw_level: true,
                interval: None,
                emitted: 0,
            }),
            buffer: vec![],
        }
    }

    /// Takes `changes` (in tick order); the pins are known up to (not including) `until`.
    fn take(&mut self, changes: &[PinChange], until: u64) -> Vec<ReceivedPacket> {
        self.buffer.clear();
        for c in changes {
            match &mut self.corrupt {
                Some(corrupt) => corrupt.filter(*c, &mut self.buffer),
                None => self.buffer.push(*c),
            }
        }
        if let Some(corrupt) = &mut self.corrupt {
            corrupt.boundaries(until, &mut self.buffer);
        }
        for c in &self.buffer {
            self.rx.push(c);
        }
        self.rx.advance_to(until)
    }
}

/// One bit of one port's first packet inverted (the test hook).
struct Corruption {
    port: usize,
    bit: u64,
    bit_ticks: f64,
    /// The pin's level after the changes taken.
    raw_level: bool,
    /// Ticks `from..to` of the inverted bit, once the first start bit was seen.
    interval: Option<(u64, u64)>,
    /// Boundaries of the interval emitted (0, 1 or 2).
    emitted: usize,
}

impl Corruption {
    /// The changes at the interval's boundaries before `until`.
    fn boundaries(&mut self, until: u64, out: &mut Vec<PinChange>) {
        let Some((from, to)) = self.interval else {
            return;
        };
        for (i, (tick, level)) in [(from, !self.raw_level), (to, self.raw_level)]
            .into_iter()
            .enumerate()
        {
            if self.emitted == i && tick < until {
                out.push(PinChange {
                    tick,
                    port: self.port,
                    level,
                });
                self.emitted += 1;
            }
        }
    }

    fn filter(&mut self, c: PinChange, out: &mut Vec<PinChange>) {
        if c.port != self.port {
            out.push(c);
            return;
        }
        self.boundaries(c.tick, out);
        self.raw_level = c.level;
        if self.interval.is_none() && !c.level {
            let at = |bit: u64| c.tick + (bit as f64 * self.bit_ticks) as u64;
            self.interval = Some((at(self.bit), at(self.bit + 1)));
        }
        let inside = self
            .interval
            .is_some_and(|(from, to)| (from..to).contains(&c.tick));
        out.push(PinChange {
            level: c.level ^ inside,
            ..c
        });
        self.boundaries(c.tick + 1, out);
    }
}

/// The verilated box in steps, the cells hearing its pins.
fn run_rtl(
    spec: &ClosedLoopSpec,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ClosedLoopRun, CosimError> {
    let sim = &spec.sim;
    let mut cells = Cells::new(spec)?;
    let model = Model::build(&sim.config, sim.vcd.is_some(), &default_cache_dir())?;
    let mut dut = Dut::new(&model, sim.vcd.as_deref())?;
    for f in &sim.host_frames {
        dut.queue_rx_frame(f.edge, &f.wire())
            .map_err(CosimError::HostFrames)?;
    }
    let cycles = cycles(sim);
    // no command from the host and no sync of the box's own: nothing comes down, the
    // cells run as generated
    let step = match sim.host_frames.is_empty() && sim.config.sync_period_ticks == 0 {
        true => PROGRESS_STEP,
        false => step_cycles(&sim.config, &spec.scene, sim.jitter.peak_ns)?,
    };
    let started = Instant::now();
    let lines = (0..sim.config.ports)
        .map(|p| cells.transitions(p).to_vec())
        .collect();
    let mut player = Player::new(&mut dut, lines, RESET_CYCLES);
    let mut receivers = Receivers::new(spec);
    let (mut out, mut uart_tx) = (vec![], vec![]);
    let mut next_report = 0;
    while player.cycle() < cycles {
        let to = (player.cycle() + step).min(cycles);
        out.extend(player.run_to(to));
        let changes = uart_tx_changes(player.dut());
        let packets = receivers.take(&changes, to + 1 - TICK_ZERO_CYCLE);
        uart_tx.extend(changes);
        for port in cells.receive(&packets, to)? {
            player.replace_line(port, cells.transitions(port).to_vec());
        }
        if to >= next_report {
            progress(to, cycles);
            next_report = to + PROGRESS_STEP;
        }
    }
    drop(player);
    let wall = started.elapsed().as_secs_f64();
    let (frames, _) = crate::frames::assemble(&out);
    uart_tx.sort_by_key(|c| (c.tick, c.port));
    finish(cells, receivers, &frames, wall, uart_tx)
}

/// The analysis of a closed-loop run's frames.
fn finish(
    cells: Cells,
    receivers: Receivers,
    frames: &[crate::frames::Frame],
    wall: f64,
    uart_tx: Vec<PinChange>,
) -> Result<ClosedLoopRun, CosimError> {
    let (spec, starts, generated, received, generations) = cells.finish();
    let mut run = analyse(&spec, frames, &starts, wall)?;
    run.uart_tx = uart_tx;
    Ok(ClosedLoopRun {
        run,
        spec,
        generated,
        received,
        receiver: receivers.rx.counts(),
        generations,
    })
}

/// The reference model, the cells generated once with its downlink (module doc).
fn run_reference(
    spec: &ClosedLoopSpec,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ClosedLoopRun, CosimError> {
    let sim = &spec.sim;
    let mut cells = Cells::new(spec)?;
    // as open-loop, the cells generated ahead are not timed
    let started = Instant::now();
    let cycles = cycles(sim);
    // no command from the host and no sync of the box's own: nothing comes down
    let pins = match sim.host_frames.is_empty() && sim.config.sync_period_ticks == 0 {
        true => vec![],
        false => {
            skinbox_model::reference::predict_with_host_frames(
                &sim.config,
                &[],
                &sim.host_frames,
                cycles,
                &mut |_, _| {},
            )?
            .1
        }
    };
    let mut receivers = Receivers::new(spec);
    let packets = receivers.take(&pins, u64::MAX);
    cells.receive(&packets, 0)?;
    let lines: Vec<Vec<Transition>> = (0..sim.config.ports)
        .map(|p| cells.transitions(p).to_vec())
        .collect();
    let (frames, uart_tx) = skinbox_model::reference::predict_with_host_frames(
        &sim.config,
        &lines,
        &sim.host_frames,
        cycles,
        progress,
    )?;
    if uart_tx != pins {
        return Err(CosimError::ClosedLoop(
            "the reference model's transmit pins changed with the cells' packets".into(),
        ));
    }
    let wall = started.elapsed().as_secs_f64();
    finish(cells, receivers, &frames, wall, uart_tx)
}
