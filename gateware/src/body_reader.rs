//! BodyReader: streams a datagram body out of a block RAM.
//!
//! On `start` it takes `length` (a clock later, so `start` drives two flip-flops and
//! nothing else: `length` must hold from `start`'s clock to the next; its tests for 0
//! and 1 are registered from `start`'s clock, so no path runs from the owner's length
//! through them) and reads the RAM from address 0 on, one read per clock
//! while its [`StreamFifo`] has room for every read in flight (a read takes
//! [`READ_LATENCY`] clocks), so the body stream's `ready` reaches the FIFO only and a
//! consumer that takes one beat per clock is never starved once the first beats arrived
//! (four clocks after `start`). `busy` holds from the clock after `start` until the last
//! beat was taken: the owner may write the RAM again when it falls. It is a register (set
//! by `start`, cleared by the last beat), so an owner's decisions on it start at a
//! flip-flop.

use crate::block_ram::READ_LATENCY;
use crate::hdl::*;
use crate::stream::ByteStreamSource;
use crate::stream_fifo::{StreamFifo, FIFO_DEPTH};

/// Address bits of a body (2 KB).
pub const BODY_ADDRESS_BITS: usize = 11;

// The read pipeline below is two registers deep.
const _: () = assert!(READ_LATENCY == 2);

/// Reads `length` bytes of a RAM into a byte stream.
#[derive(LogicBlock)]
pub struct BodyReader {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: stops reading and empties the FIFO.
    pub reset: Signal<In, Bit>,
    /// Take `length` and read the body (only while not `busy`).
    pub start: Signal<In, Bit>,
    /// Body length in bytes, 1 to 2047.
    pub length: Signal<In, Bits<BODY_ADDRESS_BITS>>,
    /// The RAM's read address.
    pub read_address: Signal<Out, Bits<BODY_ADDRESS_BITS>>,
    /// The RAM's read data, [`READ_LATENCY`] clocks after the address.
    pub read_data: Signal<In, Bits<8>>,
    /// The body.
    pub body: ByteStreamSource,
    /// A body is being read or has beats not yet taken.
    pub busy: Signal<Out, Bit>,
    fifo: StreamFifo,
    reading: DFF<Bit>,
    // `start` a clock ago: the reads begin
    starting: DFF<Bit>,
    fifo_depth: Constant<Bits<3>>,
    address: DFF<Bits<BODY_ADDRESS_BITS>>,
    // reads still to issue, and whether that is not 0 or is 1, as registers of their own
    // (the issue test and the last-read flag start at flip-flops)
    left: DFF<Bits<BODY_ADDRESS_BITS>>,
    left_nonzero: DFF<Bit>,
    left_one: DFF<Bit>,
    // `length` a clock ago was not 0, was 1
    length_nonzero: DFF<Bit>,
    length_one: DFF<Bit>,
    // reads in flight, and whether each is the body's last byte
    read_1: DFF<Bit>,
    read_1_last: DFF<Bit>,
    read_2: DFF<Bit>,
    read_2_last: DFF<Bit>,
    issue: Signal<Local, Bit>,
}

impl Default for BodyReader {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            start: Default::default(),
            length: Default::default(),
            read_address: Default::default(),
            read_data: Default::default(),
            body: Default::default(),
            busy: Default::default(),
            fifo: Default::default(),
            reading: Default::default(),
            starting: Default::default(),
            fifo_depth: Constant::new((FIFO_DEPTH as u64).into()),
            address: Default::default(),
            left: Default::default(),
            left_nonzero: Default::default(),
            left_one: Default::default(),
            length_nonzero: Default::default(),
            length_one: Default::default(),
            read_1: Default::default(),
            read_1_last: Default::default(),
            read_2: Default::default(),
            read_2_last: Default::default(),
            issue: Default::default(),
        }
    }
}

impl Logic for BodyReader {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            address,
            left,
            left_nonzero,
            left_one,
            length_nonzero,
            length_one,
            read_1,
            read_1_last,
            read_2,
            read_2_last,
            reading,
            starting
        );
        self.fifo.clock.next = self.clock.val();
        self.fifo.reset.next = self.reset.val();
        self.issue.next = self.left_nonzero.q.val()
            & ((bit_cast::<3, 1>(self.read_1.q.val().into())
                + bit_cast::<3, 1>(self.read_2.q.val().into())
                + self.fifo.count.val())
                < self.fifo_depth.val());
        self.read_address.next = self.address.q.val();
        if self.issue.val() {
            self.address.d.next = self.address.q.val() + 1;
            self.left.d.next = self.left.q.val() - 1;
            self.left_nonzero.d.next = !self.left_one.q.val();
            self.left_one.d.next = self.left.q.val() == 2;
        }
        self.starting.d.next = self.start.val();
        self.length_nonzero.d.next = self.length.val() != 0;
        self.length_one.d.next = self.length.val() == 1;
        if self.starting.q.val() {
            self.address.d.next = 0.into();
            self.left.d.next = self.length.val();
            self.left_nonzero.d.next = self.length_nonzero.q.val();
            self.left_one.d.next = self.length_one.q.val();
        }
        self.read_1.d.next = self.issue.val();
        self.read_1_last.d.next = self.left_one.q.val();
        self.read_2.d.next = self.read_1.q.val();
        self.read_2_last.d.next = self.read_1_last.q.val();
        // the FIFO has room for every read in flight: the push never waits
        self.fifo.beats_in.valid.next = self.read_2.q.val();
        self.fifo.beats_in.data.next = self.read_data.val();
        self.fifo.beats_in.last.next = self.read_2_last.q.val();
        self.fifo.beats_in.error.next = false;
        self.body.valid.next = self.fifo.beats_out.valid.val();
        self.body.data.next = self.fifo.beats_out.data.val();
        self.body.last.next = self.fifo.beats_out.last.val();
        self.body.error.next = false;
        self.fifo.beats_out.ready.next = self.body.ready.val();
        // from `start` to the clock after the last beat moved
        self.busy.next = self.reading.q.val();
        if self.fifo.beats_out.valid.val() & self.fifo.beats_out.last.val() & self.body.ready.val()
        {
            self.reading.d.next = false;
            self.starting.d.next = false;
        }
        if self.start.val() {
            self.reading.d.next = true;
        }
        if self.reset.val() {
            self.reading.d.next = false;
            self.starting.d.next = false;
            self.left.d.next = 0.into();
            self.left_nonzero.d.next = false;
            self.left_one.d.next = false;
            self.read_1.d.next = false;
            self.read_2.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Reads bodies of every small length and some long ones from a RAM model with the
    /// block RAM's latency, under random backpressure: each body comes out whole, in order,
    /// `last` on its final byte only, `busy` until it was taken, nothing left over.
    #[test]
    fn bodies_of_every_small_length_stream_whole_under_backpressure() {
        let ram: Vec<u8> = (0..2048u32).map(|a| (a * 7 + a / 256) as u8).collect();
        let mut lengths: Vec<usize> = (1..=40).collect();
        lengths.extend([255, 256, 1454, 2047]);
        for (k, take_p) in [1.0, 0.6, 0.15].into_iter().enumerate() {
            let mut rng = TestRng::new(k as u64 + 10);
            let mut bench = Bench::new(BodyReader::default(), |b| &mut b.clock);
            bench.uut.reset.next = true;
            bench.cycle();
            bench.uut.reset.next = false;
            let mut addresses = [0usize; 2];
            for &len in &lengths {
                // wait a random idle time, then start
                for _ in 0..rng.next_u64() % 4 {
                    bench.cycle();
                }
                bench.uut.start.next = true;
                bench.uut.length.next = (len as u64).into();
                bench.cycle();
                bench.uut.start.next = false;
                let mut got = vec![];
                let mut clocks = 0;
                loop {
                    let take = rng.chance(take_p);
                    let u = &mut bench.uut;
                    u.read_data.next = u64::from(ram[addresses[0]]).into();
                    u.body.ready.next = take;
                    bench.settle();
                    let u = &bench.uut;
                    let done = got.len() == len;
                    assert_eq!(u.busy.val(), !done, "length {len}, {} taken", got.len());
                    if done {
                        break;
                    }
                    if take && u.body.valid.val() {
                        got.push(u.body.data.val().to_u8());
                        assert_eq!(u.body.last.val(), got.len() == len, "length {len}");
                    }
                    addresses = [addresses[1], u.read_address.val().index()];
                    bench.cycle();
                    clocks += 1;
                    assert!(clocks < 40 * len + 100, "stalled at {}", got.len());
                }
                assert_eq!(got, ram[..len], "length {len}");
                if take_p == 1.0 {
                    // four clocks to the first beat, then one per clock
                    assert_eq!(clocks, len + 4, "length {len}");
                }
            }
        }
    }
}
