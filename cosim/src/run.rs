//! What a run is and what came out of it: the spec (packets on the box's UART pins), the
//! pin lines it makes, and the analysis of the frames (every one checked), shared by the RTL
//! runner ([`crate::sim`]) and the reference model ([`crate::reference`]).

use crate::error::CosimError;
use crate::frames::{check, is_reply, min_gap, Frame};
use crate::line::{back_to_back, jittered_transitions, Jitter, Transition, UartByte};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_model::downlink::PinChange;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::{DatagramRepr, PortCounters, TICK_NS};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

/// One cell packet as it leaves the bus root on its way to a box pin.
#[derive(Debug, Clone, PartialEq)]
pub struct SentPacket {
    /// The 20 bytes.
    pub bytes: [u8; PACKET_LEN],
    /// Falling edge of the first start bit at the box pin, ns from the simulation start.
    pub start_ns: f64,
    /// Bit length of the sending UART, ns.
    pub bit_ns: f64,
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimSpec {
    /// Box parameters.
    pub config: BoxConfig,
    /// Packets per port, each port's in time order and not overlapping.
    pub ports: Vec<Vec<SentPacket>>,
    /// Simulated time, ns (the box also needs time to flush after the last packet).
    pub duration_ns: u64,
    /// Write the frames here.
    pub pcap: Option<PathBuf>,
    /// Write a VCD trace here (builds a traced model).
    pub vcd: Option<PathBuf>,
    /// Edge jitter of every line (seeded per port from `jitter.seed`).
    pub jitter: Jitter,
    /// Frames the host sends to the box, in edge order, each starting after the one
    /// before it ended.
    pub host_frames: Vec<HostFrame>,
}

pub use skinbox_model::frame::HostFrame;
/// The reset of a run and box tick 0 ([`skinbox_model::timing`]).
pub use skinbox_model::timing::{PORTS_READY_CYCLE, RESET_CYCLES, TICK_ZERO_CYCLE};

/// What came out, checked.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SimReport {
    /// Frames the box sent; every one passed the independent checks, but for
    /// `frames_cut_at_end`.
    pub frames: u64,
    /// The frame still going out when the run ended, cut there (0 or 1): not checked, its
    /// records not delivered.
    pub frames_cut_at_end: u64,
    /// Answers to the host's frames (ARP, echo replies, acknowledgements), not checked
    /// here: the receive path's tests compare them with the control model.
    pub replies: u64,
    /// Records datagrams.
    pub record_datagrams: u64,
    /// Status datagrams.
    pub status_datagrams: u64,
    /// Records received.
    pub records: u64,
    /// Packets put on the pins.
    pub packets_sent: u64,
    /// Packets sent that came back in a record unchanged.
    pub packets_delivered: u64,
    /// Records whose cell bytes match no packet sent on their port (must be 0).
    pub records_corrupted: u64,
    /// Packets delivered with their bytes intact but a stamp more than one tick from their
    /// true start edge (must be 0): a wrong time the packet checks cannot see.
    pub records_mistimed: u64,
    /// Packets sent but not delivered (the box's counters must explain them).
    pub dropped: u64,
    /// Good packets the box counted, from the last status report, summed over ports.
    pub box_packets_good: u64,
    /// Losses by cause from the last status report, summed over ports.
    pub losses_by_cause: Vec<(String, u64)>,
    /// Largest stamp minus true start edge, in ticks (must be below 1).
    pub ts_error_max_ticks: f64,
    /// Mean stamp minus true start edge, in ticks.
    pub ts_error_mean_ticks: f64,
    /// Smallest gap between frames, clocks.
    pub min_inter_frame_gap: Option<u64>,
    /// Simulated seconds.
    pub sim_seconds: f64,
    /// Wall-clock seconds of the clock loop (model build excluded).
    pub wall_seconds: f64,
    /// Simulated clock cycles per wall second.
    pub cycles_per_second: f64,
}

/// A finished run: the report and every datagram the box sent, in order.
#[derive(Debug, Clone)]
pub struct SimRun {
    /// What came out, checked.
    pub report: SimReport,
    /// The box's datagrams (every frame passed the independent checks).
    pub datagrams: Vec<DatagramRepr>,
    /// The frames as sent, preamble to FCS, with the cycle of their first byte.
    pub frames: Vec<Frame>,
    /// The box's answers to the host's frames, in the order sent: ARP replies, echo
    /// replies and command acknowledgements (preamble to FCS).
    pub replies: Vec<Frame>,
    /// The downlink: every change of a UART transmit pin, in tick order (ties by port).
    pub uart_tx: Vec<PinChange>,
}

/// Every port's pin transitions (each line with its own seeded jitter) and the true,
/// jittered start edge of every packet, ns.
pub fn lines(spec: &SimSpec) -> (Vec<Vec<Transition>>, Vec<Vec<f64>>) {
    spec.ports
        .iter()
        .enumerate()
        .map(|(port, packets)| line(packets, &spec.jitter, port))
        .unzip()
}

/// Port `port`'s pin transitions for `packets` with the spec's `jitter` (seeded for the
/// port) and the true, jittered start edge of every packet, ns.
pub fn line(packets: &[SentPacket], jitter: &Jitter, port: usize) -> (Vec<Transition>, Vec<f64>) {
    let bytes: Vec<UartByte> = packets
        .iter()
        .flat_map(|p| back_to_back(&p.bytes, p.start_ns, p.bit_ns))
        .collect();
    let jitter = Jitter {
        seed: jitter.seed.wrapping_add(port as u64),
        ..*jitter
    };
    let (line, starts) = jittered_transitions(&bytes, &jitter);
    (line, starts.iter().step_by(PACKET_LEN).copied().collect())
}

/// Clock cycles a spec runs for.
pub fn cycles(spec: &SimSpec) -> u64 {
    spec.duration_ns / TICK_NS
}

/// The pcap writer of a run.
type Pcap = skinbox_protocol::pcap::PcapFrameWriter<std::fs::File>;

/// Checks every frame, writes the pcap and measures what the frames delivered.
pub(crate) fn analyse(
    spec: &SimSpec,
    frames: &[Frame],
    true_starts: &[Vec<f64>],
    wall: f64,
) -> Result<SimRun, CosimError> {
    let cycles = cycles(spec);
    let mut report = SimReport {
        frames: frames.len() as u64,
        packets_sent: spec.ports.iter().map(|p| p.len() as u64).sum(),
        min_inter_frame_gap: min_gap(frames),
        sim_seconds: cycles as f64 * TICK_NS as f64 * 1e-9,
        wall_seconds: wall,
        cycles_per_second: cycles as f64 / wall.max(1e-9),
        ..Default::default()
    };
    let mut pcap = open_pcap(spec)?;
    let mut tally = Tally::new(spec, true_starts);
    let mut datagrams = Vec::with_capacity(frames.len());
    let mut replies = vec![];
    // the host's frames go into the pcap beside the box's, by the cycle of their first byte
    let mut host_frames = spec.host_frames.iter().peekable();
    let mut write_host_frames = |until: u64, pcap: &mut Option<Pcap>| -> Result<(), CosimError> {
        while let Some(f) = host_frames.next_if(|f| f.edge <= until) {
            if let Some(pcap) = pcap {
                let ethernet = &f.frame[..f
                    .frame
                    .len()
                    .saturating_sub(skinbox_protocol::link::FCS_LEN)];
                pcap.write_frame(Duration::from_nanos(f.edge * TICK_NS), ethernet)
                    .map_err(pcap_error)?;
            }
        }
        Ok(())
    };
    for frame in frames {
        write_host_frames(frame.first_cycle, &mut pcap)?;
        if is_reply(&frame.bytes) {
            if let Some(pcap) = &mut pcap {
                let ethernet = &frame.bytes[8..frame.bytes.len() - 4];
                pcap.write_frame(Duration::from_nanos(frame.first_cycle * TICK_NS), ethernet)
                    .map_err(pcap_error)?;
            }
            report.replies += 1;
            replies.push(frame.clone());
            continue;
        }
        let (ethernet, payload) = match check(&frame.bytes) {
            Ok(checked) => checked,
            // the last frame, cut where the run ended (it reaches the last cycle)
            Err(_) if frame.first_cycle + frame.bytes.len() as u64 > cycles => {
                report.frames_cut_at_end += 1;
                continue;
            }
            Err(source) => {
                return Err(CosimError::Frame {
                    step: "checking a frame",
                    source,
                })
            }
        };
        if let Some(pcap) = &mut pcap {
            pcap.write_frame(Duration::from_nanos(frame.first_cycle * TICK_NS), ethernet)
                .map_err(pcap_error)?;
        }
        let datagram = DatagramRepr::parse(payload)?;
        tally.datagram(&mut report, &datagram, spec.config.ports)?;
        datagrams.push(datagram);
    }
    write_host_frames(u64::MAX, &mut pcap)?;
    if let Some(pcap) = pcap {
        pcap.finish().map_err(pcap_error)?;
    }
    tally.finish(&mut report);
    Ok(SimRun {
        report,
        datagrams,
        frames: frames.to_vec(),
        replies,
        uart_tx: Vec::new(),
    })
}

/// The spec's pcap writer, if it asks for one.
fn open_pcap(spec: &SimSpec) -> Result<Option<Pcap>, CosimError> {
    Ok(match &spec.pcap {
        Some(path) => Some(
            skinbox_protocol::pcap::PcapFrameWriter::new(std::fs::File::create(path).map_err(
                |source| CosimError::Io {
                    path: path.clone(),
                    source,
                },
            )?)
            .map_err(pcap_error)?,
        ),
        None => None,
    })
}

/// What the datagrams delivered, matched against the packets sent.
struct Tally<'a> {
    /// Each port's packets with their true start edges, to be matched in order.
    pending: Vec<VecDeque<(&'a SentPacket, f64)>>,
    /// Each port's counters in the last status report.
    last_status: Vec<PortCounters>,
    error_sum: f64,
    error_count: u64,
}

impl<'a> Tally<'a> {
    fn new(spec: &'a SimSpec, true_starts: &[Vec<f64>]) -> Self {
        Tally {
            pending: spec
                .ports
                .iter()
                .zip(true_starts)
                .map(|(p, t)| p.iter().zip(t.iter().copied()).collect())
                .collect(),
            last_status: vec![PortCounters::default(); spec.config.ports],
            error_sum: 0.0,
            error_count: 0,
        }
    }

    /// Counts one datagram of a `ports`-port box.
    fn datagram(
        &mut self,
        report: &mut SimReport,
        datagram: &DatagramRepr,
        ports: usize,
    ) -> Result<(), CosimError> {
        match &datagram.body {
            DatagramBody::Records(records) => {
                report.record_datagrams += 1;
                for r in records {
                    report.records += 1;
                    // a port the box does not have matches no packet sent
                    let Some(queue) = self.pending.get_mut(usize::from(r.port)) else {
                        report.records_corrupted += 1;
                        continue;
                    };
                    // packets before this one on the port were lost
                    match queue.iter().position(|p| p.0.bytes == r.cell_packet) {
                        Some(k) => {
                            queue.drain(..k);
                            let (_, true_start_ns) = queue.pop_front().expect("found above");
                            report.packets_delivered += 1;
                            let stamp_ns = (r.tick(datagram.base_tick) + TICK_ZERO_CYCLE) as f64
                                * TICK_NS as f64;
                            let error = (stamp_ns - true_start_ns) / TICK_NS as f64;
                            if error.abs() > 1.0 {
                                report.records_mistimed += 1;
                            }
                            report.ts_error_max_ticks = report.ts_error_max_ticks.max(error);
                            self.error_sum += error;
                            self.error_count += 1;
                        }
                        None => report.records_corrupted += 1,
                    }
                }
            }
            DatagramBody::Status(status) => {
                report.status_datagrams += 1;
                for (i, counters) in status.ports.iter().enumerate() {
                    let port = usize::from(status.first_port) + i;
                    let slot =
                        self.last_status
                            .get_mut(port)
                            .ok_or(CosimError::BoxOutput(format!(
                                "status counters for port {port} of a {ports}-port box",
                            )))?;
                    *slot = *counters;
                }
            }
        }
        Ok(())
    }

    /// The report's totals: timing error, losses, the box's own counts.
    fn finish(self, report: &mut SimReport) {
        report.ts_error_mean_ticks = if self.error_count > 0 {
            self.error_sum / self.error_count as f64
        } else {
            0.0
        };
        report.dropped = report.packets_sent - report.packets_delivered;
        report.box_packets_good = self
            .last_status
            .iter()
            .map(|p| u64::from(p.get(PortCounter::PacketsGood)))
            .sum();
        report.losses_by_cause = PortCounter::ALL
            .iter()
            .filter(|c| c.is_packet_loss() || **c == PortCounter::GarbageBytes)
            .map(|c| {
                (
                    c.name().to_string(),
                    self.last_status.iter().map(|p| u64::from(p.get(*c))).sum(),
                )
            })
            .collect();
    }
}

fn pcap_error(e: impl std::fmt::Display) -> CosimError {
    CosimError::Pcap(e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_frame_check::{encode, UdpAddresses};

    fn spec() -> SimSpec {
        SimSpec {
            config: BoxConfig::default(),
            ports: vec![Vec::new(); 8],
            duration_ns: 100_000,
            pcap: None,
            vcd: None,
            jitter: Jitter::NONE,
            host_frames: vec![],
        }
    }

    /// A frame as the box would send it, built by frame-check's encoder.
    fn frame(payload: &[u8]) -> Frame {
        let link = BoxConfig::default().link;
        let addresses = UdpAddresses {
            source_mac: link.box_mac,
            destination_mac: link.host_mac,
            source_ip: link.box_ip,
            destination_ip: link.host_ip,
            source_port: link.box_port,
            destination_port: link.host_port,
        };
        Frame {
            first_cycle: 10,
            bytes: encode(&addresses, payload).unwrap(),
        }
    }

    #[test]
    fn analysis_names_a_bad_frame_and_a_payload_that_is_no_datagram() {
        let status = DatagramRepr {
            box_id: 1,
            port_count: 8,
            flags: 0,
            sequence: 0,
            base_tick: 0,
            body: DatagramBody::Status(skinbox_protocol::StatusRepr {
                boot_id: 1,
                datagrams_sent: 0,
                records_sent: 0,
                first_port: 0,
                ports: vec![PortCounters::default(); 8],
            }),
        };
        let good = frame(&status.to_bytes());
        let run = analyse(&spec(), std::slice::from_ref(&good), &[], 0.0).unwrap();
        assert_eq!(run.report.status_datagrams, 1);

        let mut bad_fcs = good.clone();
        *bad_fcs.bytes.last_mut().unwrap() ^= 1;
        assert!(matches!(
            analyse(&spec(), &[bad_fcs], &[], 0.0),
            Err(CosimError::Frame {
                step: "checking a frame",
                ..
            })
        ));
        // the same frame cut short: at the end of the run (12,500 cycles) it is the frame the
        // run ended in, counted and skipped; anywhere else it is an error
        let mut cut = good.clone();
        cut.bytes.truncate(40);
        cut.first_cycle = 12_500 + 1 - 40;
        let run = analyse(&spec(), &[good.clone(), cut.clone()], &[], 0.0).unwrap();
        assert_eq!(
            (run.report.frames_cut_at_end, run.report.status_datagrams),
            (1, 1)
        );
        cut.first_cycle -= 1;
        assert!(matches!(
            analyse(&spec(), &[good.clone(), cut], &[], 0.0),
            Err(CosimError::Frame {
                step: "checking a frame",
                ..
            })
        ));
        assert!(matches!(
            analyse(&spec(), &[frame(&[0; 40])], &[], 0.0),
            Err(CosimError::Datagram(
                skinbox_protocol::Error::BadMagic { .. }
            ))
        ));
    }

    /// Ports an 8-port box does not have: a record is corrupted, status counters an error.
    #[test]
    fn ports_beyond_the_box_are_counted_or_refused_not_indexed() {
        let starts = vec![Vec::new(); 8];
        let records = DatagramRepr {
            box_id: 1,
            port_count: 16,
            flags: 0,
            sequence: 0,
            base_tick: 0,
            body: DatagramBody::Records(vec![skinbox_protocol::RecordRepr {
                port: 9,
                flags: 0,
                tick_offset: 0,
                cell_packet: skinbox_protocol::DataRepr::default().to_bytes(),
            }]),
        };
        let run = analyse(&spec(), &[frame(&records.to_bytes())], &starts, 0.0).unwrap();
        assert_eq!((run.report.records, run.report.records_corrupted), (1, 1));

        let status = DatagramRepr {
            box_id: 1,
            port_count: 16,
            flags: 0,
            sequence: 1,
            base_tick: 0,
            body: DatagramBody::Status(skinbox_protocol::StatusRepr {
                boot_id: 1,
                datagrams_sent: 0,
                records_sent: 0,
                first_port: 4,
                ports: vec![PortCounters::default(); 8],
            }),
        };
        let err = analyse(&spec(), &[frame(&status.to_bytes())], &starts, 0.0).unwrap_err();
        assert!(err.to_string().contains("port 8 of a 8-port box"), "{err}");
    }
}
