//! The Wireshark dissector in tshark on commands, acknowledgements and status datagrams
//! with the box counter block, each written by the protocol crate; tshark's fields must be
//! the values put in.

use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::box_counters::{BoxCounter, BoxCounters, LinkSpeed};
use skinbox_protocol::command::{
    AckReply, AckRepr, AckResult, CommandRepr, Destination, Opcode, Request,
};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{DatagramRepr, PortCounters, StatusRepr};
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

mod support;

use support::{plugin, temp_dir, tshark};

/// One tshark field per line of output, for each frame.
fn tshark_fields(plugin: &Path, pcap: &Path, fields: &[&str]) -> Vec<Vec<String>> {
    let mut args = vec!["-T", "fields", "-E", "separator=|"];
    for f in fields {
        args.extend(["-e", f]);
    }
    tshark(plugin, pcap, &args)
        .lines()
        .map(|l| l.split('|').map(str::to_string).collect())
        .collect()
}

#[test]
fn commands_acknowledgements_and_box_counters_in_tshark() {
    let dir = temp_dir("control");
    let plugin = plugin(&dir);

    let destination = Destination {
        mac: [2, 0, 0, 0, 0, 9],
        ip: [192, 0, 2, 55],
        port: 40001,
    };
    let mut counters = BoxCounters {
        link_up: true,
        link_speed: LinkSpeed::Mbit1000,
        ..BoxCounters::default()
    };
    for _ in 0..7 {
        counters.bump(BoxCounter::FramesReceived);
    }
    for _ in 0..3 {
        counters.bump(BoxCounter::CommandsAccepted);
    }
    counters.bump(BoxCounter::RefusedReplay);
    let command = CommandRepr {
        box_id: 1,
        sequence: 1234,
        host_time: 99,
        request: Request::StreamTo {
            to: Some(destination),
        },
    };
    let ack = AckRepr {
        box_id: 1,
        port_count: 8,
        sequence: 1234,
        host_time: 99,
        opcode: Opcode::StreamTo as u8,
        result: AckResult::Ok,
        last_accepted: 1234,
        receive_tick: 1000,
        send_tick: 1100,
        reply: AckReply::Destination(destination),
    };
    let status_ack = AckRepr {
        opcode: Opcode::StatusNow as u8,
        sequence: 1235,
        reply: AckReply::Counters(counters),
        ..ack
    };
    let refused = AckRepr {
        opcode: Opcode::ReadTick as u8,
        sequence: 1,
        result: AckResult::Replay,
        reply: AckReply::None,
        ..ack
    };
    let status = DatagramRepr {
        box_id: 1,
        port_count: 2,
        flags: 0,
        sequence: 5,
        base_tick: 777,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 0x5EED_0001,
            datagrams_sent: 4,
            records_sent: 40,
            first_port: 0,
            ports: vec![PortCounters::default(); 2],
        }),
    };
    let payloads = [
        command.to_bytes(),
        ack.to_bytes(),
        status_ack.to_bytes(),
        refused.to_bytes(),
        status.to_bytes_with_box_counters(&counters),
    ];
    let pcap = dir.join("control.pcap");
    let mut w = PcapFrameWriter::new(std::fs::File::create(&pcap).unwrap()).unwrap();
    let host: SocketAddr = "192.0.2.1:40000".parse().unwrap();
    let box_addr: SocketAddr = "192.0.2.10:54091".parse().unwrap();
    for (i, p) in payloads.iter().enumerate() {
        let (src, dst) = if i == 0 {
            (host, box_addr)
        } else {
            (box_addr, host)
        };
        w.write_udp(Duration::from_millis(i as u64), src, dst, p)
            .unwrap();
    }
    w.finish().unwrap();

    let rows = tshark_fields(
        &plugin,
        &pcap,
        &[
            "skinbox.command.opcode",
            "skinbox.command.sequence",
            "skinbox.destination.ip",
            "skinbox.destination.port",
            "skinbox.ack.result",
            "skinbox.ack.receive_tick",
            "skinbox.ack.send_tick",
            "skinbox.box_counters.frames_received",
            "skinbox.box_counters.refused_replay",
            "skinbox.flags.box_counters",
            "_ws.col.Info",
        ],
    );
    assert_eq!(rows.len(), 5, "{rows:?}");
    let [op, seq, ip, port, result, rx, tx, frames, replay, flag, info] =
        [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];
    // the command
    assert_eq!(rows[0][op], "1");
    assert_eq!(rows[0][seq], "1234");
    assert_eq!(rows[0][ip], "192.0.2.55");
    assert_eq!(rows[0][port], "40001");
    assert!(
        rows[0][info].contains("command stream_to"),
        "{}",
        rows[0][info]
    );
    // its acknowledgement, with the destination in effect
    assert_eq!(rows[1][result], "0");
    assert_eq!(
        (rows[1][rx].as_str(), rows[1][tx].as_str()),
        ("1000", "1100")
    );
    assert_eq!(rows[1][ip], "192.0.2.55");
    assert!(
        rows[1][info].contains("ack stream_to, seq 1234: ok"),
        "{}",
        rows[1][info]
    );
    // status-now: the counters
    assert_eq!(rows[2][frames], "7");
    assert_eq!(rows[2][replay], "1");
    // a refusal
    assert_eq!(rows[3][result], "1");
    assert!(rows[3][info].contains("replay"), "{}", rows[3][info]);
    // a status datagram with the block
    assert_eq!(rows[4][flag], "1");
    assert_eq!(rows[4][frames], "7");
}
