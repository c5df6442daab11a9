//! Live ROS 2 topics over DDS (RTPS, with the pure-Rust `rustdds`), without a ROS
//! installation: the topics of [`Topic`] as ROS 2 names them on the wire (`rt/skinbox/samples`,
//! type `skinbox_msgs::msg::dds_::CellSampleBatch_` ...), the CDR payloads the sink
//! writes, sent as they are. QoS as rclcpp's default publisher: reliable, volatile, keep
//! last ([`Topic::depth`]), or best effort for the samples ([`DdsSettings`]); a slow or
//! absent subscriber never blocks the capture (a write that finds the reliable window full
//! fails at once and is counted). A datagram's samples go in messages that fit one RTPS
//! datagram unfragmented ([`MAX_UNFRAGMENTED_MESSAGE_BYTES`]). The domain is
//! `ROS_DOMAIN_ID` (0 when unset).

use crate::cdr::CDR_LE_HEADER;
use crate::sink::{Output, Topic};
use rustdds::no_key::{DataWriter, SerializerAdapter};
use rustdds::policy::{Durability, History, Reliability, ResourceLimits};
use rustdds::{DomainParticipant, QosPolicyBuilder, RepresentationIdentifier, TopicKind};
use std::io;
use std::time::{SystemTime, UNIX_EPOCH};

/// The ROS 2 domain of `ROS_DOMAIN_ID` (0 when unset); an invalid value is an error.
pub fn ros_domain_id() -> io::Result<u16> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => s
            .trim()
            .parse::<u16>()
            .ok()
            .filter(|d| *d <= 232)
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("ROS_DOMAIN_ID={s}: a domain id is 0 to 232"),
                )
            }),
    }
}

/// The DDS topic name of a ROS 2 topic: `rt` and the ROS name.
pub fn dds_topic_name(topic: Topic) -> String {
    format!("rt{}", topic.name())
}

/// The DDS type name of a topic's message: `package::msg::dds_::Name_`.
pub fn dds_type_name(topic: Topic) -> String {
    let (package, name) = topic.message().split_once('/').unwrap_or(("", ""));
    format!("{package}::msg::dds_::{name}_")
}

/// The largest message rustdds (0.15.1) sends unfragmented from a reliable writer: its
/// datagram budget without a known path MTU (1,452 bytes: a 1,500-byte MTU less the IPv4,
/// UDP and RTPS headers) less a HEARTBEAT submessage (32) and the DATA submessage's own
/// bytes (48). Larger ones go as DATA_FRAGs of 256 bytes, each tracked and repaired on its
/// own, which at 10,000 messages a second fills the reliable window.
pub const MAX_UNFRAGMENTED_MESSAGE_BYTES: usize = 1452 - 32 - 48;

/// Samples messages a reliable writer keeps unacknowledged (or unsent) before a write
/// fails: about 1.7 s of messages at 130,000 samples/s (19,000 messages/s of 7 samples on
/// average, a datagram in two parts), at most 45 MB.
pub const SAMPLES_WINDOW: usize = 32_768;

/// Settings of a [`DdsOutput`].
#[derive(Debug, Clone, Copy, Default)]
pub struct DdsSettings {
    /// The samples topic best effort (not reliable): no acknowledgements, no repairs, no
    /// window that can fill; a datagram lost on the way is lost. Status and activity stay
    /// reliable.
    pub samples_best_effort: bool,
}

/// A CDR payload after its encapsulation header (little-endian plain CDR).
pub struct CdrBody(bytes::Bytes);

/// Sends a [`CdrBody`] as it is, declared little-endian plain CDR.
pub struct RawCdr;

impl SerializerAdapter<CdrBody> for RawCdr {
    type Error = io::Error;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &CdrBody) -> Result<bytes::Bytes, io::Error> {
        Ok(value.0.clone())
    }
}

/// What a [`DdsOutput`] sent.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct DdsPublished {
    /// Messages written, per topic ([`Topic::index`]).
    pub messages: [u64; 3],
    /// Writes that failed.
    pub write_errors: u64,
    /// The first failed write's error.
    pub first_write_error: Option<String>,
    /// Time from a samples message's log time (its datagram's receive time) to the
    /// return of its write, ns: median.
    pub latency_p50_ns: Option<u64>,
    /// The same, 99th percentile.
    pub latency_p99_ns: Option<u64>,
    /// The same, most.
    pub latency_max_ns: Option<u64>,
    /// Time in the write call of a samples message (serialisation into rustdds, its
    /// history and the hand-over to its sending thread), ns: 99th percentile.
    pub write_p99_ns: Option<u64>,
}

/// Most latencies kept for the percentiles (then every later one is dropped).
const LATENCIES_KEPT: usize = 1 << 22;

/// A DDS participant publishing the topics.
pub struct DdsOutput {
    // Declared first: the writers go before the participant.
    writers: Vec<DataWriter<CdrBody, RawCdr>>,
    _participant: DomainParticipant,
    domain: u16,
    published: DdsPublished,
    latencies_ns: Vec<u64>,
    write_ns: Vec<u64>,
}

impl DdsOutput {
    /// Joins `domain` and offers the three topics.
    pub fn create(domain: u16, settings: DdsSettings) -> io::Result<DdsOutput> {
        let err = |what: &str, e: &dyn std::fmt::Debug| {
            io::Error::other(format!("DDS (domain {domain}): {what}: {e:?}"))
        };
        let participant =
            DomainParticipant::new(domain).map_err(|e| err("joining the domain", &e))?;
        let mut writers = Vec::new();
        for topic in Topic::ALL {
            let reliability = if topic == Topic::Samples && settings.samples_best_effort {
                Reliability::BestEffort
            } else {
                // Never wait: a full window fails the write at once.
                Reliability::Reliable {
                    max_blocking_time: rustdds::Duration::ZERO,
                }
            };
            let mut qos = QosPolicyBuilder::new()
                .reliability(reliability)
                .durability(Durability::Volatile)
                .history(History::KeepLast {
                    depth: topic.depth() as i32,
                });
            if topic == Topic::Samples {
                // rustdds's reliable window (and unsent backlog) is max_samples (8,192
                // unset): room for more than a second of messages at 130,000 samples/s.
                qos = qos.resource_limits(ResourceLimits {
                    max_samples: SAMPLES_WINDOW as i32,
                    max_instances: 1,
                    max_samples_per_instance: SAMPLES_WINDOW as i32,
                });
            }
            let qos = qos.build();
            let t = participant
                .create_topic(
                    dds_topic_name(topic),
                    dds_type_name(topic),
                    &qos,
                    TopicKind::NoKey,
                )
                .map_err(|e| err("creating a topic", &e))?;
            let publisher = participant
                .create_publisher(&qos)
                .map_err(|e| err("creating a publisher", &e))?;
            writers.push(
                publisher
                    .create_datawriter_no_key::<CdrBody, RawCdr>(&t, None)
                    .map_err(|e| err("creating a writer", &e))?,
            );
        }
        Ok(DdsOutput {
            writers,
            _participant: participant,
            domain,
            published: DdsPublished::default(),
            latencies_ns: Vec::new(),
            write_ns: Vec::new(),
        })
    }

    /// The domain joined.
    pub fn domain(&self) -> u16 {
        self.domain
    }

    /// What was sent so far, with the latency percentiles.
    pub fn published(&self) -> DdsPublished {
        let mut p = self.published.clone();
        let mut l = self.latencies_ns.clone();
        l.sort_unstable();
        let at = |q: f64| {
            l.get(((l.len() as f64 - 1.0) * q).round() as usize)
                .copied()
        };
        p.latency_p50_ns = at(0.5);
        p.latency_p99_ns = at(0.99);
        p.latency_max_ns = l.last().copied();
        let mut w = self.write_ns.clone();
        w.sort_unstable();
        p.write_p99_ns = w
            .get(((w.len() as f64 - 1.0) * 0.99).round() as usize)
            .copied();
        p
    }
}

impl Output for DdsOutput {
    fn max_samples_message_bytes(&self) -> Option<usize> {
        Some(MAX_UNFRAGMENTED_MESSAGE_BYTES)
    }

    fn publish(&mut self, topic: Topic, log_time_ns: u64, cdr: &[u8]) -> io::Result<()> {
        let Some(body) = cdr.strip_prefix(&CDR_LE_HEADER[..]) else {
            return Err(io::Error::other("a payload without its CDR header"));
        };
        let Some(writer) = self.writers.get(topic.index()) else {
            return Ok(());
        };
        let started = std::time::Instant::now();
        let written = writer.write(CdrBody(bytes::Bytes::copy_from_slice(body)), None);
        if topic == Topic::Samples && self.write_ns.len() < LATENCIES_KEPT {
            self.write_ns.push(started.elapsed().as_nanos() as u64);
        }
        match written {
            Ok(()) => self.published.messages[topic.index()] += 1,
            // A write refused (the history full of unacknowledged messages, a subscriber
            // gone) is counted, not fatal: the capture goes on.
            Err(e) => {
                self.published.write_errors += 1;
                if self.published.first_write_error.is_none() {
                    self.published.first_write_error = Some(e.to_string());
                }
            }
        }
        if topic == Topic::Samples && self.latencies_ns.len() < LATENCIES_KEPT {
            let now = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64);
            self.latencies_ns.push(now.saturating_sub(log_time_ns));
        }
        Ok(())
    }

    /// Waits (at most [`CLOSE_WAIT`]) until the reliable topics' matched readers have
    /// acknowledged every message, so the last ones written are not lost as the
    /// participant goes.
    fn close(&mut self) -> io::Result<()> {
        let deadline = std::time::Instant::now() + CLOSE_WAIT;
        for w in &self.writers {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            // Best effort and no readers count as acknowledged; a failure is no error.
            let _ = w.wait_for_acknowledgments(left);
        }
        Ok(())
    }
}

/// The longest [`DdsOutput`]'s close waits for acknowledgements.
pub const CLOSE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros2_names_on_the_wire() {
        assert_eq!(dds_topic_name(Topic::Samples), "rt/skinbox/samples");
        assert_eq!(
            dds_type_name(Topic::Samples),
            "skinbox_msgs::msg::dds_::CellSampleBatch_"
        );
        assert_eq!(
            dds_type_name(Topic::Activity),
            "skinbox_msgs::msg::dds_::SkinActivity_"
        );
    }
}
