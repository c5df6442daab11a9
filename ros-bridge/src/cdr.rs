//! A little-endian CDR (XCDR1, the encoding of ROS 2 messages) writer: the 4-byte
//! encapsulation header, then each primitive aligned to its size from the end of the
//! header.

/// The encapsulation header of a little-endian plain CDR payload.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Writes one CDR payload into a reused buffer.
#[derive(Debug, Default, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    /// An empty writer.
    pub fn new() -> Self {
        CdrWriter::default()
    }

    /// Starts a new payload: the buffer cleared, the encapsulation header written.
    #[inline]
    pub fn start(&mut self) {
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
    }

    /// The payload so far.
    #[inline]
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    /// Bytes written so far, the header included.
    #[inline]
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Whether nothing is written (not even the header).
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// Back to the first `len` bytes (a mark taken with [`CdrWriter::len`]), to write
    /// another ending after the same start.
    #[inline]
    pub fn truncate(&mut self, len: usize) {
        self.buf.truncate(len);
    }

    /// Room for `additional` more bytes.
    #[inline]
    pub fn reserve(&mut self, additional: usize) {
        self.buf.reserve(additional);
    }

    #[inline(always)]
    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - pos % n) % n;
        self.buf.extend_from_slice(&[0; 8][..pad]);
    }

    /// Writes a run of primitives of at most `N` bytes (with their padding) through a
    /// [`CdrBlock`]: on the stack, aligned as they land in the payload, then appended at
    /// once, much faster than field by field.
    ///
    /// `f` writing more than `N` bytes panics: `N` is the most the caller's fixed-size
    /// message takes.
    #[inline(always)]
    pub fn block<const N: usize>(&mut self, f: impl FnOnce(&mut CdrBlock<N>)) {
        // The padding depends only on where the block starts, modulo 8: a copy of `f` for
        // each, in which every field's offset is a constant.
        match (self.buf.len() - CDR_LE_HEADER.len()) % 8 {
            0 => self.block_at(0, f),
            1 => self.block_at(1, f),
            2 => self.block_at(2, f),
            3 => self.block_at(3, f),
            4 => self.block_at(4, f),
            5 => self.block_at(5, f),
            6 => self.block_at(6, f),
            _ => self.block_at(7, f),
        }
    }

    #[inline(always)]
    fn block_at<const N: usize>(&mut self, base: usize, f: impl FnOnce(&mut CdrBlock<N>)) {
        let mut b = CdrBlock {
            bytes: [0; N],
            pos: 0,
            base,
        };
        f(&mut b);
        self.buf.extend_from_slice(&b.bytes[..b.pos]);
    }

    /// A `uint8`.
    #[inline]
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// A `bool`.
    #[inline]
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// A `uint16`.
    #[inline]
    pub fn u16(&mut self, v: u16) {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `uint32`.
    #[inline]
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// An `int32`.
    #[inline]
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `uint64`.
    #[inline]
    pub fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// An `int64`.
    #[inline]
    pub fn i64(&mut self, v: i64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    #[inline]
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A fixed-size `float64[N]` (no length).
    #[inline]
    pub fn f64_array(&mut self, v: &[f64]) {
        self.align(8);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }

    /// A `string`: length with the terminating NUL, the bytes, the NUL.
    #[inline]
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// The length of an unbounded sequence; its elements follow.
    #[inline]
    pub fn sequence_len(&mut self, n: usize) {
        self.u32(n as u32);
    }
}

/// A run of primitives being written by [`CdrWriter::block`].
#[derive(Debug)]
pub struct CdrBlock<const N: usize> {
    bytes: [u8; N],
    pos: usize,
    /// Offset of `bytes[0]` from the end of the encapsulation header, modulo 8.
    base: usize,
}

impl<const N: usize> CdrBlock<N> {
    #[inline(always)]
    fn put<const M: usize>(&mut self, v: [u8; M]) {
        // Padding is left zero: the block starts zeroed.
        self.pos += (M - (self.base + self.pos) % M) % M;
        self.bytes[self.pos..self.pos + M].copy_from_slice(&v);
        self.pos += M;
    }

    /// A `uint8`.
    #[inline(always)]
    pub fn u8(&mut self, v: u8) {
        self.put([v]);
    }

    /// A `bool`.
    #[inline(always)]
    pub fn bool(&mut self, v: bool) {
        self.put([u8::from(v)]);
    }

    /// A `uint16`.
    #[inline(always)]
    pub fn u16(&mut self, v: u16) {
        self.put(v.to_le_bytes());
    }

    /// A `uint32`.
    #[inline(always)]
    pub fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }

    /// An `int32`.
    #[inline(always)]
    pub fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes());
    }

    /// A `uint64`.
    #[inline(always)]
    pub fn u64(&mut self, v: u64) {
        self.put(v.to_le_bytes());
    }

    /// An `int64`.
    #[inline(always)]
    pub fn i64(&mut self, v: i64) {
        self.put(v.to_le_bytes());
    }

    /// A `float64`.
    #[inline(always)]
    pub fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes());
    }

    /// A fixed-size `float64[K]` (no length).
    #[inline(always)]
    pub fn f64_array(&mut self, v: &[f64]) {
        for x in v {
            self.put(x.to_le_bytes());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligns_from_the_end_of_the_header() {
        let mut w = CdrWriter::new();
        w.start();
        w.u8(1);
        w.u16(2);
        w.u8(3);
        w.f64(0.5);
        w.string("ab");
        assert_eq!(
            w.bytes(),
            &[
                0, 1, 0, 0, // header
                1, 0, 2, 0, 3, 0, 0, 0, // u8, pad, u16, u8, pad to 8
                0, 0, 0, 0, 0, 0, 0xE0, 0x3F, // 0.5
                3, 0, 0, 0, b'a', b'b', 0
            ][..]
        );
    }

    #[test]
    fn a_block_writes_what_the_fields_write() {
        for lead in 0..8 {
            let mut a = CdrWriter::new();
            let mut b = CdrWriter::new();
            for w in [&mut a, &mut b] {
                w.start();
                (0..lead).for_each(|i| w.u8(i));
            }
            a.u16(2);
            a.u8(3);
            a.f64_array(&[0.5, -1.0]);
            a.i32(-4);
            a.bool(true);
            a.u64(5);
            a.u32(6);
            a.i64(-7);
            a.f64(8.0);
            b.block::<96>(|b| {
                b.u16(2);
                b.u8(3);
                b.f64_array(&[0.5, -1.0]);
                b.i32(-4);
                b.bool(true);
                b.u64(5);
                b.u32(6);
                b.i64(-7);
                b.f64(8.0);
            });
            assert_eq!(a.bytes(), b.bytes(), "{lead} bytes before");
        }
    }
}
