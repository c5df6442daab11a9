//! Decoded datagrams to `skinbox_msgs` messages: a [`RecordSink`] that gathers each records
//! datagram's records into one [`CellSampleBatch`], turns each status datagram into a
//! [`BoxStatus`] (with the losses the host saw and the box-to-host time mapping) and sums
//! each box's ports into a [`SkinActivity`] every period; each message goes out as CDR to
//! every [`Output`] (an MCAP recording, the Foxglove live view, DDS).

use crate::cdr::CdrWriter;
use crate::msg::*;
use skinbox_host::decoder::{BoxKey, DatagramOutcome};
use skinbox_host::rows::{host_time, KIND_DATA, KIND_EVENT};
use skinbox_host::timing::{BoxTimeSummary, HostTimeSource, RecordTimes, Timing};
use skinbox_host::{DecodedRecord, RecordSink};
use skinbox_protocol::datagram::{Datagram, DatagramBody};
use skinbox_protocol::record::FLAG_LOSS_BEFORE;
use skinbox_protocol::{CellRepr, Channel, ChannelMask, DatagramRepr};
use std::net::SocketAddr;
use std::time::Duration;

/// The topics, with their message types and QoS (docs/ros2.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Topic {
    /// `/skinbox/samples`: one [`CellSampleBatch`] per records datagram.
    Samples,
    /// `/skinbox/status`: one [`BoxStatus`] per status datagram.
    Status,
    /// `/skinbox/activity`: one [`SkinActivity`] per box and period.
    Activity,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 3] = [Topic::Samples, Topic::Status, Topic::Activity];

    /// The ROS 2 topic name.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Samples => "/skinbox/samples",
            Topic::Status => "/skinbox/status",
            Topic::Activity => "/skinbox/activity",
        }
    }

    /// The message's `package/Name`.
    pub fn message(self) -> &'static str {
        match self {
            Topic::Samples => CellSampleBatch::NAME,
            Topic::Status => BoxStatus::NAME,
            Topic::Activity => SkinActivity::NAME,
        }
    }

    /// The ROS 2 type name, `package/msg/Name`.
    pub fn type_name(self) -> String {
        self.message().replacen('/', "/msg/", 1)
    }

    /// The `ros2msg` schema text (the `.msg` files).
    pub fn schema(self) -> String {
        // The definitions are compiled in and checked by the one-definition test.
        crate::msgdef::schema_text(self.message()).unwrap_or_default()
    }

    /// History depth of the topic's QoS (reliable, volatile, keep last).
    pub fn depth(self) -> u32 {
        match self {
            Topic::Samples => 1000,
            Topic::Status | Topic::Activity => 100,
        }
    }

    /// An index 0..3.
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Where messages go: an MCAP recording, the Foxglove server, a DDS publisher.
pub trait Output {
    /// One message on `topic`, CDR with its encapsulation header, logged at `log_time_ns`
    /// (host time, ns since the epoch).
    fn publish(&mut self, topic: Topic, log_time_ns: u64, cdr: &[u8]) -> std::io::Result<()>;

    /// The largest samples message this output takes, bytes of CDR with its header: a
    /// datagram's samples that need more go out as several [`CellSampleBatch`] messages
    /// (the same stamp, box and datagram sequence, the samples in order, each message as
    /// many as fit). `None`: one message per datagram, whatever its size.
    fn max_samples_message_bytes(&self) -> Option<usize> {
        None
    }

    /// No more messages: finish what is written.
    fn close(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Settings of a [`RosSink`].
#[derive(Debug, Clone, Copy)]
pub struct SinkSettings {
    /// Period of the [`SkinActivity`] messages.
    pub activity_period: Duration,
    /// The channel [`PortActivity`] sums.
    pub activity_channel: Channel,
}

impl Default for SinkSettings {
    fn default() -> Self {
        SinkSettings {
            activity_period: Duration::from_millis(100),
            activity_channel: Channel::Force1,
        }
    }
}

/// The cells seen in a period: one bit per cell id (grown to the highest id seen, so a
/// port's set stays a few cache lines, not 8 kB for every possible id), and their count.
#[derive(Debug, Default, Clone)]
struct CellSet {
    bits: Vec<u64>,
    len: usize,
}

impl CellSet {
    #[inline]
    fn insert(&mut self, cell: u16) {
        let (word, bit) = (usize::from(cell >> 6), 1u64 << (cell & 63));
        if word >= self.bits.len() {
            self.bits.resize(word + 1, 0);
        }
        let w = &mut self.bits[word];
        self.len += usize::from(*w & bit == 0);
        *w |= bit;
    }

    fn clear(&mut self) {
        if self.len > 0 {
            self.bits.fill(0);
            self.len = 0;
        }
    }
}

#[derive(Debug, Default, Clone)]
struct PortSums {
    /// The port sent once (it is reported from then on).
    seen: bool,
    packets: u64,
    events: u64,
    cells: CellSet,
    sum: f64,
    n: u64,
    max: f64,
}

#[derive(Debug, Default)]
struct BoxTrack {
    last_sequence: Option<u32>,
    datagrams_received: u64,
    datagrams_missing: u64,
    records_received: u64,
    event_packets_missing: u64,
    flagged: u64,
    period_start_ns: Option<u64>,
    period_datagrams_missing: u64,
    period_event_packets_missing: u64,
    /// Indexed by port (grown to the highest port seen).
    ports: Vec<PortSums>,
}

impl BoxTrack {
    #[inline]
    fn port(&mut self, port: u8) -> &mut PortSums {
        let i = usize::from(port);
        if i >= self.ports.len() {
            self.ports.resize_with(i + 1, PortSums::default);
        }
        &mut self.ports[i]
    }
}

/// Messages sent, per topic.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Published {
    /// [`CellSampleBatch`] messages, one per records datagram (an output with a size
    /// limit sends some in parts: [`Output::max_samples_message_bytes`]).
    pub samples_messages: u64,
    /// Cell samples in them.
    pub samples: u64,
    /// [`BoxStatus`] messages.
    pub status_messages: u64,
    /// [`SkinActivity`] messages.
    pub activity_messages: u64,
}

/// The sink: records in, messages out. The first output error stops the outputs and is
/// kept ([`RosSink::finish`]).
pub struct RosSink {
    timing: Timing,
    back: Back,
    /// The receive time of the datagram being decoded, ns.
    receive_ns: Option<u64>,
}

/// A record with its times, as far as the decoding thread takes it: what its
/// [`CellSample`] and the port sums are made of (the rest, the units and the rounding of
/// the host times too, is [`Gather::record`]'s).
#[derive(Debug, Clone, Copy)]
struct TimedRecord {
    tick: u64,
    sample_box_ns: f64,
    /// [`RecordTimes::sample_host_ns`] where `HAS_HOST` is set.
    sample_host_ns: f64,
    /// [`RecordTimes::host_error_bound_ns`] where `HAS_BOUND` is set.
    host_error_bound_ns: f64,
    cell: CellRepr,
    datagram_sequence: u32,
    box_id: u16,
    event_packets_missing_before: u16,
    port: u8,
    flags: u8,
    source: HostTimeSource,
    /// `HAS_HOST`, `HAS_BOUND`.
    has: u8,
}

const HAS_HOST: u8 = 1;
const HAS_BOUND: u8 = 2;

impl TimedRecord {
    #[inline]
    fn new(record: &DecodedRecord, times: &RecordTimes) -> TimedRecord {
        TimedRecord {
            tick: record.tick,
            sample_box_ns: times.sample_box_ns,
            sample_host_ns: times.sample_host_ns.unwrap_or(0.0),
            host_error_bound_ns: times.host_error_bound_ns.unwrap_or(0.0),
            cell: record.cell,
            datagram_sequence: record.datagram_sequence,
            box_id: record.box_id,
            event_packets_missing_before: record.event_packets_missing_before,
            port: record.port,
            flags: record.flags,
            source: times.source,
            has: (u8::from(times.sample_host_ns.is_some()) * HAS_HOST)
                | (u8::from(times.host_error_bound_ns.is_some()) * HAS_BOUND),
        }
    }

    /// The host time fields of its sample, as a row has them ([`host_time`]).
    #[inline]
    fn host_time(&self) -> (i64, f64, u8) {
        host_time(&RecordTimes {
            sample_box_s: 0.0,
            sample_box_ns: self.sample_box_ns,
            sample_index: 0,
            sample_host_ns: (self.has & HAS_HOST != 0).then_some(self.sample_host_ns),
            // not read by `host_time`
            method: skinbox_host::timing::SampleMethod::Estimated,
            sample_error_bound_ns: f64::NAN,
            host_error_bound_ns: (self.has & HAS_BOUND != 0).then_some(self.host_error_bound_ns),
            source: self.source,
        })
    }
}

/// A records or status datagram decoded, after its records.
#[derive(Debug)]
struct DecodedDatagram {
    key: BoxKey,
    sequence: u32,
    /// Host time of its activity period check (its receive time, else the time it was
    /// decoded), ns.
    at_ns: u64,
    /// `None` for a records datagram; for a status datagram its payload and its box's
    /// time mapping as the timing had it then.
    status: Option<Box<(Vec<u8>, Option<BoxTimeSummary>)>>,
}

/// What the decoding thread hands to the outputs' thread, in the order it happened.
#[derive(Debug)]
enum Item {
    /// A datagram received at this time, ns.
    Received(Option<u64>),
    /// The records from here on are from this source address.
    Source(Option<SocketAddr>),
    /// A record.
    Record(TimedRecord),
    /// A datagram decoded.
    Decoded(DecodedDatagram),
}

/// The outputs and the CDR writer: where messages become CDR and go out. The first
/// error stops them and is kept.
struct Outputs {
    outputs: Vec<Box<dyn Output + Send>>,
    w: CdrWriter,
    error: Option<std::io::Error>,
}

impl Outputs {
    fn new(outputs: Vec<Box<dyn Output + Send>>) -> Outputs {
        Outputs {
            outputs,
            w: CdrWriter::new(),
            error: None,
        }
    }

    fn send<M: RosMessage>(&mut self, topic: Topic, log_time_ns: u64, m: &M) {
        if self.error.is_some() {
            return;
        }
        m.encode(&mut self.w);
        for o in &mut self.outputs {
            if let Err(e) = o.publish(topic, log_time_ns, self.w.bytes()) {
                self.error = Some(e);
                return;
            }
        }
    }

    fn send_batch(&mut self, log_time: u64, batch: &CellSampleBatch) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = self.try_send_batch(log_time, batch) {
            self.error = Some(e);
        }
    }

    /// The batch to every output: whole to those without a size limit (encoded once), in
    /// parts of as many samples as fit to the others.
    fn try_send_batch(&mut self, log_time: u64, batch: &CellSampleBatch) -> std::io::Result<()> {
        let w = &mut self.w;
        let mut whole = false;
        for o in &mut self.outputs {
            let Some(limit) = o.max_samples_message_bytes() else {
                if !whole {
                    batch.encode(w);
                    whole = true;
                }
                o.publish(Topic::Samples, log_time, w.bytes())?;
                continue;
            };
            whole = false;
            batch.encode_header(w);
            let header = w.len();
            // The sequence length (4 bytes, aligned) and the samples at their largest.
            let fit = (limit.saturating_sub(header + 8) / CELL_SAMPLE_MAX_BYTES).max(1);
            for part in batch.samples.chunks(fit) {
                w.truncate(header);
                batch.encode_samples(w, part);
                o.publish(Topic::Samples, log_time, w.bytes())?;
            }
        }
        Ok(())
    }

    /// Closes every output; the first error.
    fn close(mut self) -> std::io::Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        for o in &mut self.outputs {
            o.close()?;
        }
        Ok(())
    }
}

/// Everything after decoding and timing: the records of a datagram gathered into its
/// [`CellSampleBatch`] (units, the sample), the per-box counts and per-port sums, the
/// status and activity messages, and the outputs. On the decoding thread
/// ([`RosSink::new`]) or on the outputs' own ([`RosSink::pipelined`]), the same work in
/// the same order.
struct Gather {
    settings: SinkSettings,
    outputs: Outputs,
    batch: CellSampleBatch,
    receive_ns: Option<u64>,
    /// The source address of the records.
    source: Option<SocketAddr>,
    /// Each box's track, found by the last box first (a datagram's records are one box's).
    boxes: Vec<(BoxKey, BoxTrack)>,
    last_box: usize,
    published: Published,
}

impl Gather {
    fn new(settings: SinkSettings, outputs: Outputs) -> Gather {
        Gather {
            settings,
            outputs,
            batch: CellSampleBatch::default(),
            receive_ns: None,
            source: None,
            boxes: Vec::new(),
            last_box: 0,
            published: Published::default(),
        }
    }

    #[inline]
    fn take(&mut self, item: &Item) {
        match item {
            Item::Record(r) => self.record(r),
            Item::Received(t) => self.received(*t),
            Item::Source(s) => self.source = *s,
            Item::Decoded(d) => self.decoded(
                d.key,
                d.sequence,
                d.at_ns,
                d.status.as_deref().map(|(p, t)| (p.as_slice(), t.as_ref())),
            ),
        }
    }

    fn received(&mut self, receive_ns: Option<u64>) {
        self.receive_ns = receive_ns;
        self.batch.samples.clear();
    }

    #[inline]
    fn record(&mut self, r: &TimedRecord) {
        let mut values = [f64::NAN; Channel::COUNT];
        let (kind, mask, event_sequence, second_part, cell_id) = match &r.cell {
            CellRepr::Data(d) => {
                for c in Channel::ALL {
                    values[c.index()] = c.to_units(d.raw(c));
                }
                (KIND_DATA, ChannelMask::ALL.bits(), -1, false, d.cell_id)
            }
            CellRepr::Event(e) => {
                for (c, raw) in e.events() {
                    values[c.index()] = c.to_units(raw);
                }
                (
                    KIND_EVENT,
                    e.channels.bits(),
                    i32::from(e.sequence),
                    e.second_part,
                    e.cell_id,
                )
            }
        };
        let key = BoxKey {
            box_id: r.box_id,
            source: self.source,
        };
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        track.records_received += 1;
        track.event_packets_missing += u64::from(r.event_packets_missing_before);
        track.period_event_packets_missing += u64::from(r.event_packets_missing_before);
        track.flagged += u64::from(r.flags & FLAG_LOSS_BEFORE != 0);
        let p = track.port(r.port);
        p.seen = true;
        p.packets += 1;
        p.events += u64::from(if kind == KIND_EVENT {
            mask.count_ones()
        } else {
            0
        });
        p.cells.insert(cell_id);
        let v = values[self.settings.activity_channel.index()];
        if !v.is_nan() {
            p.max = if p.n == 0 { v } else { p.max.max(v) };
            p.sum += v;
            p.n += 1;
        }
        let (host_time_ns, host_time_bound_ns, host_time_source) = r.host_time();
        self.batch.samples.push(CellSample {
            box_id: r.box_id,
            port: r.port,
            cell_id,
            kind,
            event_mask: mask,
            values,
            event_sequence,
            second_part,
            event_packets_missing_before: r.event_packets_missing_before,
            flags: r.flags,
            datagram_sequence: r.datagram_sequence,
            box_time_ns: r.tick.wrapping_mul(skinbox_protocol::TICK_NS),
            sample_box_time_ns: r.sample_box_ns,
            host_time_ns,
            host_time_bound_ns,
            host_time_source,
        });
    }

    /// The log time of a message about a datagram: its receive time, else the host time of
    /// its first sample, else its box time.
    fn log_time(&self) -> u64 {
        self.receive_ns.unwrap_or_else(|| {
            self.batch.samples.first().map_or(0, |s| {
                if s.host_time_ns > 0 {
                    s.host_time_ns as u64
                } else {
                    s.box_time_ns
                }
            })
        })
    }

    /// A records or status datagram of box `key` decoded (after its records): `status`
    /// has a status datagram's payload and its box's time mapping.
    fn decoded(
        &mut self,
        key: BoxKey,
        sequence: u32,
        at_ns: u64,
        status: Option<(&[u8], Option<&BoxTimeSummary>)>,
    ) {
        // Records and status datagrams share the box's sequence numbers.
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        if let Some(last) = track.last_sequence {
            let gap = sequence.wrapping_sub(last).wrapping_sub(1);
            if gap < 1 << 31 {
                track.datagrams_missing += u64::from(gap);
                track.period_datagrams_missing += u64::from(gap);
            }
        }
        track.last_sequence = Some(sequence);
        match status {
            None => {
                track.datagrams_received += 1;
                if !self.batch.samples.is_empty() {
                    self.take_batch(key, sequence);
                }
            }
            Some((payload, time)) => self.status(key, payload, time, at_ns),
        }
        self.activity(key, at_ns);
    }

    fn take_batch(&mut self, key: BoxKey, sequence: u32) {
        let log_time = self.log_time();
        self.batch.stamp = Time::from_ns(log_time);
        self.batch.box_id = key.box_id;
        self.batch.box_address = key.source.map(|a| a.to_string()).unwrap_or_default();
        self.batch.datagram_sequence = sequence;
        self.published.samples_messages += 1;
        self.published.samples += self.batch.samples.len() as u64;
        self.outputs.send_batch(log_time, &self.batch);
        self.batch.samples.clear();
    }

    fn status(
        &mut self,
        key: BoxKey,
        payload: &[u8],
        time: Option<&BoxTimeSummary>,
        log_time: u64,
    ) {
        let Ok((repr, counters)) = DatagramRepr::parse_box_counters(payload) else {
            return;
        };
        let DatagramBody::Status(s) = &repr.body else {
            return;
        };
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        let m = BoxStatus {
            stamp: Time::from_ns(log_time),
            box_id: key.box_id,
            box_address: key.source.map(|a| a.to_string()).unwrap_or_default(),
            boot_id: s.boot_id,
            link_up: counters.is_some_and(|c| c.link_up),
            link_speed: counters.map_or(
                skinbox_protocol::box_counters::LinkSpeed::Unknown as u8,
                |c| c.link_speed as u8,
            ),
            datagrams_sent: s.datagrams_sent,
            records_sent: s.records_sent,
            ports: s
                .ports
                .iter()
                .enumerate()
                .map(|(i, c)| PortCounters {
                    port: s.first_port.wrapping_add(i as u8),
                    counters: *c,
                })
                .collect(),
            datagrams_received: track.datagrams_received,
            datagrams_missing: track.datagrams_missing,
            records_received: track.records_received,
            event_packets_missing: track.event_packets_missing,
            records_flagged_loss_before: track.flagged,
            host_time_source: skinbox_host::rows::host_time_source_code(
                time.map_or(HostTimeSource::None, |t| t.source),
            ),
            drift_ppm: time.and_then(|t| t.drift_ppm).unwrap_or(f64::NAN),
            time_error_bound_ns: time.and_then(|t| t.error_bound_ns).unwrap_or(f64::NAN),
            time_map_restarts: time.map_or(0, |t| t.restarts),
        };
        self.published.status_messages += 1;
        self.outputs.send(Topic::Status, log_time, &m);
    }

    fn activity(&mut self, key: BoxKey, at_ns: u64) {
        let period_ns = self.settings.activity_period.as_nanos() as u64;
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        let start = *track.period_start_ns.get_or_insert(at_ns);
        if at_ns < start + period_ns.max(1) {
            return;
        }
        let period_s = (at_ns - start) as f64 * 1e-9;
        let channel = self.settings.activity_channel;
        let ports = track
            .ports
            .iter_mut()
            .enumerate()
            .filter(|(_, p)| p.seen)
            .map(|(port, p)| {
                let a = PortActivity {
                    port: port as u8,
                    packets_per_s: p.packets as f64 / period_s,
                    events_per_s: p.events as f64 / period_s,
                    cells_active: p.cells.len.min(usize::from(u16::MAX)) as u16,
                    channel_max: if p.n > 0 { p.max } else { f64::NAN },
                    channel_mean: if p.n > 0 {
                        p.sum / p.n as f64
                    } else {
                        f64::NAN
                    },
                };
                p.packets = 0;
                p.events = 0;
                p.cells.clear();
                p.sum = 0.0;
                p.n = 0;
                p.max = 0.0;
                a
            })
            .collect();
        let m = SkinActivity {
            stamp: Time::from_ns(at_ns),
            box_id: key.box_id,
            period_s,
            channel: channel.index() as u8,
            channel_name: channel.name().to_string(),
            ports,
            datagrams_missing: std::mem::take(&mut track.period_datagrams_missing),
            event_packets_missing: std::mem::take(&mut track.period_event_packets_missing),
        };
        track.period_start_ns = Some(at_ns);
        self.published.activity_messages += 1;
        self.outputs.send(Topic::Activity, at_ns, &m);
    }
}

/// Where the sink's records go after timing: gathered into messages and sent on this
/// thread, or handed to the outputs' thread.
enum Back {
    Inline(Box<Gather>),
    Thread(Pipeline),
}

/// Items (records, mostly) a batch for the outputs' thread holds at most (about 80 kB,
/// so that they are still in a cache shared by the two threads).
pub const PIPELINE_BATCH_ITEMS: usize = 1024;
/// Batches sent and not yet taken by the outputs' thread (16: about 1.3 MB of records, a
/// few ms of the decoding thread's work, so that the outputs' thread losing its core for a
/// moment on a shared machine does not stop the decoding thread); past them the decoding
/// thread waits.
const PIPELINE_DEPTH: usize = 16;

/// The decoding thread's end of the outputs' thread: batches of items out; emptied
/// batches back for reuse, with the messages made so far.
struct Pipeline {
    to_outputs: Option<std::sync::mpsc::SyncSender<Vec<Item>>>,
    returned: std::sync::mpsc::Receiver<(Vec<Item>, Published)>,
    thread: Option<std::thread::JoinHandle<std::io::Result<Published>>>,
    pending: Vec<Item>,
    spare: Vec<Vec<Item>>,
    /// The source address of the last record handed over.
    source: Option<SocketAddr>,
    published: Published,
}

impl Pipeline {
    fn start(gather: Gather) -> std::io::Result<Pipeline> {
        let (to_outputs, batches) = std::sync::mpsc::sync_channel::<Vec<Item>>(PIPELINE_DEPTH);
        let (give_back, returned) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("ros-outputs".into())
            .spawn(move || {
                let mut gather = gather;
                while let Ok(mut batch) = batches.recv() {
                    for item in &batch {
                        gather.take(item);
                    }
                    batch.clear();
                    if gather.outputs.error.is_some() {
                        // The decoding thread finds the channel closed and stops sending.
                        break;
                    }
                    let _ = give_back.send((batch, gather.published));
                }
                // The outputs finish here too (an MCAP file's summary and indexes).
                let published = gather.published;
                gather.outputs.close().map(|()| published)
            })?;
        Ok(Pipeline {
            to_outputs: Some(to_outputs),
            returned,
            thread: Some(thread),
            pending: Vec::with_capacity(PIPELINE_BATCH_ITEMS),
            spare: Vec::new(),
            source: None,
            published: Published::default(),
        })
    }

    fn take_returned(&mut self) {
        while let Ok((batch, published)) = self.returned.try_recv() {
            self.spare.push(batch);
            self.published = published;
        }
    }

    #[inline]
    fn push(&mut self, item: Item) {
        self.pending.push(item);
        if self.pending.len() >= PIPELINE_BATCH_ITEMS {
            self.flush();
        }
    }

    /// The pending items to the outputs' thread (waiting while it is [`PIPELINE_DEPTH`]
    /// batches behind).
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        self.take_returned();
        let next = self
            .spare
            .pop()
            .unwrap_or_else(|| Vec::with_capacity(PIPELINE_BATCH_ITEMS));
        let batch = std::mem::replace(&mut self.pending, next);
        if let Some(tx) = &self.to_outputs {
            if tx.send(batch).is_err() {
                // The outputs failed: their thread keeps the error for finish.
                self.to_outputs = None;
            }
        }
    }

    /// Sends what is pending, waits for the outputs' thread to close the outputs and end;
    /// the first error, or the messages sent.
    fn join(mut self) -> std::io::Result<Published> {
        self.flush();
        self.to_outputs = None;
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(result)) => result,
            _ => Err(std::io::Error::other("the ROS outputs' thread panicked")),
        }
    }
}

/// The track of box `key` in `boxes`, made on its first use; `last` is the box found
/// before, tried first.
#[inline]
fn track_of<'a>(
    boxes: &'a mut Vec<(BoxKey, BoxTrack)>,
    last: &mut usize,
    key: BoxKey,
) -> &'a mut BoxTrack {
    let i = match boxes.get(*last) {
        Some((k, _)) if *k == key => *last,
        _ => match boxes.iter().position(|(k, _)| *k == key) {
            Some(i) => i,
            None => {
                boxes.push((key, BoxTrack::default()));
                boxes.len() - 1
            }
        },
    };
    *last = i;
    &mut boxes[i].1
}

fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

impl RosSink {
    /// A sink timing records with `timing` and sending to `outputs`, on the caller's
    /// thread: each message goes out before the call that made it returns.
    pub fn new(
        timing: Timing,
        settings: SinkSettings,
        outputs: Vec<Box<dyn Output + Send>>,
    ) -> Self {
        let gather = Gather::new(settings, Outputs::new(outputs));
        RosSink::with_back(timing, Back::Inline(Box::new(gather)))
    }

    /// As [`RosSink::new`], with all but decoding and timing on a thread of their own:
    /// the caller's thread decodes and times the records and hands them over with the
    /// datagrams' events in batches (of up to [`PIPELINE_BATCH_ITEMS`]; a few batches ahead
    /// at most, then it waits); the other thread gathers the messages (units, samples,
    /// counts and sums), encodes the CDR and runs the outputs. The outputs get the same
    /// messages in the same order as from [`RosSink::new`], only later: for recordings,
    /// not for live outputs whose latency counts. An output's error shows at
    /// [`RosSink::finish`].
    pub fn pipelined(
        timing: Timing,
        settings: SinkSettings,
        outputs: Vec<Box<dyn Output + Send>>,
    ) -> std::io::Result<Self> {
        let gather = Gather::new(settings, Outputs::new(outputs));
        let back = Back::Thread(Pipeline::start(gather)?);
        Ok(RosSink::with_back(timing, back))
    }

    fn with_back(timing: Timing, back: Back) -> Self {
        RosSink {
            timing,
            back,
            receive_ns: None,
        }
    }

    /// The timing, for its summary.
    pub fn timing(&self) -> &Timing {
        &self.timing
    }

    /// Messages sent so far (pipelined: as far as the outputs' thread has come; all of
    /// them from [`RosSink::finish`]).
    pub fn published(&self) -> Published {
        match &self.back {
            Back::Inline(g) => g.published,
            Back::Thread(p) => p.published,
        }
    }

    /// Ends: closes every output; the first error, or the messages sent.
    pub fn finish(self) -> std::io::Result<Published> {
        match self.back {
            Back::Inline(g) => {
                let published = g.published;
                g.outputs.close().map(|()| published)
            }
            Back::Thread(p) => p.join(),
        }
    }
}

impl RecordSink for RosSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        let times = self.timing.record(record);
        let r = TimedRecord::new(record, &times);
        match &mut self.back {
            Back::Inline(g) => {
                g.source = record.source;
                g.record(&r);
            }
            Back::Thread(p) => {
                if record.source != p.source {
                    p.source = record.source;
                    p.push(Item::Source(record.source));
                }
                p.push(Item::Record(r));
            }
        }
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        self.receive_ns = receive.map(|d| d.as_nanos() as u64);
        match &mut self.back {
            Back::Inline(g) => g.received(self.receive_ns),
            Back::Thread(p) => p.push(Item::Received(self.receive_ns)),
        }
        self.timing.datagram_received(receive, source, payload);
    }

    fn datagram_decoded(
        &mut self,
        source: Option<SocketAddr>,
        payload: &[u8],
        outcome: DatagramOutcome,
    ) {
        let Ok(d) = Datagram::new_checked(payload) else {
            return;
        };
        let key = BoxKey {
            box_id: d.box_id(),
            source,
        };
        let is_status = match outcome {
            DatagramOutcome::Records { .. } => false,
            DatagramOutcome::Status => true,
            _ => return,
        };
        let sequence = d.sequence();
        let at_ns = self.receive_ns.unwrap_or_else(now_ns);
        // The box's time mapping as it is now, for a status message.
        let time = || {
            self.timing
                .summary()
                .into_iter()
                .find(|t| t.box_id == key.box_id && t.address == key.source)
        };
        match &mut self.back {
            Back::Inline(g) => {
                let time = if is_status { time() } else { None };
                let status = is_status.then_some((payload, time.as_ref()));
                g.decoded(key, sequence, at_ns, status);
            }
            Back::Thread(p) => {
                let status = is_status.then(|| Box::new((payload.to_vec(), time())));
                p.push(Item::Decoded(DecodedDatagram {
                    key,
                    sequence,
                    at_ns,
                    status,
                }));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::CellSet;

    #[test]
    fn a_cell_set_counts_each_cell_once_and_clears() {
        let mut set = CellSet::default();
        for cell in [5, 700, 5, 16383, 0, 700, 64, 63] {
            set.insert(cell);
        }
        assert_eq!(set.len, 6);
        set.clear();
        assert_eq!(set.len, 0);
        set.insert(700);
        set.insert(1);
        assert_eq!(set.len, 2);
    }
}
