//! The skinbox interface box's behaviour, modelled in pure Rust: what it sends for the
//! pin transitions and host frames it receives, and when.
//!
//! [`timing`] is the contract between the gateware and every model here: each latency the
//! gateware implements, named once, with the clocks it counts from and to.

pub mod control;
pub mod downlink;
pub mod timing;
