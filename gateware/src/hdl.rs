//! The parts of rust-hdl 0.46 the gateware uses: the core (signals, blocks, kernels,
//! simulation, Verilog generation) and the `DFF` widget. The `rust-hdl` crate would also
//! build its HLS, bus-model and documentation crates, which nothing here uses.

pub use rust_hdl_core::prelude::*;
pub use rust_hdl_widgets::prelude::{dff_setup, DFF};

/// `n` default values: the per-port and per-group parts of a block.
pub fn each<T: Default>(n: usize) -> Vec<T> {
    (0..n).map(|_| T::default()).collect()
}
