//! The downlink model: a command flood to one port is refused and counted, and an idle
//! downlink starts each packet in the next frame (the RTL's pins are held to this model in
//! cosim/tests/downlink.rs); the sync generator sends every port a sync each period.

mod support;

use skinbox_model::control::BoxControl;
use skinbox_model::downlink::DownlinkModel;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::Request;
use support::*;

#[test]
fn a_command_flood_to_one_port_is_refused_and_counted_not_queued() {
    // the model of the downlink the RTL test holds to the gateware: 2,000 commands to one
    // port, one every 0.8 us, for 1.6 ms; the port carries one every 50 us
    let config = config();
    let mut m = BoxControl::new(config);
    let mut results = [0u32; 2];
    let mut tick = 1_000;
    for i in 0..2_000u32 {
        let frame = command(
            HOST_IP,
            i + 1,
            Request::CellCommand {
                port: 5,
                packet: cell_packet(i as u8),
            },
        );
        let out = m.receive(&frame, tick);
        match out.fate {
            BoxCounter::CommandsAccepted => results[0] += 1,
            BoxCounter::RefusedDownlinkFull => results[1] += 1,
            f => panic!("command {i}: {f:?}"),
        }
        tick += 100;
    }
    let end = m.downlink.drain();
    // two queued at once, then one each time a packet's last byte has been read
    let line_ticks = (200.0 * BIT_TICKS) as u64;
    let carried = 2 + (tick - 1_000) / line_ticks;
    assert!(
        (i64::from(results[0]) - carried as i64).abs() <= 1,
        "accepted {}, the line carries {carried}",
        results[0]
    );
    assert_eq!(results[0] + results[1], 2_000);
    assert_eq!(m.counters.get(BoxCounter::RefusedDownlinkFull), results[1]);
    // all of them went out, back to back, and nothing else
    let decoded = decode_pins(m.downlink.changes(), 8);
    assert_eq!(decoded[5].len(), results[0] as usize * PACKET_LEN);
    assert!(decoded
        .iter()
        .enumerate()
        .all(|(p, d)| p == 5 || d.is_empty()));
    assert!(end < tick + 3 * line_ticks);
}

#[test]
fn the_downlink_model_is_idle_cheap_and_starts_each_packet_in_the_next_frame() {
    // a packet offered on an idle 64-port downlink (11-bit frames) is committed after its
    // copy (the offer register and 20 clocks); the first refill scan that visits its port
    // after that (one port a clock from the clock after a frame's last data bit went to
    // the pins) loads its first byte, whose start bit opens the next frame
    let (clock_hz, baud) = (125_000_000, 4_000_000);
    let frame = skinbox_gateware::cell_downlink::frame_bits(64);
    assert_eq!(frame, 11);
    let bit = |b: u64| skinbox_gateware::cell_downlink::bit_start(clock_hz, baud, b);
    for port in [0u8, 17, 63] {
        let mut d = DownlinkModel::new(64, clock_hz, baud);
        let offer = 1_000_000_007;
        assert!(d.offer(offer, port, cell_packet(1)));
        d.drain();
        let first = d.changes()[0];
        assert_eq!(first.port, usize::from(port));
        assert!(!first.level);
        let counted = offer + 1 + 20 + 1;
        let f = (0..)
            .find(|f| bit(f * frame + 8) + u64::from(port) >= counted)
            .unwrap();
        assert_eq!(first.tick, bit((f + 1) * frame), "port {port}");
    }
}

#[test]
fn an_idle_downlink_sends_the_generators_syncs_each_period_stamped_and_none_while_off() {
    // 64 ports at a 1 ms period: each port's sync opens the first frame whose refill sees
    // the toggle (within two frames), carries its start tick, and a host's sync on the
    // same downlink is stamped too; period 0 stops them, a new period sends one at once
    use skinbox_model::downlink::generated_sync;
    let (clock_hz, baud) = (125_000_000, 4_000_000);
    let frame_ticks = 11 * 32;
    let period = 125_000;
    let mut d = DownlinkModel::new(64, clock_hz, baud).with_sync_period(period);
    let mut host_sync = cell_packet(9);
    host_sync[3] = 5;
    assert!(d.offer(10_000, 7, host_sync));
    d.advance_to(3 * period + 20_000);
    let host: Vec<_> = d
        .starts()
        .iter()
        .filter(|s| s.bytes[..4] == host_sync[..4])
        .collect();
    assert_eq!(host.len(), 1);
    assert_eq!(host[0].bytes[4..12], host[0].tick.to_be_bytes());
    assert_eq!(host[0].bytes[12..], host_sync[12..]);
    for port in 0..64 {
        let syncs: Vec<u64> = d
            .starts()
            .iter()
            .filter(|s| s.port == port && s.bytes == generated_sync(s.tick))
            .map(|s| s.tick)
            .collect();
        // at once after reset (the generator restarts in the first clock), then every period
        assert_eq!(syncs.len(), 4, "port {port}");
        for (k, tick) in syncs.iter().enumerate() {
            let toggle = 1 + k as u64 * period;
            assert!(
                (toggle..toggle + 2 * frame_ticks).contains(tick),
                "port {port}: {tick}"
            );
        }
    }
    let before = d.starts().len();
    d.set_sync_period(400_000, 0);
    d.advance_to(1_000_000);
    assert_eq!(d.starts().len(), before, "no syncs while off");
    d.set_sync_period(1_000_000, 2 * period);
    d.advance_to(1_000_000 + 2 * period + 10_000);
    let after: Vec<u64> = d.starts()[before..].iter().map(|s| s.tick).collect();
    assert_eq!(after.len(), 2 * 64);
    assert!(after[..64]
        .iter()
        .all(|t| (1_000_002..1_000_002 + 2 * frame_ticks).contains(t)));
    let again = 1_000_002 + 2 * period;
    assert!(after[64..]
        .iter()
        .all(|t| (again..again + 2 * frame_ticks).contains(t)));
}
