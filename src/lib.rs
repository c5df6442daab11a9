//! The library side of the `skinbox` command: the studies of `skinbox report` (speed
//! against accuracy, and the points where each method fails), with their charts.

#![warn(missing_docs)]

pub mod studies;
