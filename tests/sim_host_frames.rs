//! `skinbox sim --host-frames`: a pcap of the host's own frames (ARP requests, pings of
//! several lengths, commands, a replay, malformed frames) into the box on GMII, at RTL and
//! in the reference model; the box's answers read back from the output pcap with
//! etherparse.

use etherparse::{
    ArpHardwareId, ArpOperation, ArpPacket, EtherType, Icmpv4Type, IpNumber, Ipv4Header, NetSlice,
    PacketBuilder, SlicedPacket, TransportSlice,
};
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr, CellMode};
use skinbox_protocol::command::{AckReply, AckRepr, CommandRepr, Destination, Request, HEADER_LEN};
use skinbox_protocol::link::LinkConfig;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

const HOST_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 0x11];
const HOST_IP: [u8; 4] = [192, 0, 2, 1];
const HOST_PORT: u16 = 40_000;
const LINK: LinkConfig = LinkConfig::DEFAULT;

fn skinbox_json(args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn arp_request(target: [u8; 4]) -> Vec<u8> {
    let arp = ArpPacket::new(
        ArpHardwareId::ETHERNET,
        EtherType::IPV4,
        ArpOperation::REQUEST,
        &HOST_MAC,
        &HOST_IP,
        &[0; 6],
        &target,
    )
    .unwrap();
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, [0xFF; 6])
        .arp(arp)
        .write(&mut f)
        .unwrap();
    f
}

fn ping(seq: u16, data: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, LINK.box_mac)
        .ipv4(HOST_IP, LINK.box_ip, 64)
        .icmpv4_echo_request(0x5EED, seq)
        .write(&mut f, data)
        .unwrap();
    f
}

fn udp_from(ip: [u8; 4], port: u16, payload: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, LINK.box_mac)
        .ipv4(ip, LINK.box_ip, 64)
        .udp(HOST_PORT, port)
        .write(&mut f, payload)
        .unwrap();
    f
}

fn command(box_id: u16, sequence: u32, request: Request) -> Vec<u8> {
    CommandRepr {
        box_id,
        sequence,
        host_time: u64::from(sequence) * 1_000,
        request,
    }
    .to_bytes()
}

/// The frames, what each should get back, and the fates they make.
struct Case {
    frames: Vec<Vec<u8>>,
    /// Per frame: the reply expected (`arp`, `echo`, an ack result name) or none.
    replies: Vec<Option<&'static str>>,
}

fn case() -> Case {
    let mut c = Case {
        frames: vec![],
        replies: vec![],
    };
    let mut add = |f: Vec<u8>, reply: Option<&'static str>| {
        c.frames.push(f);
        c.replies.push(reply);
    };
    add(arp_request(LINK.box_ip), Some("arp"));
    add(arp_request([192, 0, 2, 99]), None); // not_for_us
    for (seq, len) in [(1u16, 0usize), (2, 56), (3, 1000), (4, 1472)] {
        let data: Vec<u8> = (0..len).map(|i| (i * 7 + len) as u8).collect();
        add(ping(seq, &data), Some("echo"));
    }
    let box_id = 1;
    let port = LINK.box_port;
    add(
        udp_from(HOST_IP, port, &command(box_id, 10, Request::ReadTick)),
        Some("ok"),
    );
    add(
        udp_from(HOST_IP, port, &command(box_id, 11, Request::StatusNow)),
        Some("ok"),
    );
    add(
        udp_from(
            HOST_IP,
            port,
            &command(
                box_id,
                12,
                Request::StreamTo {
                    to: Some(Destination {
                        mac: [0xFF; 6],
                        ip: HOST_IP,
                        port: LINK.host_port,
                    }),
                },
            ),
        ),
        Some("ok"),
    );
    // the same command again: a replay
    add(
        udp_from(HOST_IP, port, &command(box_id, 11, Request::StatusNow)),
        Some("replay"),
    );
    add(
        udp_from(HOST_IP, port, &command(7, 13, Request::ReadTick)),
        Some("other_box"),
    );
    let mut bad_flush = command(box_id, 14, Request::SetFlushTimeout { ticks: 1 });
    bad_flush[HEADER_LEN..].fill(0);
    add(udp_from(HOST_IP, port, &bad_flush), Some("bad_argument"));
    // a cell command whose reserved bytes 1-3 are not 0
    let packet = CellCommandRepr {
        cell_id: 3,
        command: CellCommand::Mode(CellMode::Event),
    }
    .to_bytes();
    let mut reserved = command(box_id, 15, Request::CellCommand { port: 0, packet });
    reserved[HEADER_LEN + 2] = 1;
    add(udp_from(HOST_IP, port, &reserved), Some("bad_argument"));
    let mut unknown = command(box_id, 16, Request::ReadTick);
    unknown[6] = 77;
    add(udp_from(HOST_IP, port, &unknown), Some("unknown_opcode"));
    // malformed: no answer, each its own fate
    let mut flags = command(box_id, 17, Request::ReadTick);
    flags[7] = 1;
    add(udp_from(HOST_IP, port, &flags), None); // refused_malformed
    add(
        udp_from([10, 0, 0, 1], port, &command(box_id, 18, Request::ReadTick)),
        None,
    ); // refused_foreign_subnet
    add(udp_from(HOST_IP, 9, b"discard"), None); // unknown_udp_port
    let mut checksum = udp_from(HOST_IP, port, &command(box_id, 19, Request::ReadTick));
    checksum[24] ^= 0xFF; // IPv4 header checksum
    add(checksum, None); // ipv4_bad_header
    let mut fragment = Vec::new();
    let mut ip = Ipv4Header::new(8 + 4, 64, IpNumber::UDP, HOST_IP, LINK.box_ip).unwrap();
    ip.more_fragments = true;
    PacketBuilder::ethernet2(HOST_MAC, LINK.box_mac)
        .ip(etherparse::IpHeaders::Ipv4(ip, Default::default()))
        .udp(HOST_PORT, port)
        .write(&mut fragment, b"frag")
        .unwrap();
    add(fragment, None); // ipv4_fragment
    let mut short_udp = udp_from(HOST_IP, port, &command(box_id, 20, Request::ReadTick));
    short_udp[38..40].copy_from_slice(&9u16.to_be_bytes()); // UDP length 9
    add(short_udp, None); // bad_transport
    add(vec![0xAB; 1600], None); // bad_length (a giant)
    c
}

fn write_pcap(path: &Path, frames: &[Vec<u8>], every: Duration) {
    let mut w = PcapFrameWriter::new(std::fs::File::create(path).unwrap()).unwrap();
    for (i, f) in frames.iter().enumerate() {
        // any epoch: only the differences count
        w.write_frame(Duration::from_secs(1_700_000_000) + every * i as u32, f)
            .unwrap();
    }
    w.finish().unwrap();
}

/// Frames of `path` at or after `first`, as (timestamp, bytes).
fn frames_of(path: &Path) -> Vec<(Duration, Vec<u8>)> {
    skinbox_host::pcap::ethernet_frames(&std::fs::read(path).unwrap()).unwrap()
}

fn sim(dir: &Path, name: &str, frames: &Path, extra: &[&str]) -> (serde_json::Value, PathBuf) {
    let out = dir.join(format!("{name}.pcap"));
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/cosim/scenes/idle.toml");
    let fixed = [
        "sim",
        "--json",
        scene,
        "--from-ms",
        "0",
        "--duration-ms",
        "2",
        "--cells",
        "132",
        // the box of tests/sim.rs's idle scene: one verilated model for both
        "--status-period-ms",
        "2",
        "--host-frames",
    ];
    let mut args: Vec<&std::ffi::OsStr> = fixed.iter().map(std::ffi::OsStr::new).collect();
    args.push(frames.as_os_str());
    args.push("--pcap".as_ref());
    args.push(out.as_os_str());
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    (skinbox_json(&args), out)
}

#[test]
fn host_frames_into_the_box_at_rtl_and_in_the_reference_model() {
    let dir = std::env::temp_dir().join(format!("skinbox-host-frames-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let c = case();
    let input = dir.join("host.pcap");
    write_pcap(&input, &c.frames, Duration::from_micros(40));
    let (rtl, rtl_pcap) = sim(&dir, "rtl", &input, &["--fidelity", "rtl"]);
    let (reference, ref_pcap) = sim(&dir, "reference", &input, &["--fidelity", "reference"]);
    // RTL == reference: the same frames, host's and box's, to the clock
    assert_eq!(
        std::fs::read(&rtl_pcap).unwrap(),
        std::fs::read(&ref_pcap).unwrap()
    );
    assert_eq!(rtl["host_frames"], reference["host_frames"]);

    let h = &rtl["host_frames"];
    let n = c.frames.len() as u64;
    assert_eq!(h["frames_sent"], n);
    let want = |name: &str| c.replies.iter().filter(|r| **r == Some(name)).count() as u64;
    assert_eq!(h["arp_replies"], want("arp"));
    assert_eq!(h["echo_replies"], want("echo"));
    for result in [
        "ok",
        "replay",
        "other_box",
        "bad_argument",
        "unknown_opcode",
    ] {
        assert_eq!(h["acknowledgements"][result], want(result), "{result}");
    }
    assert_eq!(h["other_replies"], 0);
    assert_eq!(h["replies"], c.replies.iter().flatten().count() as u64);
    // every frame counted once, in its fate
    let fates = &h["box_counters"];
    assert_eq!(fates["frames_received"], n, "{fates}");
    assert_eq!(h["unaccounted_frames"], 0);
    for (fate, count) in [
        ("arp_answered", 1),
        ("pings_answered", 4),
        ("commands_accepted", 3),
        ("refused_replay", 1),
        ("refused_other_box", 1),
        ("refused_bad_argument", 2),
        ("refused_unknown_opcode", 1),
        ("refused_malformed", 1),
        ("refused_foreign_subnet", 1),
        ("unknown_udp_port", 1),
        ("ipv4_bad_header", 1),
        ("ipv4_fragment", 1),
        ("bad_transport", 1),
        ("bad_length", 1),
        ("not_for_us", 1),
        ("reply_busy", 0),
        ("bad_fcs", 0),
    ] {
        assert_eq!(fates[fate], count, "{fate}: {fates}");
    }

    // The output pcap holds the host's frames as sent, at their timestamps' spacing from
    // the window's start, and each answer after its request; read with etherparse.
    let out = frames_of(&rtl_pcap);
    let sent: Vec<&(Duration, Vec<u8>)> = out
        .iter()
        .filter(|(_, f)| f[6..12] == HOST_MAC || f.len() >= 1600)
        .collect();
    assert_eq!(sent.len(), c.frames.len());
    for (i, ((t, f), want)) in sent.iter().zip(&c.frames).enumerate() {
        let padded = {
            let mut w = want.clone();
            w.resize(w.len().max(60), 0);
            w
        };
        assert_eq!(f, &padded, "frame {i}");
        assert_eq!(
            t.saturating_sub(sent[0].0),
            Duration::from_micros(40) * i as u32
        );
    }
    let answers: Vec<&Vec<u8>> = out
        .iter()
        .map(|(_, f)| f)
        .filter(|f| f[..6] == HOST_MAC && f[6..12] == LINK.box_mac)
        .collect();
    let expected: Vec<(usize, &'static str)> = c
        .replies
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.map(|r| (i, r)))
        .collect();
    assert_eq!(answers.len(), expected.len());
    for (answer, (i, kind)) in answers.iter().zip(&expected) {
        let request = SlicedPacket::from_ethernet(&c.frames[*i]).unwrap();
        let p = SlicedPacket::from_ethernet(answer).unwrap();
        match *kind {
            "arp" => {
                let Some(NetSlice::Arp(a)) = &p.net else {
                    panic!("frame {i}: no ARP reply")
                };
                assert_eq!(a.operation(), ArpOperation::REPLY);
                assert_eq!(a.sender_hw_addr(), LINK.box_mac);
                assert_eq!(a.sender_protocol_addr(), LINK.box_ip);
                assert_eq!(a.target_hw_addr(), HOST_MAC);
                assert_eq!(a.target_protocol_addr(), HOST_IP);
            }
            "echo" => {
                let (Some(TransportSlice::Icmpv4(q)), Some(TransportSlice::Icmpv4(r))) =
                    (&request.transport, &p.transport)
                else {
                    panic!("frame {i}: no echo reply")
                };
                let Icmpv4Type::EchoRequest(qh) = q.icmp_type() else {
                    unreachable!()
                };
                assert_eq!(r.icmp_type(), Icmpv4Type::EchoReply(qh));
                assert_eq!(r.payload(), q.payload(), "frame {i}: echo data");
                // etherparse's own checksum of the reply
                let Some(NetSlice::Ipv4(ip)) = &p.net else {
                    unreachable!()
                };
                assert_eq!(
                    ip.header().to_header().calc_header_checksum(),
                    ip.header().header_checksum()
                );
                assert_eq!(r.icmp_type().calc_checksum(r.payload()), r.checksum());
            }
            result => {
                let (Some(TransportSlice::Udp(q)), Some(TransportSlice::Udp(u))) =
                    (&request.transport, &p.transport)
                else {
                    panic!("frame {i}: no acknowledgement")
                };
                assert_eq!(
                    (u.source_port(), u.destination_port()),
                    (LINK.box_port, HOST_PORT)
                );
                let ack = AckRepr::parse(u.payload()).unwrap();
                assert_eq!(ack.result.name(), result, "frame {i}");
                // the body lengths docs/wire-format.md gives: 24, 36 (stream-to ok), 108
                // (status-now ok)
                let body_len = match (&ack.reply, result) {
                    (AckReply::Destination(_), "ok") => 36,
                    (AckReply::Counters(_), "ok") => 108,
                    _ => 24,
                };
                assert_eq!(u.payload().len() - HEADER_LEN, body_len, "frame {i}");
                let cmd = skinbox_protocol::command::Command::new_checked(q.payload()).unwrap();
                assert_eq!(
                    (ack.sequence, ack.host_time),
                    (cmd.sequence(), cmd.host_time())
                );
                if cmd.opcode() == 4 && result == "ok" {
                    // status now: the counters as they stood, this command counted
                    let AckReply::Counters(counters) = ack.reply else {
                        panic!("status now without counters")
                    };
                    assert_eq!(counters.unaccounted_frames(), 0);
                }
            }
        }
    }
    // the host decoder of the report saw the commands and the acknowledgements
    assert_eq!(
        rtl["host"]["acknowledgements"],
        expected
            .iter()
            .filter(|e| e.1 != "arp" && e.1 != "echo")
            .count() as u64
    );

    // back to back with a gap: the same answers
    let (gap, _) = sim(
        &dir,
        "gap",
        &input,
        &["--fidelity", "reference", "--host-frames-gap-us", "15"],
    );
    assert_eq!(
        gap["host_frames"]["acknowledgements"],
        h["acknowledgements"]
    );
    assert_eq!(gap["host_frames"]["box_counters"], h["box_counters"]);
    assert!(gap["host_frames"]["last_tick"].as_u64() < h["last_tick"].as_u64());
    std::fs::remove_dir_all(&dir).ok();
}
