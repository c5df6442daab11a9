//! The ROS 2 options of `skinbox decode` and `skinbox capture`: MCAP recordings in
//! rosbag2's layout, the topics' per-port activity (docs/ros2.md).

use clap::Args;
use skinbox_protocol::Channel;
use skinbox_ros::sink::SinkSettings;
use std::path::PathBuf;
use std::time::Duration;

/// ROS 2 message options.
#[derive(Debug, Args)]
pub struct RosArgs {
    /// Write the skinbox_msgs topics to an MCAP recording in rosbag2's layout: a bag
    /// directory (OUT/OUT_0.mcap and OUT/metadata.yaml), or one file where OUT ends in
    /// .mcap (docs/ros2.md).
    #[arg(long, value_name = "OUT")]
    pub mcap: Option<PathBuf>,
    /// Serve the topics live to Foxglove on this address (WebSocket,
    /// ws://ADDR, e.g. 127.0.0.1:8765; port 0 picks one, printed on stderr).
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<std::net::SocketAddr>,
    /// Publish the topics live over DDS as ROS 2 nodes see them (rt/skinbox/samples ...,
    /// reliable, volatile, keep last), in the domain of ROS_DOMAIN_ID (0 when unset); no
    /// ROS installation needed.
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: the samples topic best effort instead of reliable (status and
    /// activity stay reliable).
    #[arg(long, requires = "ros2")]
    pub ros2_best_effort: bool,
    /// The channel /skinbox/activity sums per port (max and mean): accel_x ... force_1 ...
    /// temperature_2.
    #[arg(long, default_value = "force_1", value_parser = parse_channel)]
    pub activity_channel: Channel,
    /// Period of the /skinbox/activity messages, ms.
    #[arg(long, default_value_t = 100)]
    pub activity_ms: u64,
}

fn parse_channel(s: &str) -> Result<Channel, String> {
    Channel::ALL
        .into_iter()
        .find(|c| c.name() == s)
        .ok_or_else(|| {
            let names: Vec<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
            format!("{s} is no channel; one of {}", names.join(", "))
        })
}

impl RosArgs {
    /// Whether any ROS 2 output is asked for.
    pub fn any(&self) -> bool {
        self.mcap.is_some() || self.foxglove.is_some() || self.ros2
    }

    /// The sink's settings.
    pub fn settings(&self) -> anyhow::Result<SinkSettings> {
        anyhow::ensure!(self.activity_ms > 0, "--activity-ms must be positive");
        Ok(SinkSettings {
            activity_period: Duration::from_millis(self.activity_ms),
            activity_channel: self.activity_channel,
        })
    }
}
