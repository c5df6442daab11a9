//! The box's own time syncs at RTL: with a sync period of 1 ms the verilated box of 8
//! ports, its uplink at line rate, sends every port a time sync to every cell each period.
//! Every transmit pin change and every frame equals the reference model's; each sync
//! packet's `box_tick`, a host's as well as the box's, equals the tick of its first start
//! bit's falling edge as measured on the pin; host cell commands sent next to the syncs are
//! all taken while their queues have room; `set sync period` 0 stops the syncs and a new
//! period restarts them at once; status datagrams carry `FLAG_TIME_SYNCS` exactly while
//! the syncs are on.

mod support;

use skinbox_cosim::harness::{LINK_SPEED, LINK_UP};
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::run::{HostFrame, SimSpec, TICK_ZERO_CYCLE};
use skinbox_cosim::sim::run_rtl;
use skinbox_gateware::interface_box::{BoxConfig, RECEIVE_TICK_LAG};
use skinbox_model::control::{BoxControl, ControlConfig, Reply};
use skinbox_model::downlink::generated_sync;
use skinbox_protocol::cell_command::CommandCode;
use skinbox_protocol::command::{AckRepr, AckResult, Request, ALL_PORTS};
use skinbox_protocol::datagram::{DatagramBody, FLAG_TIME_SYNCS};
use support::*;

const US: u64 = 125;
const MS: u64 = 125_000;

#[test]
fn every_port_sends_a_stamped_sync_each_period_and_set_sync_period_stops_and_restarts_them() {
    let config = BoxConfig {
        sync_period_ticks: MS,
        status_period_ticks: MS / 8,
        ..box_config()
    };
    let mut host_sync = cell_packet(1);
    host_sync[3] = CommandCode::TimeSync as u8;
    // (frame edge, request, the result the rules give)
    let schedule = [
        (
            100 * US,
            Request::CellCommand {
                port: 2,
                packet: host_sync,
            },
            AckResult::Ok,
        ),
        (
            130 * US,
            Request::CellCommand {
                port: ALL_PORTS,
                packet: cell_packet(2),
            },
            AckResult::Ok,
        ),
        // around the first period's syncs: two slots on port 5, the sync takes none
        (
            990 * US,
            Request::CellCommand {
                port: 5,
                packet: cell_packet(3),
            },
            AckResult::Ok,
        ),
        (
            1002 * US,
            Request::CellCommand {
                port: 5,
                packet: cell_packet(4),
            },
            AckResult::Ok,
        ),
        (
            1014 * US,
            Request::CellCommand {
                port: 5,
                packet: cell_packet(5),
            },
            AckResult::DownlinkFull,
        ),
        (
            2200 * US,
            Request::SetSyncPeriod { ticks: 0 },
            AckResult::Ok,
        ),
        (
            2300 * US,
            Request::SetSyncPeriod {
                ticks: MS as u32 - 1,
            },
            AckResult::BadArgument,
        ),
        (
            2400 * US,
            Request::SetSyncPeriod { ticks: MS as u32 },
            AckResult::Ok,
        ),
    ];
    let host_frames: Vec<HostFrame> = schedule
        .iter()
        .enumerate()
        .map(|(i, (edge, request, _))| HostFrame {
            edge: *edge,
            frame: command(HOST_IP, 100 + i as u32, *request),
        })
        .collect();
    let spec = SimSpec {
        config: config.clone(),
        ports: traffic(config.ports, 20_000.0, 2_500_000.0, 50_000.0),
        duration_ns: 2_600_000,
        pcap: None,
        vcd: None,
        jitter: skinbox_cosim::line::Jitter::NONE,
        host_frames: host_frames.clone(),
    };
    let run = run_rtl(&spec).unwrap();
    let predicted = run_reference(&spec).unwrap();
    assert_eq!(
        run.frames, predicted.frames,
        "frames: RTL against reference"
    );
    for (i, (r, p)) in run.uart_tx.iter().zip(&predicted.uart_tx).enumerate() {
        assert_eq!(r, p, "pin change {i}: RTL against reference");
    }
    assert_eq!(run.uart_tx.len(), predicted.uart_tx.len(), "pin changes");

    // the acknowledgements: the rules' results, as the control model gives them
    let mut m = BoxControl::new(ControlConfig::of(&config));
    m.counters.link_up = LINK_UP;
    m.counters.link_speed = LINK_SPEED;
    let receive_tick = |f: &HostFrame| f.last_edge() + RECEIVE_TICK_LAG - TICK_ZERO_CYCLE;
    let acks: Vec<AckRepr> = run
        .replies
        .iter()
        .map(|f| AckRepr::parse(&f.bytes[8 + 42..f.bytes.len() - 4]).unwrap())
        .collect();
    assert_eq!(acks.len(), host_frames.len());
    for (i, f) in host_frames.iter().enumerate() {
        let Some(Reply::Ack { ack, .. }) = m.receive(&f.frame, receive_tick(f)).reply else {
            panic!("frame {i}: no acknowledgement from the model");
        };
        assert_eq!(acks[i].result, ack.result, "frame {i}");
        assert_eq!(acks[i].result, schedule[i].2, "frame {i}");
    }

    // the pins, measured: every sync carries its first start bit's falling edge
    let (off, on) = (receive_tick(&host_frames[5]), receive_tick(&host_frames[7]));
    // the epoch toggles in the clock after reset's restart, then every period, and at the re-set
    let toggles = [1, MS + 1, 2 * MS + 1, on];
    let packet_ticks = 20 * 10 * 125 / 4;
    for (port, bytes) in decode_pins(&run.uart_tx, config.ports).iter().enumerate() {
        let (mut hosts, mut syncs) = (vec![], vec![]);
        for frames in bytes.chunks(20) {
            let start = frames[0].0;
            let packet: Vec<u8> = frames.iter().map(|f| f.1).collect();
            if packet[3] == CommandCode::TimeSync as u8 {
                assert_eq!(packet[4..12], start.to_be_bytes(), "port {port} at {start}");
            }
            if packet == generated_sync(start) {
                syncs.push(start);
            } else {
                hosts.push(packet);
            }
        }
        let mut expected = vec![];
        if port == 2 {
            expected.push(host_sync.to_vec());
        }
        expected.push(cell_packet(2).to_vec());
        if port == 5 {
            expected.extend([cell_packet(3).to_vec(), cell_packet(4).to_vec()]);
        }
        for (got, want) in hosts.iter().zip(&expected) {
            // (a host's sync as it left: its tick is the box's)
            assert_eq!(got[..4], want[..4], "port {port}");
            assert_eq!(got[12..], want[12..], "port {port}");
        }
        assert_eq!(hosts.len(), expected.len(), "port {port}");
        assert_eq!(
            syncs.len(),
            toggles.len(),
            "port {port}: syncs at {syncs:?}"
        );
        for (start, toggle) in syncs.iter().zip(toggles) {
            // at the port's next packet boundary: within a packet and two frames
            assert!(
                (toggle..toggle + packet_ticks + 2 * 10 * 32).contains(start),
                "port {port}: sync at {start} for {toggle}"
            );
        }
        assert!(syncs.iter().all(|s| !(off..on).contains(s)), "port {port}");
    }

    // status datagrams say whether the syncs are on
    let statuses: Vec<(u64, bool)> = run
        .datagrams
        .iter()
        .filter(|d| matches!(d.body, DatagramBody::Status(_)))
        .map(|d| (d.base_tick, d.flags & FLAG_TIME_SYNCS != 0))
        .collect();
    for &(tick, flag) in &statuses {
        assert_eq!(flag, !(off..on).contains(&tick), "status at {tick}");
    }
    assert!(statuses.iter().any(|s| !s.1) && statuses.iter().filter(|s| s.1).count() >= 3);
}
