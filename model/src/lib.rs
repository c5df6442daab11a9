//! The skinbox interface box's behaviour, modelled in pure Rust: what it sends for the
//! pin transitions and host frames it receives, and when, byte for byte and clock for clock
//! as the gateware does (the co-simulation's tests hold every model to the RTL).
//!
//! - [`reference`](mod@reference): the uplink, cell packets on the UART pins to datagrams on GMII, and
//!   the receive path playing [`control`] at the gateware's clocks.
//! - [`control`]: what the box does with every frame it receives (ARP, ping, commands,
//!   counters).
//! - [`downlink`]: the cell commands on the UART transmit pins; [`cell_uart`]: the cells'
//!   UART receivers that decode them from the pins.
//! - [`emulator`]: the uplink and control models played together in time slices, free of
//!   I/O, for a box emulated on a UDP socket.
//! - [`timing`]: the contract between the gateware and every model here, each latency the
//!   gateware implements, named once with the clocks it counts from and to.
//! - [`frame`], [`pins`], [`inputs`]: what the models take and give.
//!
//! The crate depends on the protocol crate (the formats) and the gateware crate (the box's
//! configuration, and its constants, which [`timing`]'s tests compare); not on the
//! co-simulation, the host client or the independent frame checker.

pub mod cell_uart;
pub mod control;
pub mod downlink;
pub mod emulator;
pub mod frame;
pub mod inputs;
pub mod pins;
pub mod reference;
pub mod timing;
