//! The box's receive path at RTL: frames built with etherparse and the crc crate are driven
//! on the verilated box's GMII receive while its ports carry cell traffic, and every answer
//! it sends (ARP reply, echo reply, acknowledgement) must equal, byte for byte, what the
//! control model (`skinbox_model::control`, itself held to independent oracles in
//! model/tests/control.rs) answers to the same frames; the box counters in its status-now
//! acknowledgements must equal the model's. The uplink meanwhile loses nothing.

mod support;

use skinbox_cosim::frames::Frame;
use skinbox_cosim::harness::{LINK_SPEED, LINK_UP};
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::run::{HostFrame, SentPacket, SimRun, SimSpec, TICK_ZERO_CYCLE};
use skinbox_cosim::sim::run_rtl;
use skinbox_gateware::interface_box::{BoxConfig, RECEIVE_TICK_LAG};
use skinbox_model::control::{BoxControl, ControlConfig, Reply};
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::{UART_BAUD, UART_BITS_PER_PACKET};
use skinbox_protocol::command::{AckRepr, Request};
use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
use skinbox_protocol::{DatagramRepr, TICKS_PER_SECOND, TICK_NS};
use std::collections::BTreeMap;
use support::*;

/// Ticks of one cell packet on its 4 Mbit/s line.
const PACKET_TICKS: u64 = UART_BITS_PER_PACKET * TICKS_PER_SECOND / UART_BAUD;

/// The control model as the co-simulated box starts: its link as the harness drives it.
fn model(config: ControlConfig) -> BoxControl {
    let mut m = BoxControl::new(config);
    m.counters.link_up = LINK_UP;
    m.counters.link_speed = LINK_SPEED;
    m
}

fn spec(
    config: BoxConfig,
    ports: Vec<Vec<SentPacket>>,
    host_frames: Vec<HostFrame>,
    duration_ns: u64,
) -> SimSpec {
    SimSpec {
        config,
        ports,
        duration_ns,
        pcap: None,
        vcd: None,
        jitter: skinbox_cosim::line::Jitter::NONE,
        host_frames,
    }
}

/// The tick the box gives a host frame's arrival (its last byte).
fn receive_tick(f: &HostFrame) -> u64 {
    f.last_edge() + RECEIVE_TICK_LAG - TICK_ZERO_CYCLE
}

/// The tick of a sent frame's first byte.
fn send_tick(f: &Frame) -> u64 {
    f.first_cycle - TICK_ZERO_CYCLE
}

/// Runs `spec` on the RTL and on the reference model, which must agree on every frame
/// (replies included) and the cycle of its first byte.
fn run_both(spec: &SimSpec) -> SimRun {
    let run = run_rtl(spec).unwrap();
    let predicted = run_reference(spec).unwrap();
    for (i, (r, p)) in run.frames.iter().zip(&predicted.frames).enumerate() {
        assert!(
            r == p,
            "frame {i}: RTL at cycle {} ({} bytes), reference at {} ({} bytes)\n RTL: {:02x?}\n ref: {:02x?}",
            r.first_cycle,
            r.bytes.len(),
            p.first_cycle,
            p.bytes.len(),
            &r.bytes[..r.bytes.len().min(120)],
            &p.bytes[..p.bytes.len().min(120)]
        );
    }
    assert_eq!(run.frames.len(), predicted.frames.len(), "frames sent");
    run
}

/// Feeds the host frames to the model and checks the box's answers against the model's,
/// in order, byte for byte (an acknowledgement's send tick is the tick its frame started
/// at). Returns the model.
fn check_answers(
    run: &SimRun,
    host_frames: &[HostFrame],
    mut m: BoxControl,
    slot_free: impl Fn(usize) -> bool,
) -> BoxControl {
    let mut answers = run.replies.iter();
    for (i, f) in host_frames.iter().enumerate() {
        let outcome = m.receive_with_slot(&f.frame, receive_tick(f), slot_free(i));
        let Some(reply) = outcome.reply else {
            continue;
        };
        let got = answers
            .next()
            .unwrap_or_else(|| panic!("frame {i} ({:?}) was not answered", outcome.fate));
        let expected = match &reply {
            Reply::Arp(bytes) | Reply::Echo(bytes) => bytes.clone(),
            Reply::Ack { .. } => reply.frame(&m.config().link, send_tick(got)),
        };
        if got.bytes != expected {
            let ack = |b: &[u8]| AckRepr::parse(&b[8 + 42..b.len() - 4]).ok();
            panic!(
                "frame {i} ({:?}): answer differs\n box:   {:02x?}\n model: {:02x?}\n acks: {:?} / {:?}",
                outcome.fate,
                got.bytes,
                expected,
                ack(&got.bytes),
                ack(&expected)
            );
        }
    }
    assert!(
        answers.next().is_none(),
        "the box answered more than the model"
    );
    m
}

/// Runs `host_frames` on the RTL and the reference model (which must agree) with the
/// ports' traffic, and checks every answer against the control model's (the buffer free
/// for every frame: they come far enough apart); returns the run and the model after it.
fn answer_all(
    config: &BoxConfig,
    ports: Vec<Vec<SentPacket>>,
    host_frames: &[HostFrame],
    duration_ns: u64,
) -> (SimRun, BoxControl) {
    let run = run_both(&spec(
        config.clone(),
        ports,
        host_frames.to_vec(),
        duration_ns,
    ));
    let m = check_answers(
        &run,
        host_frames,
        model(skinbox_model::emulator::control_config(config)),
        |_| true,
    );
    (run, m)
}

#[test]
fn answers_equal_the_control_model_on_random_good_and_bad_frames() {
    let config = box_config();
    let mut rng = Rng(0x005E_C04D);
    let mut next_sequence = BTreeMap::new();
    let mut accepted = vec![];
    let mut host_frames = vec![];
    let mut fates: BTreeMap<&str, u32> = BTreeMap::new();
    // frames 40 us apart: every answer has left before the next frame comes
    let mut edge = 20_000;
    while host_frames.len() < 240 {
        let case = random_case(&mut rng, &mut next_sequence, &mut accepted);
        *fates.entry(case.fate.name()).or_default() += 1;
        host_frames.push(HostFrame {
            edge,
            frame: case.frame,
        });
        edge += 5_000;
    }
    // a status-now at the end: its acknowledgement carries every counter
    host_frames.push(HostFrame {
        edge,
        frame: command(HOST_IP, u32::MAX / 2, Request::StatusNow),
    });
    let duration_ns = (edge + 10_000) * TICK_NS;
    let ports = traffic(
        config.ports,
        30_000.0,
        duration_ns as f64 - 200_000.0,
        400_000.0,
    );
    let (run, m) = answer_all(&config, ports, &host_frames, duration_ns);
    // every kind of fate the generator makes occurred and was counted, and the status
    // report after the last frame carries the same counters
    assert!(fates.len() >= 15, "fates {fates:?}");
    for c in BoxCounter::ALL {
        if c != BoxCounter::FramesReceived && c != BoxCounter::ReplyBusy {
            assert_eq!(
                m.counters.get(c),
                fates.get(c.name()).copied().unwrap_or(0)
                    + u32::from(c == BoxCounter::CommandsAccepted),
                "{}",
                c.name()
            );
        }
    }
    let r = &run.report;
    assert_eq!(
        (r.packets_delivered, r.records_corrupted, r.records_mistimed),
        (r.packets_sent, 0, 0),
        "the uplink lost nothing: {r:?}"
    );
}

#[test]
fn commands_reconfigure_the_uplink_under_line_rate_traffic() {
    let config = box_config();
    let link = config.link;
    let ms = 125_000;
    // every port at line rate (a packet every 200 bits) for 6 ms
    let ports = traffic(config.ports, 30_000.0, 6_000_000.0, 50_000.0);
    let sequence = 10;
    let at = |ms_: f64| (ms_ * ms as f64) as u64;
    let host_frames = vec![
        // who has the box's IP; ping it
        HostFrame {
            edge: at(0.5),
            frame: arp_request(link.box_ip, HOST_MAC, HOST_IP),
        },
        HostFrame {
            edge: at(0.6),
            frame: ping(link.box_mac, link.box_ip, 0x1234, 1, &[0xAB; 56]),
        },
        // claim the stream: datagrams go to the sender from then on
        HostFrame {
            edge: at(1.0),
            frame: command(HOST_IP, sequence, Request::StreamTo { to: None }),
        },
        // flush after 10 us
        HostFrame {
            edge: at(2.0),
            frame: command(
                HOST_IP,
                sequence + 1,
                Request::SetFlushTimeout { ticks: 1_250 },
            ),
        },
        // a status report every ms, counted from 3 ms
        HostFrame {
            edge: at(3.0),
            frame: command(
                HOST_IP,
                sequence + 2,
                Request::SetStatusPeriod { ticks: ms as u32 },
            ),
        },
        // a status report now
        HostFrame {
            edge: at(4.5),
            frame: command(HOST_IP, sequence + 3, Request::StatusNow),
        },
        // a replay: refused and counted
        HostFrame {
            edge: at(5.0),
            frame: command(HOST_IP, sequence + 3, Request::ReadTick),
        },
    ];
    let duration_ns = at(7.0) * TICK_NS;
    let (run, m) = answer_all(&config, ports, &host_frames, duration_ns);
    assert_eq!(m.counters.get(BoxCounter::ArpAnswered), 1);
    assert_eq!(m.counters.get(BoxCounter::PingsAnswered), 1);
    assert_eq!(m.counters.get(BoxCounter::CommandsAccepted), 4);
    assert_eq!(m.counters.get(BoxCounter::RefusedReplay), 1);
    let r = &run.report;
    assert_eq!(
        (r.packets_delivered, r.records_corrupted, r.records_mistimed),
        (r.packets_sent, 0, 0),
        "no record lost while the box answered: {r:?}"
    );

    // the frames' destinations and the datagrams' timing, tick by tick
    let mut status_ticks = vec![];
    for frame in run.frames.iter().filter(|f| !run.replies.contains(f)) {
        let (ethernet, payload) = skinbox_cosim::frames::check(&frame.bytes).unwrap();
        let d = DatagramRepr::parse(payload).unwrap();
        let tick = send_tick(frame);
        let claimed = tick > receive_tick(&host_frames[2]) + 1_000;
        let destination_mac = &ethernet[0..6];
        let destination_ip = &ethernet[30..34];
        if claimed {
            assert_eq!(destination_mac, HOST_MAC, "tick {tick}");
            assert_eq!(destination_ip, HOST_IP, "tick {tick}");
            assert_eq!(&ethernet[36..38], HOST_PORT.to_be_bytes(), "tick {tick}");
        } else if tick < receive_tick(&host_frames[2]) {
            assert_eq!(destination_mac, link.host_mac, "tick {tick}");
            assert_eq!(destination_ip, link.host_ip, "tick {tick}");
        }
        match &d.body {
            DatagramBody::Records(records) => {
                // after the new flush timeout every datagram closed within 10 us of its
                // first record's arrival (its stamp is its start bit, a packet's time on
                // the line earlier), and went out soon after
                let opened = d.base_tick;
                if opened > receive_tick(&host_frames[3]) + 1_000 {
                    assert_ne!(d.flags & FLAG_FLUSH_TIMEOUT, 0, "tick {tick}");
                    assert!(
                        tick - opened < PACKET_TICKS + 1_250 + 1_000,
                        "opened {opened}, sent {tick}"
                    );
                    assert!(!records.is_empty());
                } else if opened + 12_500 < receive_tick(&host_frames[3]) {
                    assert!(tick - opened >= 1_250, "opened {opened}, sent {tick}");
                }
            }
            DatagramBody::Status(_) => status_ticks.push(d.base_tick),
        }
    }
    // reports at reset, every ms from 4 ms on, and one right after the status-now
    let set = receive_tick(&host_frames[4]);
    let now = receive_tick(&host_frames[5]);
    let after: Vec<u64> = status_ticks.iter().copied().filter(|&t| t > set).collect();
    assert!(
        after.iter().any(|&t| t > now && t < now + 2_000),
        "a report right after status-now: {status_ticks:?}"
    );
    let periodic: Vec<u64> = after
        .iter()
        .copied()
        .filter(|&t| t < now || t > now + 2_000)
        .collect();
    assert_eq!(
        periodic.len(),
        3,
        "reports a ms apart after the change: {status_ticks:?}"
    );
    for (k, t) in periodic.iter().enumerate() {
        let due = set + (k as u64 + 1) * ms;
        assert!((due..due + 200).contains(t), "{status_ticks:?}");
    }
}

/// Reply latency when the transmitter is idle: from the edge that samples a command's
/// last byte to its acknowledgement's first byte on GMII, per acknowledgement kind. The
/// blocks' latencies add up to it: the MAC and the parser decide, the command unit
/// carries the command out, the builder writes the reply, the arbiter offers it a clock
/// later, the transmitter takes it and starts.
#[test]
fn reply_latency_is_the_sum_of_the_blocks_latencies() {
    use skinbox_gateware::command_unit::COMMAND_LATENCY;
    use skinbox_gateware::datagram_arbiter::OFFER_LATENCY;
    use skinbox_gateware::frame_parser::DECISION_LATENCY;
    use skinbox_gateware::frame_transmitter::TAKE_TO_FIRST_BYTE;
    use skinbox_gateware::mac_receiver::MAC_LATENCY;
    use skinbox_gateware::reply_builder::{build_clocks, AckReplyKind, ReplyKind};
    let config = box_config();
    let requests = [
        (Request::ReadTick, AckReplyKind::None),
        (Request::StreamTo { to: None }, AckReplyKind::Destination),
        (Request::StatusNow, AckReplyKind::Counters),
    ];
    // no cell traffic, commands 0.2 ms apart (status reports only every 100 ms)
    let host_frames: Vec<HostFrame> = requests
        .iter()
        .enumerate()
        .map(|(i, (r, _))| HostFrame {
            edge: 20_000 + 25_000 * i as u64,
            frame: command(HOST_IP, 100 + i as u32, *r),
        })
        .collect();
    let duration_ns = 120_000 * TICK_NS;
    let (run, _) = answer_all(
        &config,
        vec![vec![]; config.ports],
        &host_frames,
        duration_ns,
    );
    assert_eq!(run.replies.len(), 3);
    for ((f, (_, kind)), ack) in host_frames.iter().zip(requests).zip(&run.replies) {
        let latency = ack.first_cycle - f.last_edge();
        let expected = MAC_LATENCY
            + DECISION_LATENCY
            + COMMAND_LATENCY
            + build_clocks(ReplyKind::Ack(kind))
            + OFFER_LATENCY
            + TAKE_TO_FIRST_BYTE;
        eprintln!(
            "acknowledgement ({kind:?}): {latency} clocks = {:.3} us from the command's last byte",
            latency as f64 * TICK_NS as f64 / 1000.0
        );
        assert_eq!(latency, expected, "{kind:?}");
    }
}

/// 3,000 frames mutated from an ARP request, a ping and two commands (bytes changed, cut,
/// grown, each with a right FCS) through the RTL receive path, 12 us apart (every answer
/// has left before the next frame): every answer equals the control model's byte for byte,
/// and the status-now acknowledgement at the end carries the model's counters, every frame
/// counted once.
#[test]
fn mutated_frames_are_answered_and_counted_as_the_model_says() {
    let config = box_config();
    let mut rng = Rng(0xF00D);
    let seeds = mutation_seeds();
    let cases = 3000;
    let mut host_frames: Vec<HostFrame> = (0..cases)
        .map(|i| HostFrame {
            edge: 20_000 + 1_500 * i as u64,
            frame: mutated_frame(&mut rng, &seeds[i % seeds.len()]),
        })
        .collect();
    let edge = 20_000 + 1_500 * cases as u64 + 10_000;
    host_frames.push(HostFrame {
        edge,
        frame: command(HOST_IP, u32::MAX / 2, Request::StatusNow),
    });
    let duration_ns = (edge + 10_000) * TICK_NS;
    let (run, m) = answer_all(
        &config,
        vec![vec![]; config.ports],
        &host_frames,
        duration_ns,
    );
    assert_eq!(m.counters.get(BoxCounter::FramesReceived), cases as u32 + 1);
    assert_eq!(m.counters.unaccounted_frames(), 0);
    // the mutations reach past the FCS: answered and refused frames both occurred
    let answered = run.replies.len();
    assert!(
        answered > cases / 10 && answered < cases,
        "{answered} answers"
    );
    assert!(m.counters.get(BoxCounter::ReplyBusy) == 0);
}

/// Requests that come while the previous reply still holds the buffer are counted
/// `reply_busy` and not answered; once the reply has left, the next is answered. The
/// reference model predicts which (RTL == reference), and the status-now acknowledgement at
/// the end counts them.
#[test]
fn requests_while_a_reply_waits_are_counted_busy() {
    let config = box_config();
    let link = config.link;
    let mut host_frames = vec![];
    let mut edge = 20_000;
    // bursts of pings with the minimum gap, each longer than a reply's build
    for burst in 0..4u16 {
        for k in 0..6u16 {
            let frame = if k % 3 == 2 {
                arp_request(link.box_ip, HOST_MAC, HOST_IP)
            } else {
                ping(
                    link.box_mac,
                    link.box_ip,
                    burst,
                    k,
                    &vec![k as u8; 40 + 300 * k as usize],
                )
            };
            let len = frame.len() as u64;
            host_frames.push(HostFrame { edge, frame });
            edge += 8 + len + 12;
        }
        edge += 30_000;
    }
    host_frames.push(HostFrame {
        edge,
        frame: command(HOST_IP, 7, Request::StatusNow),
    });
    let duration_ns = (edge + 10_000) * TICK_NS;
    let ports = traffic(
        config.ports,
        30_000.0,
        duration_ns as f64 - 100_000.0,
        100_000.0,
    );
    let run = run_both(&spec(
        config.clone(),
        ports,
        host_frames.clone(),
        duration_ns,
    ));
    let last = run.replies.last().expect("the status-now acknowledgement");
    let ack = AckRepr::parse(&last.bytes[8 + 42..last.bytes.len() - 4]).unwrap();
    let skinbox_protocol::command::AckReply::Counters(counters) = ack.reply else {
        panic!("status-now answered with {:?}", ack.reply)
    };
    let busy = counters.get(BoxCounter::ReplyBusy);
    let answered = counters.get(BoxCounter::PingsAnswered) + counters.get(BoxCounter::ArpAnswered);
    eprintln!("{answered} answered, {busy} busy of 24 requests");
    assert_eq!(answered + busy, 24);
    assert!(
        busy >= 8 && answered >= 4,
        "{answered} answered, {busy} busy"
    );
    assert_eq!(run.replies.len() as u32, answered + 1);
    let r = &run.report;
    assert_eq!(
        (r.packets_delivered, r.records_corrupted),
        (r.packets_sent, 0)
    );
}
