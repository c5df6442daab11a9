//! DownlinkPacketCopy: captures a cell command's packet as the frame goes by and copies
//! an accepted one into each target port's queue.
//!
//! The bytes the frame parser writes at frame offsets [`PACKET_OFFSET`].. go into a
//! 160-bit register a clock after they are written, whatever the frame is. An `offer`
//! (registered: the copy starts a clock after it) moves the packet to the staging
//! register, and it is written a byte a clock into the queue RAM at the target port's free
//! slot (`copy_tail`, which the downlink looks up for `copy_port`), port after port for
//! `ALL_PORTS`: [`COPY_CLOCKS_PER_PORT`] clocks each. `commit` (one clock, with
//! `copy_port`) says a port's copy is whole; `accepted` follows a clock later. The queue
//! RAM's writes leave registers (a slot's last byte lands a clock after its commit, long
//! before a refill reads it).

use crate::hdl::*;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::{cell_command_field, ALL_PORTS, HEADER_LEN};
use skinbox_protocol::link::{ETHERNET_HEADER_LEN, IPV4_HEADER_LEN, UDP_HEADER_LEN};

/// Frame offset of the cell packet in a cell command frame: Ethernet, IPv4 (no options)
/// and UDP headers, the command header, then the arguments' packet field.
pub const PACKET_OFFSET: usize = ETHERNET_HEADER_LEN
    + IPV4_HEADER_LEN
    + UDP_HEADER_LEN
    + HEADER_LEN
    + cell_command_field::PACKET.start;

/// Clocks the copy of a packet into one port's queue takes.
pub const COPY_CLOCKS_PER_PORT: u64 = PACKET_LEN as u64;

/// Queue RAM address bits: 6 of port, 1 of slot, 5 of byte index.
pub const QUEUE_ADDRESS_BITS: usize = 12;

/// The capture and copy of cell command packets into the queues of N ports.
#[derive(LogicBlock)]
pub struct DownlinkPacketCopy {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no copy under way.
    pub reset: Signal<In, Bit>,
    /// A byte of a received frame is written into the reply buffer at `capture_address`.
    pub capture: Signal<In, Bit>,
    /// Frame offset of the byte on `capture_data`.
    pub capture_address: Signal<In, Bits<11>>,
    /// The byte written.
    pub capture_data: Signal<In, Bits<8>>,
    /// One clock: copy the captured packet to `offer_port` (a port, or `ALL_PORTS`).
    pub offer: Signal<In, Bit>,
    /// Target of the offer.
    pub offer_port: Signal<In, Bits<8>>,
    /// An offer was taken or a packet is being copied: no offer now.
    pub busy: Signal<Out, Bit>,
    /// The port being copied to.
    pub copy_port: Signal<Out, Bits<8>>,
    /// The free slot of `copy_port` (its queue's tail).
    pub copy_tail: Signal<In, Bit>,
    /// One clock: the copy to `copy_port` is whole.
    pub commit: Signal<Out, Bit>,
    /// Queue RAM write: enable, address (port, slot, byte) and byte.
    pub queue_write: Signal<Out, Bit>,
    /// Address of the queue RAM write.
    pub queue_write_address: Signal<Out, Bits<QUEUE_ADDRESS_BITS>>,
    /// Byte of the queue RAM write.
    pub queue_write_data: Signal<Out, Bits<8>>,
    /// High for one clock a clock after a commit, with `accepted_port`.
    pub accepted: Signal<Out, Bit>,
    /// The port of that commit.
    pub accepted_port: Signal<Out, Bits<8>>,
    last_port: Constant<Bits<8>>,
    packet_first: Constant<Bits<11>>,
    packet_last: Constant<Bits<11>>,
    all_ports: Constant<Bits<8>>,
    /// A byte at the packet's offsets was written, registered: the packet register shifts
    /// it in a clock later (the offset's decode does not reach the 160 flip-flops).
    capture_hit: DFF<Bit>,
    capture_byte: DFF<Bits<8>>,
    captured: DFF<Bits<160>>,
    offered: DFF<Bit>,
    offered_port: DFF<Bits<8>>,
    staging: DFF<Bits<160>>,
    copying: DFF<Bit>,
    broadcast: DFF<Bit>,
    port: DFF<Bits<8>>,
    index: DFF<Bits<5>>,
    accepted_out: DFF<Bit>,
    accepted_port_out: DFF<Bits<8>>,
    write_enable: DFF<Bit>,
    write_address: DFF<Bits<QUEUE_ADDRESS_BITS>>,
    write_data: DFF<Bits<8>>,
    committing: Signal<Local, Bit>,
}

impl DownlinkPacketCopy {
    /// The copy into the queues of `ports` ports.
    pub fn new(ports: usize) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            capture: Default::default(),
            capture_address: Default::default(),
            capture_data: Default::default(),
            offer: Default::default(),
            offer_port: Default::default(),
            busy: Default::default(),
            copy_port: Default::default(),
            copy_tail: Default::default(),
            commit: Default::default(),
            queue_write: Default::default(),
            queue_write_address: Default::default(),
            queue_write_data: Default::default(),
            accepted: Default::default(),
            accepted_port: Default::default(),
            last_port: Constant::new((ports as u64 - 1).into()),
            packet_first: Constant::new((PACKET_OFFSET as u64).into()),
            packet_last: Constant::new(((PACKET_OFFSET + PACKET_LEN - 1) as u64).into()),
            all_ports: Constant::new(u64::from(ALL_PORTS).into()),
            capture_hit: Default::default(),
            capture_byte: Default::default(),
            captured: Default::default(),
            offered: Default::default(),
            offered_port: Default::default(),
            staging: Default::default(),
            copying: Default::default(),
            broadcast: Default::default(),
            port: Default::default(),
            index: Default::default(),
            accepted_out: Default::default(),
            accepted_port_out: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            committing: Default::default(),
        }
    }
}

impl Logic for DownlinkPacketCopy {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            capture_hit,
            capture_byte,
            captured,
            offered,
            offered_port,
            staging,
            copying,
            broadcast,
            port,
            index,
            accepted_out,
            accepted_port_out,
            write_enable,
            write_address,
            write_data
        );
        self.write_enable.d.next = false;
        self.write_data.d.next = self.staging.q.val().get_bits::<8>(0);
        self.queue_write.next = self.write_enable.q.val();
        self.queue_write_address.next = self.write_address.q.val();
        self.queue_write_data.next = self.write_data.q.val();
        self.accepted_out.d.next = false;
        // capture: the bytes at the packet's frame offsets, the first ending in bits 7..0
        self.capture_hit.d.next = self.capture.val()
            & (self.capture_address.val() >= self.packet_first.val())
            & (self.capture_address.val() <= self.packet_last.val());
        self.capture_byte.d.next = self.capture_data.val();
        if self.capture_hit.q.val() {
            self.captured.d.next = (self.captured.q.val() >> 8)
                | (bit_cast::<160, 8>(self.capture_byte.q.val()) << 152);
        }
        self.busy.next = self.copying.q.val() | self.offered.q.val();
        self.offered.d.next = self.offer.val();
        self.offered_port.d.next = self.offer_port.val();
        if self.offered.q.val() {
            self.staging.d.next = self.captured.q.val();
            self.copying.d.next = true;
            self.index.d.next = 0.into();
            self.broadcast.d.next = self.offered_port.q.val() == self.all_ports.val();
            self.port.d.next = self.offered_port.q.val();
            if self.offered_port.q.val() == self.all_ports.val() {
                self.port.d.next = 0.into();
            }
        }
        // copy the staged packet into the target port's free slot
        self.copy_port.next = self.port.q.val();
        self.committing.next = false;
        if self.copying.q.val() {
            self.write_enable.d.next = true;
            self.write_address.d.next = (bit_cast::<QUEUE_ADDRESS_BITS, 8>(self.port.q.val()) << 6)
                | (bit_cast::<QUEUE_ADDRESS_BITS, 1>(self.copy_tail.val().into()) << 5)
                | bit_cast::<QUEUE_ADDRESS_BITS, 5>(self.index.q.val());
            self.staging.d.next = (self.staging.q.val() >> 8)
                | (bit_cast::<160, 8>(self.staging.q.val().get_bits::<8>(0)) << 152);
            self.index.d.next = self.index.q.val() + 1;
            if self.index.q.val() == 19 {
                self.committing.next = true;
                self.accepted_out.d.next = true;
                self.accepted_port_out.d.next = self.port.q.val();
            }
        }
        self.commit.next = self.committing.val();
        if self.committing.val() {
            self.index.d.next = 0.into();
            if self.broadcast.q.val() & (self.port.q.val() != self.last_port.val()) {
                self.port.d.next = self.port.q.val() + 1;
            } else {
                self.copying.d.next = false;
            }
        }
        self.accepted.next = self.accepted_out.q.val();
        self.accepted_port.next = self.accepted_port_out.q.val();
        if self.reset.val() {
            self.copying.d.next = false;
            self.offered.d.next = false;
            self.write_enable.d.next = false;
            self.accepted_out.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// A packet captured from a frame and offered to every port of three is written into
    /// each port's free slot, byte after byte, with a commit and an acceptance per port;
    /// `busy` holds from the clock after the offer to the last commit.
    #[test]
    fn an_all_ports_offer_is_copied_into_every_port_in_order() {
        let ports = 3;
        let mut bench = Bench::new(DownlinkPacketCopy::new(ports), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut rng = TestRng::new(9);
        let frame: Vec<u8> = (0..PACKET_OFFSET + PACKET_LEN + 6)
            .map(|_| rng.byte())
            .collect();
        for (offset, byte) in frame.iter().enumerate() {
            bench.uut.capture.next = true;
            bench.uut.capture_address.next = (offset as u64).into();
            bench.uut.capture_data.next = u64::from(*byte).into();
            bench.cycle();
        }
        bench.uut.capture.next = false;
        bench.cycles(2);
        bench.uut.offer.next = true;
        bench.uut.offer_port.next = u64::from(ALL_PORTS).into();
        bench.cycle();
        bench.uut.offer.next = false;
        // port p's free slot is p % 2
        let mut writes = vec![];
        let mut commits = vec![];
        let mut accepted = vec![];
        for _ in 0..100 {
            let port = bench.uut.copy_port.val().to_u32();
            bench.uut.copy_tail.next = port % 2 == 1;
            bench.cycle();
            let uut = &bench.uut;
            if uut.queue_write.val() {
                writes.push((
                    uut.queue_write_address.val().to_u32(),
                    uut.queue_write_data.val().to_u32() as u8,
                ));
            }
            if uut.commit.val() {
                commits.push(uut.copy_port.val().to_u32());
            }
            if uut.accepted.val() {
                accepted.push(uut.accepted_port.val().to_u32());
            }
        }
        assert!(!bench.uut.busy.val());
        let packet = &frame[PACKET_OFFSET..PACKET_OFFSET + PACKET_LEN];
        let expected: Vec<(u32, u8)> = (0..ports as u32)
            .flat_map(|p| {
                packet
                    .iter()
                    .enumerate()
                    .map(move |(i, b)| (p << 6 | (p % 2) << 5 | i as u32, *b))
            })
            .collect();
        assert_eq!(writes, expected);
        assert_eq!(commits, vec![0, 1, 2]);
        assert_eq!(accepted, vec![0, 1, 2]);
    }
}
