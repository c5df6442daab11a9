//! MCAP recordings laid out as rosbag2's MCAP storage writes them: profile `ros2`, one
//! `ros2msg` schema per message type (the `.msg` files), one `cdr` channel per topic with
//! its `offered_qos_profiles`, message log and publish times = host times, chunks with
//! message indexes, the summary with statistics, and a `rosbag2` metadata record holding
//! the bag's metadata. Written as a bag directory (`DIR/DIR_0.mcap` and
//! `DIR/metadata.yaml`, as `ros2 bag record -s mcap -o DIR` leaves it) or a single
//! `.mcap` file.

use crate::sink::{Output, Topic};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};

/// The bag metadata version written (rosbag2 of ROS 2 Iron; later releases read it).
pub const BAG_VERSION: u32 = 8;

/// The `offered_qos_profiles` of a topic, as rosbag2 (metadata version 8) serialises
/// them: reliable, volatile, keep last `depth`, automatic liveliness, durations unset.
pub fn offered_qos_profiles(topic: Topic) -> String {
    format!(
        "- history: 1\n  depth: {}\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false",
        topic.depth()
    )
}

/// Chunk size of a recording: big enough that a chunk's record and its message index are
/// a small share, small enough for a reader to seek to a time without reading much.
pub const DEFAULT_CHUNK_BYTES: u64 = 768 * 1024;

fn mcap_error(e: mcap::McapError) -> io::Error {
    io::Error::other(e.to_string())
}

/// Messages recorded, per topic, with the span of their log times.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Recorded {
    /// Messages per topic ([`Topic::index`]).
    pub messages: [u64; 3],
    /// First log time, ns.
    pub start_ns: u64,
    /// Last log time, ns.
    pub end_ns: u64,
}

/// An MCAP recording being written.
pub struct McapOutput {
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channels: [u16; 3],
    recorded: Recorded,
    /// The bag directory, if one is written.
    bag_dir: Option<PathBuf>,
    file_name: String,
}

impl McapOutput {
    /// Creates the recording at `path`: a bag directory, or one file where `path` ends in
    /// `.mcap`. An existing bag directory is refused, as rosbag2 does. Chunks of
    /// [`DEFAULT_CHUNK_BYTES`], not compressed.
    pub fn create(path: &Path) -> io::Result<McapOutput> {
        McapOutput::create_with_chunks(path, DEFAULT_CHUNK_BYTES)
    }

    /// As [`McapOutput::create`], with chunks of `chunk_bytes` (uncompressed) at most.
    pub fn create_with_chunks(path: &Path, chunk_bytes: u64) -> io::Result<McapOutput> {
        let named = |e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
        let (file, bag_dir) = if path.extension().is_some_and(|e| e == "mcap") {
            (path.to_path_buf(), None)
        } else {
            let stem = path
                .file_name()
                .and_then(|n| n.to_str())
                .filter(|n| !n.is_empty())
                .ok_or_else(|| {
                    io::Error::new(
                        io::ErrorKind::InvalidInput,
                        format!("{}: no name for a bag directory", path.display()),
                    )
                })?;
            if path.exists() {
                return Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    format!("{}: the bag directory exists already", path.display()),
                ));
            }
            std::fs::create_dir_all(path).map_err(named)?;
            (
                path.join(format!("{stem}_0.mcap")),
                Some(path.to_path_buf()),
            )
        };
        let out = BufWriter::with_capacity(1 << 20, File::create(&file).map_err(named)?);
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!(
                "skinbox {} (rosbag2 layout)",
                env!("CARGO_PKG_VERSION")
            ))
            .compression(None)
            .chunk_size(Some(chunk_bytes.max(1)))
            .calculate_chunk_crcs(false)
            .create(out)
            .map_err(mcap_error)?;
        let mut channels = [0u16; 3];
        for topic in Topic::ALL {
            let schema = writer
                .add_schema(&topic.type_name(), "ros2msg", topic.schema().as_bytes())
                .map_err(mcap_error)?;
            let metadata = BTreeMap::from([
                (
                    "offered_qos_profiles".to_string(),
                    offered_qos_profiles(topic),
                ),
                ("topic_type_hash".to_string(), String::new()),
            ]);
            channels[topic.index()] = writer
                .add_channel(schema, topic.name(), "cdr", &metadata)
                .map_err(mcap_error)?;
        }
        Ok(McapOutput {
            writer: Some(writer),
            channels,
            recorded: Recorded::default(),
            bag_dir,
            file_name: file
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default()
                .to_string(),
        })
    }

    /// The bag's metadata as rosbag2 serialises it (`metadata.yaml`, and the `rosbag2`
    /// metadata record); JSON, which YAML readers take as YAML.
    pub fn bag_metadata(&self) -> String {
        let r = &self.recorded;
        let total: u64 = r.messages.iter().sum();
        let duration = r.end_ns.saturating_sub(r.start_ns);
        let topics: Vec<serde_json::Value> = Topic::ALL
            .iter()
            .map(|t| {
                serde_json::json!({
                    "topic_metadata": {
                        "name": t.name(),
                        "type": t.type_name(),
                        "serialization_format": "cdr",
                        "offered_qos_profiles": offered_qos_profiles(*t),
                        "type_description_hash": "",
                    },
                    "message_count": r.messages[t.index()],
                })
            })
            .collect();
        let meta = serde_json::json!({
            "rosbag2_bagfile_information": {
                "version": BAG_VERSION,
                "storage_identifier": "mcap",
                "relative_file_paths": [self.file_name],
                "duration": {"nanoseconds": duration},
                "starting_time": {"nanoseconds_since_epoch": r.start_ns},
                "message_count": total,
                "topics_with_message_count": topics,
                "compression_format": "",
                "compression_mode": "",
                "files": [{
                    "path": self.file_name,
                    "starting_time": {"nanoseconds_since_epoch": r.start_ns},
                    "duration": {"nanoseconds": duration},
                    "message_count": total,
                }],
                "custom_data": {},
                "ros_distro": "",
            }
        });
        serde_json::to_string_pretty(&meta).unwrap_or_default() + "\n"
    }

    /// Messages recorded so far.
    pub fn recorded(&self) -> Recorded {
        self.recorded
    }

    /// Writes the metadata record, the summary and the footer (and `metadata.yaml` of a
    /// bag directory); later messages are refused.
    pub fn finish(&mut self) -> io::Result<Recorded> {
        let Some(mut writer) = self.writer.take() else {
            return Ok(self.recorded);
        };
        let serialized = self.bag_metadata();
        writer
            .write_metadata(&mcap::records::Metadata {
                name: "rosbag2".into(),
                metadata: BTreeMap::from([("serialized_metadata".to_string(), serialized.clone())]),
            })
            .map_err(mcap_error)?;
        writer.finish().map_err(mcap_error)?;
        let mut out = writer.into_inner();
        io::Write::flush(&mut out)?;
        if let Some(dir) = &self.bag_dir {
            std::fs::write(dir.join("metadata.yaml"), serialized)?;
        }
        Ok(self.recorded)
    }
}

impl Output for McapOutput {
    fn publish(&mut self, topic: Topic, log_time_ns: u64, cdr: &[u8]) -> io::Result<()> {
        let r = &mut self.recorded;
        r.messages[topic.index()] += 1;
        let sequence = r.messages[topic.index()] as u32;
        if r.messages.iter().sum::<u64>() == 1 {
            r.start_ns = log_time_ns;
            r.end_ns = log_time_ns;
        }
        r.start_ns = r.start_ns.min(log_time_ns);
        r.end_ns = r.end_ns.max(log_time_ns);
        let Some(writer) = &mut self.writer else {
            return Err(io::Error::other("the recording is finished"));
        };
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: self.channels[topic.index()],
                    sequence,
                    log_time: log_time_ns,
                    publish_time: log_time_ns,
                },
                cdr,
            )
            .map_err(mcap_error)
    }

    fn close(&mut self) -> io::Result<()> {
        self.finish().map(|_| ())
    }
}
