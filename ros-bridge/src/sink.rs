//! Decoded datagrams to `skinbox_msgs` messages: a [`RecordSink`] that gathers each records
//! datagram's records into one [`CellSampleBatch`], turns each status datagram into a
//! [`BoxStatus`] (with the losses the host saw and the box-to-host time mapping) and sums
//! each box's ports into a [`SkinActivity`] every period; each message goes out as CDR to
//! every [`Output`] (an MCAP recording, the Foxglove live view, DDS).

use crate::cdr::CdrWriter;
use crate::msg::*;
use skinbox_host::decoder::{BoxKey, DatagramOutcome};
use skinbox_host::rows::RecordRow;
use skinbox_host::timing::{HostTimeSource, Timing};
use skinbox_host::{DecodedRecord, RecordSink};
use skinbox_protocol::datagram::{Datagram, DatagramBody};
use skinbox_protocol::record::FLAG_LOSS_BEFORE;
use skinbox_protocol::{Channel, DatagramRepr};
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
    settings: SinkSettings,
    back: Back,
    batch: CellSampleBatch,
    receive_ns: Option<u64>,
    /// Each box's track, found by the last box first (a datagram's records are one box's).
    boxes: Vec<(BoxKey, BoxTrack)>,
    last_box: usize,
    published: Published,
}

/// A message as values, with its log time, on its way to the outputs' thread.
enum Message {
    Samples(u64, CellSampleBatch),
    Status(u64, BoxStatus),
    Activity(u64, SkinActivity),
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

    fn publish(&mut self, m: &Message) {
        match m {
            Message::Samples(t, b) => self.send_batch(*t, b),
            Message::Status(t, s) => self.send(Topic::Status, *t, s),
            Message::Activity(t, a) => self.send(Topic::Activity, *t, a),
        }
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

/// Where the sink's messages go: to the outputs on this thread, or to their own thread.
enum Back {
    Inline(Outputs),
    Thread(Pipeline),
}

/// Samples a batch of messages for the outputs' thread holds at most (about 140 kB of
/// [`CellSample`]s, so that they are still in a cache shared by the two threads).
pub const PIPELINE_BATCH_SAMPLES: usize = 1024;
/// Messages a batch holds at most.
const PIPELINE_BATCH_MESSAGES: usize = 64;
/// Batches sent and not yet taken by the outputs' thread (16: about 2 MB of samples, a few
/// ms of the decoding thread's work, so that the outputs' thread losing its core for a
/// moment on a shared machine does not stop the decoding thread); past them the decoding
/// thread waits.
const PIPELINE_DEPTH: usize = 16;

/// The decoding thread's end of the outputs' thread: batches of messages out; emptied
/// batches and sample vectors back, for reuse.
struct Pipeline {
    to_outputs: Option<std::sync::mpsc::SyncSender<Vec<Message>>>,
    returned: std::sync::mpsc::Receiver<(Vec<Message>, Vec<Vec<CellSample>>)>,
    thread: Option<std::thread::JoinHandle<Outputs>>,
    pending: Vec<Message>,
    pending_samples: usize,
    spare_batches: Vec<Vec<Message>>,
    spare_samples: Vec<Vec<CellSample>>,
}

impl Pipeline {
    fn start(outputs: Outputs) -> std::io::Result<Pipeline> {
        let (to_outputs, batches) = std::sync::mpsc::sync_channel::<Vec<Message>>(PIPELINE_DEPTH);
        let (give_back, returned) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("ros-outputs".into())
            .spawn(move || {
                let mut outputs = outputs;
                while let Ok(mut batch) = batches.recv() {
                    let mut samples = Vec::new();
                    for m in batch.drain(..) {
                        outputs.publish(&m);
                        if let Message::Samples(_, b) = m {
                            let mut s = b.samples;
                            s.clear();
                            samples.push(s);
                        }
                    }
                    if outputs.error.is_some() {
                        // The decoding thread finds the channel closed and stops sending.
                        break;
                    }
                    let _ = give_back.send((batch, samples));
                }
                outputs
            })?;
        Ok(Pipeline {
            to_outputs: Some(to_outputs),
            returned,
            thread: Some(thread),
            pending: Vec::with_capacity(PIPELINE_BATCH_MESSAGES),
            pending_samples: 0,
            spare_batches: Vec::new(),
            spare_samples: Vec::new(),
        })
    }

    /// An empty sample vector: one the outputs' thread gave back, where there is one.
    #[inline]
    fn samples_vec(&mut self) -> Vec<CellSample> {
        if self.spare_samples.is_empty() {
            self.take_returned();
        }
        self.spare_samples.pop().unwrap_or_default()
    }

    fn take_returned(&mut self) {
        while let Ok((batch, samples)) = self.returned.try_recv() {
            self.spare_batches.push(batch);
            self.spare_samples.extend(samples);
        }
    }

    #[inline]
    fn push(&mut self, m: Message, samples: usize) {
        self.pending.push(m);
        self.pending_samples += samples;
        if self.pending_samples >= PIPELINE_BATCH_SAMPLES
            || self.pending.len() >= PIPELINE_BATCH_MESSAGES
        {
            self.flush();
        }
    }

    /// The pending messages to the outputs' thread (waiting while it is
    /// [`PIPELINE_DEPTH`] batches behind).
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        self.take_returned();
        let next = self
            .spare_batches
            .pop()
            .unwrap_or_else(|| Vec::with_capacity(PIPELINE_BATCH_MESSAGES));
        let batch = std::mem::replace(&mut self.pending, next);
        self.pending_samples = 0;
        if let Some(tx) = &self.to_outputs {
            if tx.send(batch).is_err() {
                // The outputs failed: their thread keeps the error for finish.
                self.to_outputs = None;
            }
        }
    }

    /// Sends what is pending and waits for the outputs' thread to end.
    fn join(mut self) -> std::io::Result<Outputs> {
        self.flush();
        self.to_outputs = None;
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(outputs)) => Ok(outputs),
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
        RosSink::with_back(timing, settings, Back::Inline(Outputs::new(outputs)))
    }

    /// As [`RosSink::new`], with the CDR encoding and the outputs on a thread of their
    /// own: the caller's thread decodes, times and gathers the messages as values and
    /// hands them over in batches (of up to [`PIPELINE_BATCH_SAMPLES`] samples; a few
    /// batches ahead at most, then it waits). The outputs get the same messages in the
    /// same order as from [`RosSink::new`], only later: for recordings, not for live
    /// outputs whose latency counts. An output's error shows at [`RosSink::finish`].
    pub fn pipelined(
        timing: Timing,
        settings: SinkSettings,
        outputs: Vec<Box<dyn Output + Send>>,
    ) -> std::io::Result<Self> {
        let back = Back::Thread(Pipeline::start(Outputs::new(outputs))?);
        Ok(RosSink::with_back(timing, settings, back))
    }

    fn with_back(timing: Timing, settings: SinkSettings, back: Back) -> Self {
        RosSink {
            timing,
            settings,
            back,
            batch: CellSampleBatch::default(),
            receive_ns: None,
            boxes: Vec::new(),
            last_box: 0,
            published: Published::default(),
        }
    }

    /// The timing, for its summary.
    pub fn timing(&self) -> &Timing {
        &self.timing
    }

    /// Messages sent so far.
    pub fn published(&self) -> Published {
        self.published
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

    fn take_batch(&mut self, key: BoxKey, sequence: u32) {
        let log_time = self.log_time();
        self.batch.stamp = Time::from_ns(log_time);
        self.batch.box_id = key.box_id;
        self.batch.box_address = key.source.map(|a| a.to_string()).unwrap_or_default();
        self.batch.datagram_sequence = sequence;
        let samples = self.batch.samples.len();
        self.published.samples_messages += 1;
        self.published.samples += samples as u64;
        match &mut self.back {
            Back::Inline(o) => {
                o.send_batch(log_time, &self.batch);
                self.batch.samples.clear();
            }
            Back::Thread(p) => {
                let batch = CellSampleBatch {
                    stamp: self.batch.stamp,
                    box_id: self.batch.box_id,
                    box_address: std::mem::take(&mut self.batch.box_address),
                    datagram_sequence: sequence,
                    samples: std::mem::replace(&mut self.batch.samples, p.samples_vec()),
                };
                p.push(Message::Samples(log_time, batch), samples);
            }
        }
    }

    fn status(&mut self, key: BoxKey, payload: &[u8]) {
        let Ok((repr, counters)) = DatagramRepr::parse_box_counters(payload) else {
            return;
        };
        let DatagramBody::Status(s) = &repr.body else {
            return;
        };
        let log_time = self.receive_ns.unwrap_or_else(now_ns);
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        let time = self
            .timing
            .summary()
            .into_iter()
            .find(|t| t.box_id == key.box_id && t.address == key.source);
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
                time.as_ref().map_or(HostTimeSource::None, |t| t.source),
            ),
            drift_ppm: time.as_ref().and_then(|t| t.drift_ppm).unwrap_or(f64::NAN),
            time_error_bound_ns: time
                .as_ref()
                .and_then(|t| t.error_bound_ns)
                .unwrap_or(f64::NAN),
            time_map_restarts: time.as_ref().map_or(0, |t| t.restarts),
        };
        self.published.status_messages += 1;
        match &mut self.back {
            Back::Inline(o) => o.send(Topic::Status, log_time, &m),
            Back::Thread(p) => p.push(Message::Status(log_time, m), 0),
        }
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
        match &mut self.back {
            Back::Inline(o) => o.send(Topic::Activity, at_ns, &m),
            Back::Thread(p) => p.push(Message::Activity(at_ns, m), 0),
        }
    }

    /// Ends: closes every output; the first error, or the messages sent.
    pub fn finish(self) -> std::io::Result<Published> {
        let outputs = match self.back {
            Back::Inline(o) => o,
            Back::Thread(p) => p.join()?,
        };
        outputs.close()?;
        Ok(self.published)
    }
}

impl RecordSink for RosSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        let times = self.timing.record(record);
        let row = RecordRow::new(record, &times);
        let key = BoxKey {
            box_id: record.box_id,
            source: record.source,
        };
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        track.records_received += 1;
        track.event_packets_missing += u64::from(record.event_packets_missing_before);
        track.period_event_packets_missing += u64::from(record.event_packets_missing_before);
        track.flagged += u64::from(record.flags & FLAG_LOSS_BEFORE != 0);
        let p = track.port(record.port);
        p.seen = true;
        p.packets += 1;
        p.events += u64::from(if row.kind == skinbox_host::rows::KIND_EVENT {
            row.mask.count_ones()
        } else {
            0
        });
        p.cells.insert(row.cell_id);
        let v = row.values[self.settings.activity_channel.index()];
        if !v.is_nan() {
            p.max = if p.n == 0 { v } else { p.max.max(v) };
            p.sum += v;
            p.n += 1;
        }
        self.batch.samples.push(CellSample::from(&row));
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        self.receive_ns = receive.map(|d| d.as_nanos() as u64);
        self.batch.samples.clear();
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
        if !matches!(
            outcome,
            DatagramOutcome::Records { .. } | DatagramOutcome::Status
        ) {
            return;
        }
        // Records and status datagrams share the box's sequence numbers.
        let track = track_of(&mut self.boxes, &mut self.last_box, key);
        let sequence = d.sequence();
        if let Some(last) = track.last_sequence {
            let gap = sequence.wrapping_sub(last).wrapping_sub(1);
            if gap < 1 << 31 {
                track.datagrams_missing += u64::from(gap);
                track.period_datagrams_missing += u64::from(gap);
            }
        }
        track.last_sequence = Some(sequence);
        if let DatagramOutcome::Records { .. } = outcome {
            track.datagrams_received += 1;
            if !self.batch.samples.is_empty() {
                self.take_batch(key, sequence);
            }
        } else {
            self.status(key, payload);
        }
        let at = self.receive_ns.unwrap_or_else(now_ns);
        self.activity(key, at);
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
