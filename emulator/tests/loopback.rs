//! `skinbox emulate`'s box on loopback: commands sent at their spacing are decided at their
//! arrival, as the RTL (through the control model, which the receive-path and downlink
//! tests hold to it) decides them.

#[path = "../../cosim/tests/support/mod.rs"]
mod support;

use skinbox_protocol::command::{AckRepr, AckResult, CommandRepr, Request};
use std::net::SocketAddrV4;

fn command(sequence: u32, request: Request) -> Vec<u8> {
    CommandRepr {
        box_id: 1,
        sequence,
        host_time: 5,
        request,
    }
    .to_bytes()
}

/// One command sent on loopback: its sequence number, payload and the wall-clock bracket
/// of its `send_to` (ns since the Unix epoch; on loopback the kernel stamps the datagram's
/// arrival inside that call).
struct Sent {
    sequence: u32,
    payload: Vec<u8>,
    before_ns: i128,
    after_ns: i128,
}

fn epoch_ns() -> i128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i128
}

/// Waits until the kernel stamps datagrams on arrival: it turns its receive stamps on in a
/// deferred work item once a socket asks for them, and before that a datagram is stamped
/// when read. A probe sent to itself is stamped inside its `send_to` once they are on.
fn wait_for_arrival_stamps() {
    let probe = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    skinbox_host::live::enable_receive_timestamps(&probe).unwrap();
    let me = probe.local_addr().unwrap();
    let mut buf = [0u8; 8];
    for _ in 0..500 {
        let before = epoch_ns();
        probe.send_to(b"probe", me).unwrap();
        let after = epoch_ns();
        let (_, _, stamp) = skinbox_host::live::recv_stamped(&probe, &mut buf, false).unwrap();
        if stamp.is_some_and(|s| (before..=after).contains(&(s.as_nanos() as i128))) {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    panic!("the kernel did not stamp datagrams on arrival within 5 s");
}

/// The emulator serving `socket` at real speed until `stop` or for at most 20 s.
fn serve_for_20_s(
    prepared: &skinbox_emulator::PreparedEmulator,
    socket: &std::net::UdpSocket,
    stop: &std::sync::atomic::AtomicBool,
) -> skinbox_emulator::ServeSummary {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    skinbox_emulator::serve(prepared, socket, 1.0, stop, Some(deadline), &mut |_| {}).unwrap()
}

/// Sends `requests` to `to` from `socket`, each at its offset (us) after the first,
/// spinning for the instant; sequence numbers from `first_sequence`.
fn send_paced(
    socket: &std::net::UdpSocket,
    to: std::net::SocketAddr,
    first_sequence: u32,
    requests: &[(f64, Request)],
) -> Vec<Sent> {
    let start = std::time::Instant::now() + std::time::Duration::from_millis(1);
    requests
        .iter()
        .enumerate()
        .map(|(i, &(at_us, request))| {
            let sequence = first_sequence + i as u32;
            let payload = command(sequence, request);
            let at = start + std::time::Duration::from_nanos((at_us * 1e3) as u64);
            while std::time::Instant::now() < at {
                std::hint::spin_loop();
            }
            let before_ns = epoch_ns();
            socket.send_to(&payload, to).unwrap();
            let after_ns = epoch_ns();
            Sent {
                sequence,
                payload,
                before_ns,
                after_ns,
            }
        })
        .collect()
}

/// The acknowledgements of `sent`, by sequence number, in the order sent.
fn acks_of(socket: &std::net::UdpSocket, sent: &[Sent]) -> Vec<AckRepr> {
    let mut by_sequence = std::collections::HashMap::new();
    let mut buf = [0u8; 2048];
    socket
        .set_read_timeout(Some(std::time::Duration::from_secs(2)))
        .unwrap();
    while by_sequence.len() < sent.len() {
        let (n, _) = socket.recv_from(&mut buf).expect("an acknowledgement");
        let ack = AckRepr::parse(&buf[..n]).unwrap();
        by_sequence.insert(ack.sequence, ack);
    }
    sent.iter().map(|s| by_sequence[&s.sequence]).collect()
}

/// The emulator's decision ticks are the kernel's arrival stamps: the ticks between two
/// commands' acknowledgements are the time between their sends (each arrival lies inside
/// its `send_to`), within the tick and the wall clock's rounding. Returns each command's
/// arrival after the first, us.
fn assert_decided_at_arrival(sent: &[Sent], acks: &[AckRepr]) -> Vec<f64> {
    let tick_ns = skinbox_protocol::TICK_NS as i128;
    let first = acks[0].receive_tick as i128;
    sent.iter()
        .zip(acks)
        .enumerate()
        .map(|(i, (s, a))| {
            let apart = (a.receive_tick as i128 - first) * tick_ns;
            let (low, high) = (
                s.before_ns - sent[0].after_ns - 2 * tick_ns,
                s.after_ns - sent[0].before_ns + 2 * tick_ns,
            );
            assert!(
                (low..=high).contains(&apart),
                "command {i}: decided {apart} ns after the first, sent {low}..{high} ns after it"
            );
            apart as f64 / 1e3
        })
        .collect()
}

/// The RTL's results for `sent` decided at the ticks `acks` name: the control model, which
/// the receive-path and downlink tests hold equal to the RTL, fed the same frames at them.
fn model_results(
    model: &mut skinbox_model::control::BoxControl,
    from: SocketAddrV4,
    sent: &[Sent],
    acks: &[AckRepr],
) -> Vec<AckResult> {
    use skinbox_model::control::Reply;
    sent.iter()
        .zip(acks)
        .map(|(s, a)| {
            match skinbox_model::emulator::deliver(model, from, &s.payload, a.receive_tick).reply {
                Some(Reply::Ack { ack, .. }) => ack.result,
                r => panic!("the model answered {r:?}"),
            }
        })
        .collect()
}

/// The acknowledgements of `skinbox emulate` on loopback are the RTL's for the same
/// commands at the spacing they arrived with: the downlink test's schedule (12 to 115 us
/// apart, whose results the RTL gives) and twenty cell commands 32 us apart to one port
/// (a packet takes 50 us on the line: the queue of two fills and some are refused
/// `downlink_full`, as the RTL refuses them).
#[test]
fn emulator_acknowledgements_on_loopback_are_the_rtls_at_the_arrival_spacing() {
    use skinbox_emulator::{prepare as prepare_emulator, EmulatorSettings};
    use std::sync::atomic::{AtomicBool, Ordering};
    let box_socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let listen = match box_socket.local_addr().unwrap() {
        std::net::SocketAddr::V4(a) => a,
        a => panic!("{a}"),
    };
    let settings = EmulatorSettings {
        scene: Some("idle".into()),
        buses: Some(8),
        cells: Some(16),
        from_ms: 0.0,
        duration_ms: 200.0,
        ..EmulatorSettings::default()
    };
    let prepared = prepare_emulator(&settings, listen).unwrap();
    let mut model = skinbox_model::control::BoxControl::new(
        skinbox_model::control::ControlConfig::of(&prepared.config),
    );
    let host = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let from = match host.local_addr().unwrap() {
        std::net::SocketAddr::V4(a) => a,
        a => panic!("{a}"),
    };
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let server = scope.spawn(|| serve_for_20_s(&prepared, &box_socket, &stop));
        let to = std::net::SocketAddr::V4(listen);
        // a read-tick exchange, and the kernel's arrival stamps on, before the commands
        // whose spacing counts
        let sent = send_paced(&host, to, 1, &[(0.0, Request::ReadTick)]);
        let acks = acks_of(&host, &sent);
        assert_eq!(
            model_results(&mut model, from, &sent, &acks),
            [AckResult::Ok]
        );
        wait_for_arrival_stamps();

        // the downlink test's schedule, its offsets from the first command
        let schedule = support::downlink_schedule();
        let requests: Vec<(f64, Request)> = schedule
            .iter()
            .map(|&(edge, port, n, _)| {
                (
                    (edge - schedule[0].0) as f64 / 125.0,
                    Request::CellCommand {
                        port,
                        packet: support::cell_packet(n),
                    },
                )
            })
            .collect();
        let sent = send_paced(&host, to, 2, &requests);
        let acks = acks_of(&host, &sent);
        let arrived = assert_decided_at_arrival(&sent, &acks);
        let results: Vec<AckResult> = acks.iter().map(|a| a.result).collect();
        assert_eq!(results, model_results(&mut model, from, &sent, &acks));
        // where every command arrived within 5 us of its schedule, the results are the
        // schedule's, the RTL's (the model gives them at any such spacing: checked here
        // on random ones)
        let mut noise = 0x2545_F491_4F6C_DD1Du64;
        for _ in 0..200 {
            let mut m = skinbox_model::control::BoxControl::new(*model.config());
            let jittered: Vec<AckRepr> = acks
                .iter()
                .zip(&schedule)
                .map(|(a, s)| {
                    noise ^= noise << 13;
                    noise ^= noise >> 7;
                    noise ^= noise << 17;
                    let jitter = (noise % 1_251) as i64 - 625; // +-5 us in ticks
                    AckRepr {
                        receive_tick: (1_000_000 + s.0 as i64 + jitter) as u64,
                        ..*a
                    }
                })
                .collect();
            let rtl: Vec<AckResult> = schedule.iter().map(|s| s.3).collect();
            assert_eq!(model_results(&mut m, from, &sent, &jittered), rtl);
        }
        let drift = requests
            .iter()
            .zip(&arrived)
            .map(|(r, a)| (a - r.0).abs())
            .fold(0.0, f64::max);
        eprintln!("downlink schedule: arrivals up to {drift:.1} us off the schedule");
        if drift <= 5.0 {
            let rtl: Vec<AckResult> = schedule.iter().map(|s| s.3).collect();
            assert_eq!(results, rtl);
        }

        // after the queues drained: twenty to port 0, 32 us apart
        std::thread::sleep(std::time::Duration::from_millis(5));
        let requests: Vec<(f64, Request)> = (0..20u8)
            .map(|i| {
                (
                    f64::from(i) * 32.0,
                    Request::CellCommand {
                        port: 0,
                        packet: support::cell_packet(i),
                    },
                )
            })
            .collect();
        let sent = send_paced(&host, to, 100, &requests);
        let acks = acks_of(&host, &sent);
        let arrived = assert_decided_at_arrival(&sent, &acks);
        let results: Vec<AckResult> = acks.iter().map(|a| a.result).collect();
        assert_eq!(results, model_results(&mut model, from, &sent, &acks));
        let refused = |results: &[AckResult]| {
            results
                .iter()
                .filter(|&&r| r == AckResult::DownlinkFull)
                .count()
        };
        eprintln!(
            "20 commands over {:.0} us: {} refused downlink_full",
            arrived.last().unwrap(),
            refused(&results)
        );
        // at exactly 32 us the RTL refuses 6 (issue #40); the emulator's results are the
        // RTL's at the spacing the commands arrived with (above)
        let mut m = skinbox_model::control::BoxControl::new(*model.config());
        let nominal: Vec<AckRepr> = acks
            .iter()
            .enumerate()
            .map(|(i, a)| AckRepr {
                receive_tick: 1_000_000 + i as u64 * 32 * 125,
                ..*a
            })
            .collect();
        assert_eq!(refused(&model_results(&mut m, from, &sent, &nominal)), 6);
        stop.store(true, Ordering::Relaxed);
        let served = server.join().unwrap();
        assert_eq!(served.stats.commands_received, 29);
        assert_eq!(served.stats.acks_sent, 29);
    });
}

/// The commands among the receive-path test's random frames (the same generator and seed:
/// other boxes, replays, three hosts and foreign ones, bad arguments, unknown opcodes,
/// malformed payloads), sent over loopback at their frames' times (40 us apart), each
/// host from its own address (192.0.2.1 to 3 as 127.0.0.1 to 3; the foreign subnet's
/// senders as 127.0.1.x outside the emulator's 127.0.0.0/24): every command is answered
/// or not as the test's book and the RTL say, with the result they give, and every
/// acknowledgement is the control model's at its receive tick, field for field.
#[test]
fn the_receive_path_tests_commands_on_loopback_are_answered_as_the_box_answers() {
    use skinbox_emulator::{prepare as prepare_emulator, EmulatorSettings};
    use skinbox_model::control::{BoxControl, ControlConfig, Reply};
    use skinbox_protocol::box_counters::BoxCounter;
    use std::collections::{BTreeMap, HashMap, VecDeque};
    use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
    use std::sync::atomic::{AtomicBool, Ordering};

    // the generator's commands: (sender, UDP payload, expected result if answered)
    let mut rng = support::Rng(0x005E_C04D);
    let (mut next_sequence, mut accepted) = (BTreeMap::new(), vec![]);
    // (frame index, sender, payload, expected result): the frames are 40 us apart
    type Booked = (u64, [u8; 4], Vec<u8>, Option<AckResult>);
    let mut commands: Vec<Booked> = vec![];
    for index in 0..240 {
        let case = support::random_case(&mut rng, &mut next_sequence, &mut accepted);
        let command_fate = matches!(
            case.fate,
            BoxCounter::CommandsAccepted
                | BoxCounter::RefusedForeignSubnet
                | BoxCounter::RefusedMalformed
                | BoxCounter::RefusedOtherBox
                | BoxCounter::RefusedReplay
                | BoxCounter::RefusedUnknownOpcode
                | BoxCounter::RefusedBadArgument
                | BoxCounter::RefusedDownlinkFull
        );
        if !command_fate {
            continue;
        }
        let ethernet = &case.frame[..case.frame.len() - 4];
        let packet = etherparse::SlicedPacket::from_ethernet(ethernet).unwrap();
        let Some(etherparse::NetSlice::Ipv4(ip)) = packet.net else {
            panic!("a command frame without IPv4")
        };
        let Some(etherparse::TransportSlice::Udp(udp)) = packet.transport else {
            panic!("a command frame without UDP")
        };
        commands.push((
            index,
            ip.header().source(),
            udp.payload().to_vec(),
            case.ack.map(|a| a.0),
        ));
    }
    let fates: std::collections::BTreeSet<Option<u8>> =
        commands.iter().map(|c| c.3.map(|r| r as u8)).collect();
    assert!(fates.len() >= 5, "kinds of answers: {fates:?}");

    let box_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let SocketAddr::V4(listen) = box_socket.local_addr().unwrap() else {
        panic!("IPv4")
    };
    let settings = EmulatorSettings {
        scene: Some("idle".into()),
        buses: Some(8),
        cells: Some(16),
        from_ms: 0.0,
        duration_ms: 200.0,
        host_subnet: ([127, 0, 0, 0], 24),
        ..EmulatorSettings::default()
    };
    let prepared = prepare_emulator(&settings, listen).unwrap();
    let mut model = BoxControl::new(ControlConfig::of(&prepared.config));
    model.counters.link_speed = skinbox_protocol::box_counters::LinkSpeed::Unknown;
    let local = |ip: [u8; 4]| -> Ipv4Addr {
        match ip {
            [192, 0, 2, h] => Ipv4Addr::new(127, 0, 0, h),
            [_, _, c, _] => Ipv4Addr::new(127, 0, 1, c),
        }
    };
    let mut sockets: HashMap<Ipv4Addr, UdpSocket> = HashMap::new();
    for (_, ip, _, _) in &commands {
        let ip = local(*ip);
        sockets
            .entry(ip)
            .or_insert_with(|| UdpSocket::bind((ip, 0)).unwrap());
    }
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let server = scope.spawn(|| serve_for_20_s(&prepared, &box_socket, &stop));
        let to = SocketAddr::V4(listen);
        // the emulator serving (a command for another box, from a host of its own,
        // answered and changing no host's state), the kernel's arrival stamps on, then
        // each command at its frame's time
        let other = UdpSocket::bind("127.0.0.9:0").unwrap();
        let payload = CommandRepr {
            box_id: 7,
            sequence: 1,
            host_time: 0,
            request: Request::ReadTick,
        }
        .to_bytes();
        other.send_to(&payload, to).unwrap();
        other
            .set_read_timeout(Some(std::time::Duration::from_secs(2)))
            .unwrap();
        let mut buf = [0u8; 2048];
        let n = other.recv(&mut buf).unwrap();
        let ack = AckRepr::parse(&buf[..n]).unwrap();
        assert_eq!(ack.result, AckResult::OtherBox);
        let other_address =
            SocketAddrV4::new([127, 0, 0, 9].into(), other.local_addr().unwrap().port());
        skinbox_model::emulator::deliver(&mut model, other_address, &payload, ack.receive_tick);
        wait_for_arrival_stamps();
        let start = std::time::Instant::now() + std::time::Duration::from_millis(1);
        let mut sent = vec![];
        for (index, ip, payload, _) in &commands {
            let at = start + std::time::Duration::from_micros(40 * index);
            while std::time::Instant::now() < at {
                std::hint::spin_loop();
            }
            let before_ns = epoch_ns();
            sockets[&local(*ip)].send_to(payload, to).unwrap();
            sent.push((before_ns, epoch_ns()));
        }
        // every answer has left 100 ms on: the box stops, then each host's
        // acknowledgements are read, in the order the box sent them
        std::thread::sleep(std::time::Duration::from_millis(100));
        stop.store(true, Ordering::Relaxed);
        let served = server.join().unwrap();
        let mut acks: HashMap<Ipv4Addr, VecDeque<AckRepr>> = HashMap::new();
        for (ip, socket) in &sockets {
            socket
                .set_read_timeout(Some(std::time::Duration::from_millis(50)))
                .unwrap();
            let mut buf = [0u8; 2048];
            let queue = acks.entry(*ip).or_default();
            while let Ok(n) = socket.recv(&mut buf) {
                // a stream-to among the commands sends the box's datagrams here too
                if skinbox_protocol::command::peek_kind(&buf[..n])
                    == Some(skinbox_protocol::command::KIND_ACK)
                {
                    queue.push_back(AckRepr::parse(&buf[..n]).unwrap());
                }
            }
        }
        let mut decided = vec![];
        let (mut cell_commands, mut cell_commands_as_booked) = (0, 0);
        for (i, (_, ip, payload, expected)) in commands.iter().enumerate() {
            let host = local(*ip);
            let got = match expected {
                Some(_) => acks.get_mut(&host).and_then(VecDeque::pop_front),
                None => None,
            };
            // whether it is answered, and the result, as the book (the RTL) says; a cell
            // command's result depends on the spacing the downlink saw, which a loaded
            // sender may not keep: the control model's at its arrival (below) decides it
            let cell_command = got
                .is_some_and(|a| a.opcode == skinbox_protocol::command::Opcode::CellCommand as u8);
            assert_eq!(got.is_some(), expected.is_some(), "command {i} from {host}");
            if cell_command {
                cell_commands += 1;
                cell_commands_as_booked += usize::from(got.map(|a| a.result) == *expected);
            } else {
                assert_eq!(
                    got.map(|a| a.result),
                    *expected,
                    "command {i} from {host}: the book's (the RTL's) answer"
                );
            }
            let sender = SocketAddrV4::new(host, sockets[&host].local_addr().unwrap().port());
            let tick = got.map_or(0, |a| a.receive_tick);
            let reply = skinbox_model::emulator::deliver(&mut model, sender, payload, tick).reply;
            match (got, reply) {
                (Some(got), Some(Reply::Ack { ack, .. })) => {
                    assert_eq!(
                        got,
                        AckRepr {
                            send_tick: got.send_tick,
                            ..ack
                        },
                        "command {i}: the control model's acknowledgement"
                    );
                    decided.push((sent[i], got.receive_tick));
                }
                (None, None) => {}
                (got, reply) => panic!("command {i}: emulator {got:?}, model {reply:?}"),
            }
        }
        assert!(
            acks.values().all(VecDeque::is_empty),
            "no acknowledgement beyond the book's"
        );
        // decided at arrival: within each datagram's send, relative to the first answered
        let ((b0, a0), t0) = decided[0];
        for (i, &((before, after), tick)) in decided.iter().enumerate() {
            let apart = (tick as i128 - t0 as i128) * 8;
            assert!(
                (before - a0 - 16..=after - b0 + 16).contains(&apart),
                "answered command {i}: decided {apart} ns after the first"
            );
        }
        eprintln!(
            "{} commands, {} answered, kinds of answers {fates:?}; {cell_commands_as_booked} of {cell_commands} cell commands as booked at 40 us a frame",
            commands.len(),
            decided.len()
        );
        assert_eq!(served.stats.commands_received, commands.len() as u64 + 1);
        assert_eq!(served.stats.acks_sent, decided.len() as u64 + 1);
    });
}
