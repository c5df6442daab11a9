//! The dissector's expert info on every malformation docs/wire-format.md lists ("What a
//! reader refuses"): one crafted datagram each, through tshark; well-formed datagrams of
//! every kind carry none.

use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::box_counters::{BoxCounters, BOX_COUNTERS_LEN};
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr, CellMode};
use skinbox_protocol::command::{
    AckReply, AckRepr, AckResult, CommandRepr, Destination, Opcode, Request, HEADER_LEN,
};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{Channel, DataRepr, DatagramRepr, EventRepr, RecordRepr, StatusRepr};
use std::net::SocketAddr;
use std::time::Duration;

mod support;

use support::{plugin, temp_dir, tshark};

fn records(sequence: u32, cells: Vec<[u8; 20]>) -> Vec<u8> {
    DatagramRepr {
        box_id: 1,
        port_count: 4,
        flags: 0,
        sequence,
        base_tick: 1_000,
        body: DatagramBody::Records(
            cells
                .into_iter()
                .map(|cell_packet| RecordRepr {
                    port: 1,
                    flags: 0,
                    tick_offset: 0,
                    cell_packet,
                })
                .collect(),
        ),
    }
    .to_bytes()
}

fn data() -> [u8; 20] {
    DataRepr::from_raw(5, [1, -2, 3, 4, 5, 6, 7, 8, 9])
        .unwrap()
        .to_bytes()
}

fn event() -> [u8; 20] {
    EventRepr::new(6, 9, false, &[(Channel::Force1, 3)])
        .unwrap()
        .to_bytes()
}

fn status(sequence: u32, first_port: u8) -> Vec<u8> {
    DatagramRepr {
        box_id: 1,
        port_count: 4,
        flags: 0,
        sequence,
        base_tick: 2_000,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 7,
            datagrams_sent: 1,
            records_sent: 1,
            first_port,
            ports: vec![Default::default(); 2],
        }),
    }
    .to_bytes_with_box_counters(&BoxCounters::default())
}

fn ack(opcode: Opcode, result: AckResult, reply: AckReply) -> Vec<u8> {
    AckRepr {
        box_id: 1,
        port_count: 4,
        sequence: 30,
        host_time: 5,
        opcode: opcode as u8,
        result,
        last_accepted: 30,
        receive_tick: 100,
        send_tick: 200,
        reply,
    }
    .to_bytes()
}

fn command(request: Request) -> Vec<u8> {
    CommandRepr {
        box_id: 1,
        sequence: 30,
        host_time: 5,
        request,
    }
    .to_bytes()
}

fn cell_command(packet: [u8; 20]) -> Vec<u8> {
    command(Request::CellCommand { port: 1, packet })
}

fn mode_packet() -> [u8; 20] {
    CellCommandRepr {
        cell_id: 2,
        command: CellCommand::Mode(CellMode::Event),
    }
    .to_bytes()
}

fn with(mut b: Vec<u8>, at: usize, value: u8) -> Vec<u8> {
    b[at] = value;
    b
}

/// A crafted datagram and the words its expert info must hold (empty: none).
type Case = (Vec<u8>, &'static str);

/// Well-formed datagrams of every kind, then one malformed datagram per rule with the
/// words its expert info must hold.
fn cases() -> (Vec<Vec<u8>>, Vec<Case>) {
    let rec = HEADER_LEN; // first record
    let cell = rec + 6; // its cell packet
    let status_blocks = HEADER_LEN + 16;
    let counters_at = status(0, 0).len() - BOX_COUNTERS_LEN;
    let body = HEADER_LEN;
    let counters_ack = ack(
        Opcode::StatusNow,
        AckResult::Ok,
        AckReply::Counters(BoxCounters::default()),
    );
    let good = vec![
        records(0, vec![data(), event()]),
        status(1, 0),
        status(2, 2),
        cell_command(mode_packet()),
        command(Request::StreamTo {
            to: Some(Destination {
                mac: [0xFF; 6],
                ip: [192, 0, 2, 1],
                port: 9,
            }),
        }),
        command(Request::SetStatusPeriod { ticks: 125_000 }),
        ack(Opcode::ReadTick, AckResult::Ok, AckReply::None),
        counters_ack.clone(),
        ack(Opcode::CellCommand, AckResult::DownlinkFull, AckReply::None),
    ];
    // datagrams
    let mut bad: Vec<Case> = vec![(status(3, 3), "at or above the port count")];
    bad.push((with(records(4, vec![data()]), 6, 0), "port count 0 outside"));
    bad.push((
        with(records(5, vec![data()]), 7, 0x04),
        "undefined flag bits",
    ));
    // (bit 1: the box counter block follows; bit 2, the box sends time syncs, is defined)
    bad.push((with(status(6, 0), 7, 0x0A), "undefined flag bits"));
    bad.push((with(status(7, 0), counters_at, 2), "link_up 2"));
    bad.push((with(status(8, 0), counters_at + 1, 5), "link_speed 5"));
    bad.push((
        with(status(9, 0), counters_at + 3, 1),
        "box counters: reserved",
    ));
    bad.push((
        with(records(10, vec![data()]), rec + 1, 0x02),
        "undefined record flag bits",
    ));
    bad.push((with(records(11, vec![data()]), rec, 4), "is not below"));
    bad.push((
        with(records(12, vec![data()]), cell + 1, 0x40),
        "cell id above 14 bits",
    ));
    let mut accel = data();
    accel[3..5].copy_from_slice(&600i16.to_be_bytes());
    bad.push((records(13, vec![accel]), "accel_x 600 outside"));
    let mut no_channel = event();
    no_channel[3..5].fill(0);
    bad.push((records(14, vec![no_channel]), "no channel in the mask"));
    let mut slot = event();
    slot[9] = 1;
    bad.push((records(15, vec![slot]), "value slot after"));
    bad.push((with(status(16, 0), status_blocks - 1, 0), "")); // reserved: ignored
                                                               // acknowledgements
    let read_tick = ack(Opcode::ReadTick, AckResult::Ok, AckReply::None);
    bad.push((with(read_tick.clone(), body + 1, 6), "unknown result 6"));
    let mut long = read_tick.clone();
    long.push(0);
    long[21] = 25;
    bad.push((long, "body of 25 bytes"));
    bad.push((with(read_tick.clone(), 6, 0), "port count 0 outside"));
    bad.push((with(read_tick.clone(), 7, 1), "flags 0x01 are not 0"));
    bad.push((with(read_tick.clone(), 23, 1), "header reserved"));
    bad.push((
        with(read_tick.clone(), body + 2, 1),
        "acknowledgement body reserved",
    ));
    let mut missing = read_tick[..HEADER_LEN].to_vec();
    missing[20..22].fill(0);
    bad.push((missing, "acknowledgement body shorter"));
    bad.push((
        ack(Opcode::ReadTick, AckResult::DownlinkFull, AckReply::None),
        "is not one the box gives",
    ));
    bad.push((
        with(read_tick.clone(), body + 7, 31),
        "last accepted is not the command's",
    ));
    bad.push((
        ack(Opcode::StatusNow, AckResult::Ok, AckReply::None),
        "call for 108",
    ));
    bad.push((with(counters_ack.clone(), body + 24, 2), "link_up 2"));
    // commands
    let read = command(Request::ReadTick);
    bad.push((with(read.clone(), 7, 1), "flags 0x01 are not 0"));
    bad.push((with(read.clone(), 22, 1), "header reserved"));
    bad.push((with(read.clone(), 6, 77), "unknown opcode 77"));
    let mut short = command(Request::SetFlushTimeout { ticks: 10 });
    short.truncate(HEADER_LEN + 2);
    short[21] = 2;
    bad.push((short, "arguments of 2 bytes"));
    let mut flush0 = command(Request::SetFlushTimeout { ticks: 10 });
    flush0[HEADER_LEN..].fill(0);
    bad.push((flush0, "flush timeout 0"));
    let mut period = command(Request::SetStatusPeriod { ticks: 125_000 });
    period[HEADER_LEN..].copy_from_slice(&10u32.to_be_bytes());
    bad.push((period, "status period 10"));
    let mut ip0 = good[4].clone();
    ip0[HEADER_LEN + 6..HEADER_LEN + 10].fill(0);
    bad.push((ip0, "IP 0.0.0.0"));
    let cc = cell_command(mode_packet());
    let packet = HEADER_LEN + 4;
    bad.push((with(cc.clone(), HEADER_LEN + 2, 1), "reserved bytes 1-3"));
    bad.push((with(cc.clone(), packet + 19, 0x54), "end byte 0x54"));
    bad.push((with(cc.clone(), packet + 3, 9), "unknown command 9"));
    bad.push((with(cc.clone(), packet + 4, 2), "mode 2"));
    bad.push((with(cc.clone(), packet + 7, 1), "after the arguments"));
    bad.push((
        read[..HEADER_LEN - 1].to_vec(),
        "shorter than the 24-byte header",
    ));
    let mut announced = read;
    announced.push(0);
    bad.push((announced, "header announces"));
    (good, bad)
}

#[test]
fn every_documented_malformation_has_an_expert_info() {
    let dir = temp_dir("experts");
    let plugin = plugin(&dir);
    let (good, bad) = cases();
    let src: SocketAddr = "192.0.2.10:54091".parse().unwrap();
    let dst: SocketAddr = "192.0.2.1:54091".parse().unwrap();
    let pcap = dir.join("experts.pcap");
    let mut w = PcapFrameWriter::new(std::fs::File::create(&pcap).unwrap()).unwrap();
    let all: Vec<&Vec<u8>> = good.iter().chain(bad.iter().map(|b| &b.0)).collect();
    for (i, p) in all.iter().enumerate() {
        w.write_udp(Duration::from_micros(10 * i as u64), src, dst, p)
            .unwrap();
    }
    w.finish().unwrap();
    let text = tshark(
        &plugin,
        &pcap,
        &[
            "-Y",
            "skinbox.expert.malformed",
            "-T",
            "fields",
            "-e",
            "frame.number",
            "-e",
            "_ws.expert.message",
        ],
    );
    let flagged: Vec<(usize, String)> = text
        .lines()
        .map(|l| {
            let (n, m) = l.split_once('\t').unwrap_or((l, ""));
            (n.parse().unwrap(), m.to_string())
        })
        .collect();
    let mut want = vec![];
    for (i, (_, words)) in bad.iter().enumerate() {
        let frame = good.len() + i + 1;
        if words.is_empty() {
            // an ignored reserved field: no expert
            assert!(
                flagged.iter().all(|(n, _)| *n != frame),
                "frame {frame} flagged"
            );
            continue;
        }
        want.push(frame);
        let messages = flagged
            .iter()
            .find(|(n, _)| *n == frame)
            .map(|(_, m)| m.as_str())
            .unwrap_or_else(|| panic!("frame {frame} ({words}): no expert info"));
        assert!(
            messages.contains(words),
            "frame {frame}: {messages:?} does not say {words:?}"
        );
    }
    let frames: Vec<usize> = flagged.iter().map(|f| f.0).collect();
    assert_eq!(frames, want, "only the malformed frames are flagged");
    std::fs::remove_dir_all(&dir).ok();
}
