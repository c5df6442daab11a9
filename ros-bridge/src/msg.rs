//! The messages of `ros/skinbox_msgs` as Rust values, each written as CDR by hand in the
//! order of its `.msg` file (fast: one pass, no reflection). [`RosMessage::fields`] says
//! what each value holds by the field names of the `.msg` file; the one-definition test
//! (`tests/one_definition.rs`) decodes [`RosMessage::encode`]'s bytes with
//! [`crate::msgdef::decode`] and checks they say the same, so a field added, removed,
//! retyped or moved on either side fails it.

use crate::cdr::CdrWriter;
use crate::msgdef::Value;
use skinbox_host::rows::RecordRow;
use skinbox_protocol::status::{PortCounter, PortCounters as WirePortCounters};
use skinbox_protocol::Channel;

/// A message of `skinbox_msgs`.
pub trait RosMessage {
    /// Its `package/Name` (the key of [`crate::msgdef::DEFINITIONS`]).
    const NAME: &'static str;

    /// Its fields as CDR, after the encapsulation header.
    fn encode_fields(&self, w: &mut CdrWriter);

    /// What each field holds, by the `.msg` file's names, in its order.
    fn fields(&self) -> Vec<(String, Value)>;

    /// The whole CDR payload into `w` (started anew).
    fn encode(&self, w: &mut CdrWriter) {
        w.start();
        self.encode_fields(w);
    }

    /// The ROS 2 type name, `package/msg/Name`.
    fn type_name() -> String {
        Self::NAME.replacen('/', "/msg/", 1)
    }
}

fn f(name: &str, v: Value) -> (String, Value) {
    (name.to_string(), v)
}

fn message<M: RosMessage>(m: &M) -> Value {
    Value::Message(m.fields())
}

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds in the second.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch (seconds saturate at `i32::MAX`).
    pub fn from_ns(ns: u64) -> Time {
        Time {
            sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

impl RosMessage for Time {
    const NAME: &'static str = "builtin_interfaces/Time";

    fn encode_fields(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("sec", Value::I32(self.sec)),
            f("nanosec", Value::U32(self.nanosec)),
        ]
    }
}

/// `skinbox_msgs/CellSample`: one cell packet with its times.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CellSample {
    /// The box.
    pub box_id: u16,
    /// Its UART port.
    pub port: u8,
    /// The cell.
    pub cell_id: u16,
    /// `KIND_DATA` or `KIND_EVENT` ([`skinbox_host::rows::KIND_DATA`]).
    pub kind: u8,
    /// Channels present in `values`.
    pub event_mask: u16,
    /// The nine channels in physical units (NaN where absent).
    pub values: [f64; Channel::COUNT],
    /// Event sequence number (-1 for data).
    pub event_sequence: i32,
    /// The second packet of a split event sample.
    pub second_part: bool,
    /// Event packets of the cell missing just before.
    pub event_packets_missing_before: u16,
    /// Record flags.
    pub flags: u8,
    /// Sequence number of its datagram.
    pub datagram_sequence: u32,
    /// Box time of its first start bit, ns.
    pub box_time_ns: u64,
    /// Estimated box time of its sample, ns.
    pub sample_box_time_ns: f64,
    /// Host time of its sample, ns since the epoch (0: none).
    pub host_time_ns: i64,
    /// Error bound of the host time, ns (NaN: none).
    pub host_time_bound_ns: f64,
    /// Source of the host time ([`skinbox_host::rows::HOST_TIME_NONE`] ...).
    pub host_time_source: u8,
}

impl From<&RecordRow> for CellSample {
    fn from(r: &RecordRow) -> CellSample {
        CellSample {
            box_id: r.box_id,
            port: r.port,
            cell_id: r.cell_id,
            kind: r.kind,
            event_mask: r.mask,
            values: r.values,
            event_sequence: r.event_sequence,
            second_part: r.second_part != 0,
            event_packets_missing_before: r.event_packets_missing_before,
            flags: r.flags,
            datagram_sequence: r.datagram_sequence,
            box_time_ns: r.box_time_ns,
            sample_box_time_ns: r.sample_box_time_ns,
            host_time_ns: r.host_time_ns,
            host_time_bound_ns: r.host_time_bound_ns,
            host_time_source: r.host_time_source,
        }
    }
}

impl RosMessage for CellSample {
    const NAME: &'static str = "skinbox_msgs/CellSample";

    #[inline]
    fn encode_fields(&self, w: &mut CdrWriter) {
        w.block::<CELL_SAMPLE_MAX_BYTES>(
            #[inline(always)]
            |w| {
                w.u16(self.box_id);
                w.u8(self.port);
                w.u16(self.cell_id);
                w.u8(self.kind);
                w.u16(self.event_mask);
                w.f64_array(&self.values);
                w.i32(self.event_sequence);
                w.bool(self.second_part);
                w.u16(self.event_packets_missing_before);
                w.u8(self.flags);
                w.u32(self.datagram_sequence);
                w.u64(self.box_time_ns);
                w.f64(self.sample_box_time_ns);
                w.i64(self.host_time_ns);
                w.f64(self.host_time_bound_ns);
                w.u8(self.host_time_source);
            },
        );
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("box_id", Value::U16(self.box_id)),
            f("port", Value::U8(self.port)),
            f("cell_id", Value::U16(self.cell_id)),
            f("kind", Value::U8(self.kind)),
            f("event_mask", Value::U16(self.event_mask)),
            f(
                "values",
                Value::Array(self.values.iter().map(|v| Value::F64(*v)).collect()),
            ),
            f("event_sequence", Value::I32(self.event_sequence)),
            f("second_part", Value::Bool(self.second_part)),
            f(
                "event_packets_missing_before",
                Value::U16(self.event_packets_missing_before),
            ),
            f("flags", Value::U8(self.flags)),
            f("datagram_sequence", Value::U32(self.datagram_sequence)),
            f("box_time_ns", Value::U64(self.box_time_ns)),
            f("sample_box_time_ns", Value::F64(self.sample_box_time_ns)),
            f("host_time_ns", Value::I64(self.host_time_ns)),
            f("host_time_bound_ns", Value::F64(self.host_time_bound_ns)),
            f("host_time_source", Value::U8(self.host_time_source)),
        ]
    }
}

/// `skinbox_msgs/CellSampleBatch`: the samples of one datagram.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CellSampleBatch {
    /// Host receive time of the datagram.
    pub stamp: Time,
    /// The box.
    pub box_id: u16,
    /// Its source address (empty: unknown).
    pub box_address: String,
    /// The datagram's sequence number.
    pub datagram_sequence: u32,
    /// Its records.
    pub samples: Vec<CellSample>,
}

/// Bytes of one [`CellSample`] in CDR at most, with its padding (131 to 138 bytes by
/// where it starts, rounded up to 8).
pub const CELL_SAMPLE_MAX_BYTES: usize = 144;

impl CellSampleBatch {
    /// The fields before `samples` into `w`, started anew (the encapsulation header
    /// first): with [`CellSampleBatch::encode_samples`], a message with a part of the
    /// samples, written once for every part.
    pub fn encode_header(&self, w: &mut CdrWriter) {
        w.start();
        self.stamp.encode_fields(w);
        w.u16(self.box_id);
        w.string(&self.box_address);
        w.u32(self.datagram_sequence);
    }

    /// `samples` (all of the batch's or a run of them) after
    /// [`CellSampleBatch::encode_header`]: the message is this batch with those samples.
    pub fn encode_samples(&self, w: &mut CdrWriter, samples: &[CellSample]) {
        w.sequence_len(samples.len());
        w.reserve(samples.len() * CELL_SAMPLE_MAX_BYTES);
        for s in samples {
            s.encode_fields(w);
        }
    }
}

impl RosMessage for CellSampleBatch {
    const NAME: &'static str = "skinbox_msgs/CellSampleBatch";

    fn encode(&self, w: &mut CdrWriter) {
        self.encode_header(w);
        self.encode_samples(w, &self.samples);
    }

    fn encode_fields(&self, w: &mut CdrWriter) {
        self.encode_header(w);
        self.encode_samples(w, &self.samples);
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("stamp", message(&self.stamp)),
            f("box_id", Value::U16(self.box_id)),
            f("box_address", Value::String(self.box_address.clone())),
            f("datagram_sequence", Value::U32(self.datagram_sequence)),
            f(
                "samples",
                Value::Array(self.samples.iter().map(message).collect()),
            ),
        ]
    }
}

/// `skinbox_msgs/PortCounters`: one port's counters, in the wire order of
/// [`PortCounter::ALL`] (their names are the `.msg` file's field names).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PortCounters {
    /// The port.
    pub port: u8,
    /// Its counters.
    pub counters: WirePortCounters,
}

impl RosMessage for PortCounters {
    const NAME: &'static str = "skinbox_msgs/PortCounters";

    fn encode_fields(&self, w: &mut CdrWriter) {
        w.u8(self.port);
        for c in PortCounter::ALL {
            w.u32(self.counters.get(c));
        }
    }

    fn fields(&self) -> Vec<(String, Value)> {
        let mut v = vec![f("port", Value::U8(self.port))];
        v.extend(
            PortCounter::ALL
                .iter()
                .map(|c| f(c.name(), Value::U32(self.counters.get(*c)))),
        );
        v
    }
}

/// `skinbox_msgs/BoxStatus`: a box's report, the host's losses and the time mapping.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BoxStatus {
    /// Host receive time of the status datagram.
    pub stamp: Time,
    /// The box.
    pub box_id: u16,
    /// Its source address.
    pub box_address: String,
    /// Changes at every reset of the box.
    pub boot_id: u32,
    /// The PHY reports the link up.
    pub link_up: bool,
    /// The link speed code (`LINK_SPEED_*`).
    pub link_speed: u8,
    /// Records datagrams sent since reset.
    pub datagrams_sent: u32,
    /// Records sent since reset.
    pub records_sent: u32,
    /// The ports' counters.
    pub ports: Vec<PortCounters>,
    /// Records datagrams the host received from the box.
    pub datagrams_received: u64,
    /// Datagrams missing (gaps in the sequence numbers records and status datagrams share).
    pub datagrams_missing: u64,
    /// Records received.
    pub records_received: u64,
    /// Event packets missing (event sequence gaps).
    pub event_packets_missing: u64,
    /// Records the box flagged: packets lost on their port just before.
    pub records_flagged_loss_before: u64,
    /// Source of the host times (`CellSample.HOST_TIME_*`).
    pub host_time_source: u8,
    /// The box clock's drift against the host's, ppm (NaN: not measured).
    pub drift_ppm: f64,
    /// Error bound of the mapping at its last exchange, ns (NaN: none).
    pub time_error_bound_ns: f64,
    /// Times the mapping started over.
    pub time_map_restarts: u64,
}

impl RosMessage for BoxStatus {
    const NAME: &'static str = "skinbox_msgs/BoxStatus";

    fn encode_fields(&self, w: &mut CdrWriter) {
        self.stamp.encode_fields(w);
        w.u16(self.box_id);
        w.string(&self.box_address);
        w.u32(self.boot_id);
        w.bool(self.link_up);
        w.u8(self.link_speed);
        w.u32(self.datagrams_sent);
        w.u32(self.records_sent);
        w.sequence_len(self.ports.len());
        for p in &self.ports {
            p.encode_fields(w);
        }
        w.u64(self.datagrams_received);
        w.u64(self.datagrams_missing);
        w.u64(self.records_received);
        w.u64(self.event_packets_missing);
        w.u64(self.records_flagged_loss_before);
        w.u8(self.host_time_source);
        w.f64(self.drift_ppm);
        w.f64(self.time_error_bound_ns);
        w.u64(self.time_map_restarts);
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("stamp", message(&self.stamp)),
            f("box_id", Value::U16(self.box_id)),
            f("box_address", Value::String(self.box_address.clone())),
            f("boot_id", Value::U32(self.boot_id)),
            f("link_up", Value::Bool(self.link_up)),
            f("link_speed", Value::U8(self.link_speed)),
            f("datagrams_sent", Value::U32(self.datagrams_sent)),
            f("records_sent", Value::U32(self.records_sent)),
            f(
                "ports",
                Value::Array(self.ports.iter().map(message).collect()),
            ),
            f("datagrams_received", Value::U64(self.datagrams_received)),
            f("datagrams_missing", Value::U64(self.datagrams_missing)),
            f("records_received", Value::U64(self.records_received)),
            f(
                "event_packets_missing",
                Value::U64(self.event_packets_missing),
            ),
            f(
                "records_flagged_loss_before",
                Value::U64(self.records_flagged_loss_before),
            ),
            f("host_time_source", Value::U8(self.host_time_source)),
            f("drift_ppm", Value::F64(self.drift_ppm)),
            f("time_error_bound_ns", Value::F64(self.time_error_bound_ns)),
            f("time_map_restarts", Value::U64(self.time_map_restarts)),
        ]
    }
}

/// `skinbox_msgs/PortActivity`: one port over a period.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PortActivity {
    /// The port.
    pub port: u8,
    /// Cell packets per second.
    pub packets_per_s: f64,
    /// Events (channels carried by event packets) per second.
    pub events_per_s: f64,
    /// Cells that sent in the period.
    pub cells_active: u16,
    /// Highest value of the chosen channel (NaN: none).
    pub channel_max: f64,
    /// Mean value of the chosen channel (NaN: none).
    pub channel_mean: f64,
}

impl RosMessage for PortActivity {
    const NAME: &'static str = "skinbox_msgs/PortActivity";

    fn encode_fields(&self, w: &mut CdrWriter) {
        w.u8(self.port);
        w.f64(self.packets_per_s);
        w.f64(self.events_per_s);
        w.u16(self.cells_active);
        w.f64(self.channel_max);
        w.f64(self.channel_mean);
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("port", Value::U8(self.port)),
            f("packets_per_s", Value::F64(self.packets_per_s)),
            f("events_per_s", Value::F64(self.events_per_s)),
            f("cells_active", Value::U16(self.cells_active)),
            f("channel_max", Value::F64(self.channel_max)),
            f("channel_mean", Value::F64(self.channel_mean)),
        ]
    }
}

/// `skinbox_msgs/SkinActivity`: a box's ports over one period.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SkinActivity {
    /// Host time of the period's end.
    pub stamp: Time,
    /// The box.
    pub box_id: u16,
    /// The period, s.
    pub period_s: f64,
    /// The chosen channel's index.
    pub channel: u8,
    /// Its name.
    pub channel_name: String,
    /// Every port that sent in the period, or had before.
    pub ports: Vec<PortActivity>,
    /// Datagrams missing in the period.
    pub datagrams_missing: u64,
    /// Event packets missing in the period.
    pub event_packets_missing: u64,
}

impl RosMessage for SkinActivity {
    const NAME: &'static str = "skinbox_msgs/SkinActivity";

    fn encode_fields(&self, w: &mut CdrWriter) {
        self.stamp.encode_fields(w);
        w.u16(self.box_id);
        w.f64(self.period_s);
        w.u8(self.channel);
        w.string(&self.channel_name);
        w.sequence_len(self.ports.len());
        for p in &self.ports {
            p.encode_fields(w);
        }
        w.u64(self.datagrams_missing);
        w.u64(self.event_packets_missing);
    }

    fn fields(&self) -> Vec<(String, Value)> {
        vec![
            f("stamp", message(&self.stamp)),
            f("box_id", Value::U16(self.box_id)),
            f("period_s", Value::F64(self.period_s)),
            f("channel", Value::U8(self.channel)),
            f("channel_name", Value::String(self.channel_name.clone())),
            f(
                "ports",
                Value::Array(self.ports.iter().map(message).collect()),
            ),
            f("datagrams_missing", Value::U64(self.datagrams_missing)),
            f(
                "event_packets_missing",
                Value::U64(self.event_packets_missing),
            ),
        ]
    }
}
