//! The skin in the robotics stack: the messages of the ROS 2 interface package
//! `ros/skinbox_msgs` serialised as CDR from the one definition in its `.msg` files
//! ([`msg`]), a [`RecordSink`](skinbox_host::RecordSink) that turns decoded datagrams into
//! those messages ([`sink`]), MCAP recordings laid out as rosbag2 writes them
//! ([`mcap_out`]) and a Foxglove WebSocket live view ([`foxglove`]). docs/ros2.md tells a
//! ROS 2 user how to build the message package, record, play and view.
//!
//! One definition: the `.msg` files are the schema text the recordings and the live view
//! carry (they are compiled in), and a test decodes what the Rust side encodes with a CDR
//! decoder driven by those files ([`msgdef`]), so a field changed on one side only fails.

#![warn(missing_docs)]

pub mod bench;
pub mod cdr;
pub mod dds;
pub mod foxglove;
pub mod mcap_out;
pub mod msg;
pub mod msgdef;
pub mod sink;
