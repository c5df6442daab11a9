//! The parts of rust-hdl 0.46 the gateware uses: the core (signals, blocks, kernels,
//! simulation, Verilog generation) and the `DFF` widget. The `rust-hdl` crate would also
//! build its HLS, bus-model and documentation crates, which nothing here uses. Beside
//! them, the helpers every block's constructor uses.

pub use rust_hdl_core::prelude::*;
pub use rust_hdl_widgets::prelude::{dff_setup, DFF};

/// `n` default values: the per-port and per-group parts of a block.
pub fn each<T: Default>(n: usize) -> Vec<T> {
    (0..n).map(|_| T::default()).collect()
}

/// `value` as an N-bit kernel constant; panics when it does not fit N bits.
pub fn constant<const N: usize>(value: u64) -> Constant<Bits<N>> {
    assert!(N >= 64 || value < 1 << N, "{value} does not fit {N} bits");
    Constant::new(value.into())
}

/// The number whose big-endian bytes these are (at most 8): a MAC or IP address, a port or
/// a byte string as one kernel value.
pub fn big_endian(bytes: &[u8]) -> u64 {
    assert!(bytes.len() <= 8, "{} bytes do not fit 64 bits", bytes.len());
    bytes.iter().fold(0, |n, &b| n << 8 | u64::from(b))
}
