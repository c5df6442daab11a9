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

    /// Room for `additional` more bytes.
    #[inline]
    pub fn reserve(&mut self, additional: usize) {
        self.buf.reserve(additional);
    }

    #[inline]
    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
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
}
