//! The box's geometry: how many ports it can have, how the per-port blocks group and bank
//! them, and what a stored packet holds. Every per-port block takes these from here.

use crate::hdl::*;
use skinbox_protocol::cell::PACKET_LEN;

/// Most ports (the port number field of a record is a byte, the status's `port_count`
/// 1 to 64).
pub const MAX_PORTS: usize = skinbox_protocol::datagram::MAX_PORTS as usize;

/// Ports per group: the deframing engine's scan, the counter registers and the port resets
/// gather eight ports' terms in a register first, the groups a clock later (two short OR
/// trees, not one across the chip).
pub const GROUP_PORTS: usize = 8;

/// Port `port`'s group, one-hot (a bit of a `Bits<8>`: at most eight groups).
pub fn group_onehot(port: usize) -> Constant<Bits<8>> {
    Constant::new((1u64 << (port / GROUP_PORTS)).into())
}

/// Stored words of a packet before its cell bytes: the 32-bit start tick.
pub const TICK_BEATS: usize = 4;

/// Packets a port's buffer holds.
pub const SLOTS: usize = 2;

/// Stored words of a packet: tick and cell bytes.
pub const STORED_BEATS: usize = TICK_BEATS + PACKET_LEN;

/// Ports whose packet slots share one block RAM bank (ports 0-31 in bank 0, 32-63 in
/// bank 1; one DP16KD of 2048 x 9 each).
pub const SLOT_BANK_PORTS: usize = 32;

/// Address bits of a slot bank: 5 port, 1 slot, 5 word.
pub const SLOT_BANK_ADDRESS_BITS: usize = 11;

/// Ports whose downlink frame bytes share one block RAM bank of the pin scan (port `p` at
/// word `p % DOWNLINK_BANK_PORTS` of bank `p / DOWNLINK_BANK_PORTS`).
pub const DOWNLINK_BANK_PORTS: usize = 16;

const _: () = assert!(MAX_PORTS <= 8 * GROUP_PORTS);
const _: () = assert!(MAX_PORTS <= 2 * SLOT_BANK_PORTS);
const _: () = assert!(SLOT_BANK_PORTS << 6 == 1 << SLOT_BANK_ADDRESS_BITS);
const _: () = assert!(STORED_BEATS <= 32);
