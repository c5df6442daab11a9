//! The closed-form rate model: the third fidelity level of docs/design.md section 6. Rates and
//! loads of a whole skin from a handful of numbers, with no time loop, for sweeps over
//! millions of cells.
//!
//! - A cell sends `packets_per_sample` packets per sample: 1 in data mode; in event mode the
//!   calibrated packet rate of its scene (the papers' Fig. 8, which the cell models
//!   reproduce within 3 %: `skinbox calibrate`).
//! - A bus's root UART carries at most 20,000 packets/s (4 Mbit/s, 200 bits a packet); the
//!   excess is dropped.
//! - The box writes one record into a datagram in 30 clocks (26 record bytes and the 4-clock
//!   pause that rewrites its tick), 4.17 M records/s at 125 MHz: the box's own ceiling.
//! - A datagram holds the records that arrive while it waits for its flush timeout,
//!   `1 + rate * timeout` for a steady rate, at most 55; on the wire it costs preamble,
//!   headers, FCS and gap: `90 + 26 k` bytes for `k` records at 125 M bytes/s.
//! - Status datagrams: one per status period for every [`MAX_STATUS_PORTS`] ports.
//!
//! What it leaves out, by design: the start-up burst of event mode (every cell's first
//! sample sends two packets), short bursts that fill the root FIFOs below the mean rate,
//! and the framer closing a datagram late while the link is busy (which packs more records
//! under load). The fidelity study (C2) measures what that costs against the RTL.

use skinbox_protocol::cell::{PACKET_LEN, UART_BAUD, UART_BITS_PER_PACKET};
use skinbox_protocol::datagram::{HEADER_LEN, MAX_RECORDS, MAX_STATUS_PORTS};
use skinbox_protocol::link::{
    ETHERNET_HEADER_LEN, FCS_LEN, INTER_FRAME_GAP, IPV4_HEADER_LEN, LINK_BITS_PER_S, MIN_FRAME_LEN,
    PREAMBLE_LEN, UDP_HEADER_LEN,
};
use skinbox_protocol::record::{self, RECORD_LEN};

/// Packets per second one bus's root UART carries (4 Mbit/s, 8N1, 20 bytes).
pub const BUS_PACKETS_PER_S: f64 = (UART_BAUD / UART_BITS_PER_PACKET) as f64;
/// Bytes per second of Gigabit Ethernet.
pub const LINK_BYTES_PER_S: f64 = (LINK_BITS_PER_S / 8) as f64;
/// Box clock, Hz.
pub const CLOCK_HZ: f64 = skinbox_gateware::CLOCK_HZ as f64;
/// Clocks the framer takes to write one record (26 bytes, then one per tick offset byte,
/// 4, while it rewrites the tick).
pub const RECORD_WRITE_CLOCKS: f64 =
    (RECORD_LEN + record::field::TICK_OFFSET.end - record::field::TICK_OFFSET.start) as f64;
/// Wire bytes of an Ethernet frame besides its UDP payload: preamble and SFD (8), Ethernet
/// header (14), IPv4 (20), UDP (8), FCS (4), inter-frame gap (12).
pub const FRAME_OVERHEAD_BYTES: f64 = (PREAMBLE_LEN
    + ETHERNET_HEADER_LEN
    + IPV4_HEADER_LEN
    + UDP_HEADER_LEN
    + FCS_LEN
    + INTER_FRAME_GAP) as f64;

/// Wire bytes of a records datagram with `records` records (padding to the 60-byte
/// minimum frame never applies: the 24-byte header and one record make 50 payload bytes).
pub fn records_frame_wire_bytes(records: f64) -> f64 {
    FRAME_OVERHEAD_BYTES + HEADER_LEN as f64 + RECORD_LEN as f64 * records
}

/// Wire bytes of one datagram of the original box: one 20-byte cell packet as the UDP
/// payload, padded to the 60-byte minimum frame: 86 bytes.
pub fn original_frame_wire_bytes() -> f64 {
    let frame =
        (ETHERNET_HEADER_LEN + IPV4_HEADER_LEN + UDP_HEADER_LEN + PACKET_LEN).max(MIN_FRAME_LEN);
    (PREAMBLE_LEN + frame + FCS_LEN + INTER_FRAME_GAP) as f64
}

/// Records a datagram holds at a steady `records_per_s` with `flush_timeout_s`: the first
/// record and those arriving while it waits, at most 55.
pub fn records_per_datagram(records_per_s: f64, flush_timeout_s: f64) -> f64 {
    (1.0 + records_per_s * flush_timeout_s).min(MAX_RECORDS as f64)
}

/// Records per second the framer can write (its ceiling, whatever the link).
pub fn framer_records_per_s() -> f64 {
    CLOCK_HZ / RECORD_WRITE_CLOCKS
}

/// Share of the link's time that records datagrams of `records_per_datagram` records take at
/// `records_per_s`.
pub fn link_load(records_per_s: f64, records_per_datagram: f64) -> f64 {
    records_per_s / records_per_datagram * records_frame_wire_bytes(records_per_datagram)
        / LINK_BYTES_PER_S
}

/// Records per second the link carries when every datagram holds `records_per_datagram`
/// records, capped by the framer's ceiling.
pub fn capacity_records_per_s(records_per_datagram: f64) -> f64 {
    let link =
        LINK_BYTES_PER_S * records_per_datagram / records_frame_wire_bytes(records_per_datagram);
    link.min(framer_records_per_s())
}

/// Records per second of the original box: one 86-byte frame per packet.
pub fn original_capacity_records_per_s() -> f64 {
    LINK_BYTES_PER_S / original_frame_wire_bytes()
}

/// What the rate model needs of a skin and a box.
#[derive(Debug, Clone)]
pub struct RateInputs {
    /// Cells on each bus.
    pub cells_per_bus: Vec<usize>,
    /// Sample rate of every cell, Hz.
    pub sample_rate_hz: f64,
    /// Packets per sample and cell (1 in data mode).
    pub packets_per_sample: f64,
    /// Flush timeout of the box, s.
    pub flush_timeout_s: f64,
    /// Status period of the box, s.
    pub status_period_s: f64,
}

/// The rate model's answer for a skin.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RatePrediction {
    /// Packets per second the cells make.
    pub offered_per_s: f64,
    /// Packets per second the buses carry to the box.
    pub delivered_per_s: f64,
    /// Share of the packets the bus roots drop.
    pub bus_loss: f64,
    /// Records per records datagram.
    pub records_per_datagram: f64,
    /// Datagrams (records and status) per second.
    pub datagrams_per_s: f64,
    /// Share of the link's time in use.
    pub link_load: f64,
}

/// The closed form.
pub fn predict(inputs: &RateInputs) -> RatePrediction {
    let per_cell = inputs.sample_rate_hz * inputs.packets_per_sample;
    let (mut offered, mut delivered) = (0.0, 0.0);
    for &cells in &inputs.cells_per_bus {
        let bus = cells as f64 * per_cell;
        offered += bus;
        delivered += bus.min(BUS_PACKETS_PER_S);
    }
    let carried = delivered.min(framer_records_per_s());
    let k = records_per_datagram(carried, inputs.flush_timeout_s);
    let status_per_s =
        inputs.cells_per_bus.len().div_ceil(MAX_STATUS_PORTS) as f64 / inputs.status_period_s;
    RatePrediction {
        offered_per_s: offered,
        delivered_per_s: carried,
        bus_loss: if offered > 0.0 {
            1.0 - carried / offered
        } else {
            0.0
        },
        records_per_datagram: k,
        datagrams_per_s: carried / k + status_per_s,
        link_load: link_load(carried, k),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_sizes_match_the_design_figures() {
        // docs/design.md section 5: 55 records, 1520 bytes on the wire with preamble and gap.
        assert_eq!(MAX_RECORDS, 55);
        assert_eq!(records_frame_wire_bytes(55.0), 1520.0);
        // The original box: a minimum frame, 1.45 M datagrams/s (docs/design.md section 2).
        assert_eq!(original_frame_wire_bytes(), 86.0);
        let original = original_capacity_records_per_s();
        assert!((1.44e6..1.5e6).contains(&original), "{original}");
        // Full datagrams: 82,000 frames/s and 4.5 M records/s on the link, but the framer
        // writes at most 4.17 M records/s.
        let link_full = LINK_BYTES_PER_S / 1520.0 * 55.0;
        assert!((4.5e6..4.55e6).contains(&link_full));
        assert!((framer_records_per_s() - 125e6 / 30.0).abs() < 1.0);
        assert_eq!(capacity_records_per_s(55.0), framer_records_per_s());
    }

    #[test]
    fn buses_saturate_at_20000_packets_per_second() {
        let inputs = RateInputs {
            cells_per_bus: vec![66, 100],
            sample_rate_hz: 250.0,
            packets_per_sample: 1.0,
            flush_timeout_s: 100e-6,
            status_period_s: 0.1,
        };
        let p = predict(&inputs);
        assert_eq!(p.offered_per_s, 166.0 * 250.0);
        assert_eq!(p.delivered_per_s, 66.0 * 250.0 + 20_000.0);
        assert!((p.bus_loss - 5_000.0 / 41_500.0).abs() < 1e-12);
        // 36,500 records/s wait 100 us: 4.65 records a datagram.
        assert!((p.records_per_datagram - 4.65).abs() < 1e-9);
        assert!((p.datagrams_per_s - (36_500.0 / 4.65 + 10.0)).abs() < 1e-6);
    }

    #[test]
    fn a_long_timeout_fills_datagrams_and_a_short_one_sends_one_record_each() {
        assert_eq!(records_per_datagram(1e6, 1.0), 55.0);
        assert_eq!(records_per_datagram(1e3, 0.0), 1.0);
        assert!(capacity_records_per_s(1.0) < original_capacity_records_per_s());
    }
}
