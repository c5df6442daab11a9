//! A bus: a chain of up to 66 cells relaying their packets to one UART port of the box.
//!
//! Model (docs/design.md section 7): a packet sampled at `sample_time` is ready in its cell after
//! a processing latency, then needs one hop latency per relaying cell to reach the root cell
//! (the one wired to the box). The root holds a FIFO and sends back to back on its UART:
//! 8N1, 10 bits per byte, 200 bits per 20-byte packet, 50 us at 4 Mbit/s, so at most 20,000
//! packets/s. When packets arrive faster the FIFO fills; a packet that finds it full is
//! dropped in the cells and counted against its origin cell.
//!
//! The box pin is driven by the root cell's UART, so every packet of a bus reaches the pin
//! with the root cell's bit period (its own clock error).
//!
//! The way down ([`downlink_arrival_ns`]): a cell command packet leaves the box's UART, is
//! complete in the root cell 50 us later, and each cell relays it outward after the same hop
//! latency as the uplink.

use skinbox_protocol::cell::PACKET_LEN;
use std::collections::VecDeque;

/// Nominal UART bit rate of the cell buses.
pub const UART_BAUD: u64 = skinbox_protocol::cell::UART_BAUD;
/// UART bits on the wire per 20-byte packet (8N1: start, 8 data, stop per byte).
pub const BITS_PER_PACKET: u64 = skinbox_protocol::cell::UART_BITS_PER_PACKET;
/// Nominal bit period in picoseconds (250 ns).
pub const NOMINAL_BIT_PERIOD_PS: u64 = 1_000_000_000_000 / UART_BAUD;
/// Most cells on one bus (Bergner et al.).
pub const MAX_CELLS_PER_BUS: usize = 66;

/// Time a 20-byte cell command packet takes on the box's UART to the root cell, ns (the box
/// sends at the nominal 4 Mbit/s: 200 bits of 250 ns, 50 us).
pub const DOWNLINK_PACKET_NS: u64 = BITS_PER_PACKET * NOMINAL_BIT_PERIOD_PS / 1000;

/// When a cell command packet whose first start bit leaves the box at `leave_box_ns` is
/// complete in the cell at `position` (0 = the root): the packet time to the root, then one
/// store-and-forward hop per cell outward, the uplink's hop latency.
pub fn downlink_arrival_ns(leave_box_ns: u64, position: usize, hop_latency_ns: u64) -> u64 {
    leave_box_ns + DOWNLINK_PACKET_NS + position as u64 * hop_latency_ns
}

/// Bit period of a UART whose clock is `error_ppm` fast (positive) or slow (negative).
pub fn bit_period_ps(error_ppm: f64) -> u32 {
    (NOMINAL_BIT_PERIOD_PS as f64 / (1.0 + error_ppm * 1e-6)).round() as u32
}

/// One packet as it reaches the box pin: what the co-simulation drives bit by bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusPacket {
    /// Cell that sampled and sent the packet.
    pub cell_id: u16,
    /// The 20 packet bytes, sent in order, least significant bit first.
    pub bytes: [u8; PACKET_LEN],
    /// True time the cell took the sample, in simulated ns from the scene start.
    pub sample_time_ns: u64,
    /// True time of the falling edge of the packet's first start bit at the box pin, in
    /// simulated ps from the scene start.
    pub pin_edge_ps: u64,
    /// Bit period of the UART driving the pin (the bus's root cell), in ps; bit `k` of the
    /// packet (0 = first start bit) starts at `pin_edge_ps + k * bit_period_ps`.
    pub bit_period_ps: u32,
}

impl BusPacket {
    /// [`BusPacket::pin_edge_ps`] in whole ns (rounded down).
    pub fn pin_edge_ns(&self) -> u64 {
        self.pin_edge_ps / 1000
    }

    /// End of the packet's last stop bit at the pin, in ps.
    pub fn pin_end_ps(&self) -> u64 {
        self.pin_edge_ps + BITS_PER_PACKET * u64::from(self.bit_period_ps)
    }

    /// Latency from the sample to the first start-bit edge at the pin, in ns.
    pub fn latency_ns(&self) -> u64 {
        self.pin_edge_ns().saturating_sub(self.sample_time_ns)
    }
}

/// Counters of one bus over a run.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct BusStats {
    /// Packets the cells produced.
    pub offered: u64,
    /// Packets that reached the pin.
    pub sent: u64,
    /// Packets dropped because the root FIFO was full.
    pub dropped: u64,
    /// Largest FIFO occupancy seen, in packets (including the one on the wire).
    pub max_queue_packets: usize,
}

/// The root cell's FIFO and UART: accepts packets in order of arrival and sends them back to
/// back.
#[derive(Debug, Clone)]
pub struct RootFifo {
    capacity_packets: usize,
    bit_period_ps: u32,
    /// End times (ps) of the accepted packets whose stop bit has not left yet, oldest first.
    in_fifo_end_ps: VecDeque<u64>,
    line_free_ps: u64,
    stats: BusStats,
}

impl RootFifo {
    /// A FIFO of `capacity_packets` (at least 1; a packet occupies it until its last stop bit
    /// has left) on a UART with bit period `bit_period_ps`.
    pub fn new(capacity_packets: usize, bit_period_ps: u32) -> RootFifo {
        RootFifo {
            capacity_packets: capacity_packets.max(1),
            bit_period_ps,
            in_fifo_end_ps: VecDeque::new(),
            line_free_ps: 0,
            stats: BusStats::default(),
        }
    }

    /// Offers a packet arriving at `arrival_ps` (non-decreasing from call to call): its first
    /// start-bit edge time, or `None` when the FIFO is full and the packet is dropped.
    pub fn offer(&mut self, arrival_ps: u64) -> Option<u64> {
        self.stats.offered += 1;
        while self
            .in_fifo_end_ps
            .front()
            .is_some_and(|&end| end <= arrival_ps)
        {
            self.in_fifo_end_ps.pop_front();
        }
        if self.in_fifo_end_ps.len() >= self.capacity_packets {
            self.stats.dropped += 1;
            return None;
        }
        let start = arrival_ps.max(self.line_free_ps);
        let end = start + BITS_PER_PACKET * u64::from(self.bit_period_ps);
        self.line_free_ps = end;
        self.in_fifo_end_ps.push_back(end);
        self.stats.sent += 1;
        self.stats.max_queue_packets = self.stats.max_queue_packets.max(self.in_fifo_end_ps.len());
        Some(start)
    }

    /// Bit period of the UART, ps.
    pub fn bit_period_ps(&self) -> u32 {
        self.bit_period_ps
    }

    /// Counters so far.
    pub fn stats(&self) -> &BusStats {
        &self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: u64 = 1_000_000; // ps

    #[test]
    fn a_command_reaches_the_root_after_50_us_and_each_cell_one_hop_later() {
        assert_eq!(DOWNLINK_PACKET_NS, 50_000);
        assert_eq!(downlink_arrival_ns(1_000, 0, 52_000), 51_000);
        // The 66th cell: 65 hops of 52 us after the root.
        assert_eq!(downlink_arrival_ns(0, 65, 52_000), 50_000 + 65 * 52_000);
    }

    #[test]
    fn nominal_packet_takes_50_us() {
        assert_eq!(bit_period_ps(0.0), 250_000);
        assert_eq!(BITS_PER_PACKET * u64::from(bit_period_ps(0.0)), 50 * US);
        // 1 % fast: 247.525 ns per bit.
        assert_eq!(bit_period_ps(10_000.0), 247_525);
    }

    #[test]
    fn burst_keeps_capacity_and_sends_back_to_back() {
        let mut fifo = RootFifo::new(4, bit_period_ps(0.0));
        let starts: Vec<_> = (0..10).map(|_| fifo.offer(0)).collect();
        assert_eq!(
            starts,
            vec![
                Some(0),
                Some(50 * US),
                Some(100 * US),
                Some(150 * US),
                None,
                None,
                None,
                None,
                None,
                None
            ]
        );
        // The first packet's stop bit has left at 50 us: one place is free again.
        assert_eq!(fifo.offer(50 * US), Some(200 * US));
        assert_eq!(fifo.offer(50 * US), None);
        let s = fifo.stats();
        assert_eq!((s.offered, s.sent, s.dropped), (12, 5, 7));
        assert_eq!(s.max_queue_packets, 4);
    }

    #[test]
    fn exactly_20000_packets_per_second_never_queue() {
        let mut fifo = RootFifo::new(2, bit_period_ps(0.0));
        for k in 0..20_000u64 {
            assert_eq!(fifo.offer(k * 50 * US), Some(k * 50 * US));
        }
        let s = fifo.stats();
        assert_eq!((s.sent, s.dropped, s.max_queue_packets), (20_000, 0, 1));
    }

    #[test]
    fn above_20000_packets_per_second_drops_exactly_the_excess() {
        // 25,000 packets/s for 1 s into a FIFO of 4: once full, each 50 us departure frees
        // one place, so the accepted packets are the 4 that fill it plus one per departure
        // before the last arrival at 999,960 us: 4 + floor(999,960 / 50) = 20,003.
        let mut fifo = RootFifo::new(4, bit_period_ps(0.0));
        for k in 0..25_000u64 {
            fifo.offer(k * 40 * US);
        }
        let s = fifo.stats();
        assert_eq!(s.offered, 25_000);
        assert_eq!(s.sent, 20_003);
        assert_eq!(s.dropped, 4_997);
        assert_eq!(s.sent + s.dropped, s.offered);
    }

    #[test]
    fn a_slow_root_uart_drops_at_20000_packets_per_second() {
        // 1 % slow: 50.5 us per packet, 19,802 packets/s; 20,000 offered for 1 s.
        let mut fifo = RootFifo::new(8, bit_period_ps(-10_000.0));
        for k in 0..20_000u64 {
            fifo.offer(k * 50 * US);
        }
        let s = fifo.stats();
        assert!(s.dropped > 0);
        // Line busy from 0 to the last arrival: floor(999,950 / 50.5) + 1 = 19,801 departures
        // started, plus up to 8 held: drops within one FIFO of 20,000 - 19,809.
        assert!((191..=199).contains(&s.dropped), "dropped {}", s.dropped);
    }
}
