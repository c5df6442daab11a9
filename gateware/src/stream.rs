//! The one stream interface between blocks: bytes with valid, ready and last.
//!
//! A beat moves when `valid & ready` at a rising clock edge. `last` marks the final beat of
//! a packet; `error` is meaningful on the `last` beat only and marks the whole packet as
//! bad, so a receiver that stores packets can discard it. A source never interleaves two
//! packets and never takes `valid` back before the beat moved.

use crate::hdl::*;

/// Bits of a datagram's body sum: the ones'-complement running sum of its 16-bit words, 16
/// bits and, in bit 16, the last addition's carry, which the next addition folds in (as
/// [`OnesComplementSum`](crate::ones_complement_sum::OnesComplementSum) keeps it). Its
/// value is the words' sum modulo 0xFFFF.
pub const BODY_SUM_BITS: usize = 17;

/// The sending side of a byte stream.
#[derive(LogicInterface, Default)]
#[join = "ByteStreamSink"]
pub struct ByteStreamSource {
    /// The byte of this beat.
    pub data: Signal<Out, Bits<8>>,
    /// A beat is offered.
    pub valid: Signal<Out, Bit>,
    /// The beat is the last of its packet.
    pub last: Signal<Out, Bit>,
    /// On the last beat: the packet is bad and must be discarded.
    pub error: Signal<Out, Bit>,
    /// The receiver takes the beat.
    pub ready: Signal<In, Bit>,
}

/// The receiving side of a byte stream.
#[derive(LogicInterface, Default)]
#[join = "ByteStreamSource"]
pub struct ByteStreamSink {
    /// The byte of this beat.
    pub data: Signal<In, Bits<8>>,
    /// A beat is offered.
    pub valid: Signal<In, Bit>,
    /// The beat is the last of its packet.
    pub last: Signal<In, Bit>,
    /// On the last beat: the packet is bad and must be discarded.
    pub error: Signal<In, Bit>,
    /// This side takes the beat.
    pub ready: Signal<Out, Bit>,
}

/// Descriptor kind of a raw frame: its body is the whole Ethernet frame from the
/// destination MAC on, padded to the minimum length by its source; the transmitter adds
/// only preamble, SFD and FCS. (No box datagram has kind 0.)
pub const RAW_FRAME_KIND: u8 = 0;

/// The sending side of a datagram: a descriptor, taken when `valid & ready`, then its
/// body of `body_len` beats (at least one) on `body`, the last one with `last`. A source
/// offers no body beat before its descriptor was taken.
///
/// The descriptor carries what the frame's headers need before the body goes out: the
/// datagram header's kind, flags, entry count and base tick, the body's length and the
/// sum of its big-endian 16-bit words (not folded) for the UDP checksum. The source holds
/// the descriptor from the take until its body's last beat moved: the transmitter reads
/// the kind and the header fields while the header goes out.
#[derive(LogicInterface, Default)]
#[join = "DatagramSink"]
pub struct DatagramSource {
    /// A descriptor is offered.
    pub valid: Signal<Out, Bit>,
    /// The receiver takes the descriptor.
    pub ready: Signal<In, Bit>,
    /// Datagram kind (`skinbox_protocol::DatagramKind`).
    pub kind: Signal<Out, Bits<8>>,
    /// Datagram header flags.
    pub flags: Signal<Out, Bits<8>>,
    /// Records or port counter blocks in the body.
    pub entry_count: Signal<Out, Bits<16>>,
    /// Base tick of the datagram.
    pub base_tick: Signal<Out, Bits<64>>,
    /// Body length in bytes, 1 to 2047.
    pub body_len: Signal<Out, Bits<11>>,
    /// Ones'-complement running sum of the body's big-endian 16-bit words
    /// ([`BODY_SUM_BITS`]: the last carry not yet folded in).
    pub body_sum: Signal<Out, Bits<BODY_SUM_BITS>>,
    /// The body, after the descriptor was taken.
    pub body: ByteStreamSource,
}

/// The receiving side of a datagram (see [`DatagramSource`]).
#[derive(LogicInterface, Default)]
#[join = "DatagramSource"]
pub struct DatagramSink {
    /// A descriptor is offered.
    pub valid: Signal<In, Bit>,
    /// This side takes the descriptor.
    pub ready: Signal<Out, Bit>,
    /// Datagram kind.
    pub kind: Signal<In, Bits<8>>,
    /// Datagram header flags.
    pub flags: Signal<In, Bits<8>>,
    /// Records or port counter blocks in the body.
    pub entry_count: Signal<In, Bits<16>>,
    /// Base tick of the datagram.
    pub base_tick: Signal<In, Bits<64>>,
    /// Body length in bytes.
    pub body_len: Signal<In, Bits<11>>,
    /// Ones'-complement running sum of the body's big-endian 16-bit words
    /// ([`BODY_SUM_BITS`]).
    pub body_sum: Signal<In, Bits<BODY_SUM_BITS>>,
    /// The body.
    pub body: ByteStreamSink,
}

/// A received frame's beats as the receive layers listen to them: each beat in the clock
/// it arrives, with its frame position, and one clock later registered. A listener sets
/// its position flags from the arriving beat (equality decodes of `next_index` only) and
/// takes bytes from the registered one, so no range compare sits in front of its logic.
#[derive(LogicInterface, Default)]
pub struct FrameBeats {
    /// A beat arrives this clock.
    pub next_valid: Signal<In, Bit>,
    /// Its frame position (0 outside a frame).
    pub next_index: Signal<In, Bits<11>>,
    /// A beat of the same frame came before it.
    pub in_frame: Signal<In, Bit>,
    /// The registered beat (the one that arrived last clock) is valid.
    pub beat_valid: Signal<In, Bit>,
    /// The registered beat's byte.
    pub beat_data: Signal<In, Bits<8>>,
}
