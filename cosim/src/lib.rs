//! Verilator co-simulation of the skinbox interface box.
//!
//! [`model::Model::build`] turns a [`BoxConfig`] into a verilated, compiled and loaded
//! model: the gateware crate writes the Verilog, Verilator 5 (`--cc -O3`) translates it, the
//! C++ compiler builds it with a small generated `extern "C"` shim into a shared library in
//! a cache directory, and the library is loaded. Verilator's runtime is compiled once per
//! Verilator version and shared by every model. A design that was built before is loaded
//! from the cache in milliseconds.
//!
//! [`dut::Dut`] is the safe handle to one instance: set UART pins and reset, run clock
//! cycles, receive the GMII bytes.
//!
//! [`harness`] plays pin lines ([`line`](mod@line)) into it; [`run`] and [`sim`] run a
//! spec on the RTL or on the reference model and check every frame with
//! `skinbox_frame_check`; [`closed_loop`] runs a scene whose cells hear the box's transmit
//! pins. The box's behaviour models (reference, control, downlink,
//! emulator core) and their timing contract with the gateware are the `skinbox_model`
//! crate's; [`reference`](mod@reference) runs its reference model on a spec.
//!
//! [`BoxConfig`]: skinbox_gateware::interface_box::BoxConfig

pub mod bench;
mod binding;
pub mod cache_lock;
pub mod closed_loop;
pub mod dut;
pub mod error;
pub mod frames;
pub mod harness;
pub mod line;
pub mod model;
pub mod reference;
pub mod run;
pub mod scene;
pub mod sim;
pub mod synthetic;
pub mod traffic;

pub use dut::{Dut, GmiiByte, UartTxEdge};
pub use error::CosimError;
pub use model::Model;
