//! Host frames for the receive path's tests: the model crate's test support (frames built
//! with etherparse and the crc crate, the random frame generator, the downlink pin decoder)
//! and the box configuration, uplink traffic and downlink schedule of the RTL tests.

#![allow(dead_code)]

#[path = "../../../model/tests/support/mod.rs"]
mod model_support;

pub use model_support::*;
use skinbox_cosim::run::SentPacket;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::DataRepr;

/// The box of the support module's control configuration.
pub fn box_config() -> BoxConfig {
    let c = config();
    BoxConfig {
        ports: usize::from(c.port_count),
        box_id: c.box_id,
        link: c.link,
        flush_timeout_ticks: u64::from(c.flush_timeout_ticks),
        status_period_ticks: u64::from(c.status_period_ticks),
        sync_period_ticks: u64::from(c.sync_period_ticks),
        ..BoxConfig::default()
    }
}

/// Cell packets on every port: one every `every_ns` from `from_ns` to `until_ns`.
pub fn traffic(ports: usize, from_ns: f64, until_ns: f64, every_ns: f64) -> Vec<Vec<SentPacket>> {
    let bit_ns = 250.0;
    (0..ports)
        .map(|port| {
            let mut out = vec![];
            let mut t = from_ns + port as f64 * 1_100.0;
            let mut n = 0u16;
            while t < until_ns {
                let bytes = DataRepr::from_raw(
                    (port as u16) << 8 | (n & 0xFF),
                    [i32::from(n), 1, 2, 3, 4, 5, 6, 7, 8],
                )
                .unwrap()
                .to_bytes();
                out.push(SentPacket {
                    bytes,
                    start_ns: t,
                    bit_ns,
                });
                t += every_ns;
                n = n.wrapping_add(1);
            }
            out
        })
        .collect()
}

/// The cell commands of the downlink test (the RTL's acknowledgements are these results,
/// cosim/tests/downlink.rs; the emulator's test replays them on loopback): (box tick of
/// the frame's first edge, port, packet, the result the rules give: two slots a port, a
/// packet queued in every target port or in none). 12 us apart: an acknowledgement waits
/// for the uplink's datagram on the wire, and holds the reply buffer until it has left.
/// (Offers while a packet is still being copied, 20 clocks a port, are refused too: at 8
/// ports the copy ends before the buffer is free again; the block's and the model's tests
/// show it.)
pub fn downlink_schedule() -> Vec<(u64, u8, u8, skinbox_protocol::command::AckResult)> {
    use skinbox_protocol::command::{AckResult, ALL_PORTS};
    let us = 125u64;
    vec![
        (50 * us, 3, 1, AckResult::Ok),
        (62 * us, 3, 2, AckResult::Ok),
        // port 3 holds two: the broadcast goes nowhere, the next for port 3 neither
        (74 * us, ALL_PORTS, 3, AckResult::DownlinkFull),
        (86 * us, 3, 4, AckResult::DownlinkFull),
        // port 3 has drained (two packets take 100 us)
        (200 * us, ALL_PORTS, 5, AckResult::Ok),
        (215 * us, 1, 6, AckResult::Ok),
        (230 * us, ALL_PORTS, 7, AckResult::DownlinkFull),
        (245 * us, 0, 8, AckResult::Ok),
    ]
}
