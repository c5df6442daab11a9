//! The one stream interface between blocks: bytes with valid, ready and last.
//!
//! A beat moves when `valid & ready` at a rising clock edge. `last` marks the final beat of
//! a packet; `error` is meaningful on the `last` beat only and marks the whole packet as
//! bad, so a receiver that stores packets can discard it. A source never interleaves two
//! packets and never takes `valid` back before the beat moved.

use crate::hdl::*;

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
