//! Every record's times, as `skinbox decode` and `skinbox capture` write them: the box time
//! of its first start bit (the stamp), the estimated box time of its sample
//! ([`crate::sample_clock`]), and that sample time on the host's clock
//! ([`crate::clock_map`]), with the mapping's error bound where it has one.
//!
//! The host clock is the one the datagrams' receive times are on: CLOCK_REALTIME for a live
//! capture (the kernel's SO_TIMESTAMPNS) and for its pcap; whatever the writer used for
//! other pcaps (a co-simulation's are simulated time). Each box has its own map, so the
//! records of several boxes land on one host time line.

use crate::box_map::BoxMap;
use crate::clock_map::{ClockMap, HostTime, ReceiveStampMap, TimeExchange};
use crate::decoder::{BoxKey, DecodedRecord};
use crate::sample_clock::{PathModel, SampleTimer};
use skinbox_protocol::datagram::{Datagram, DatagramKind};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::Duration;

/// Where a record's host time came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HostTimeSource {
    /// NTP-style exchanges with the box ([`ClockMap`]); with an error bound.
    Exchanges,
    /// The datagrams' receive timestamps ([`ReceiveStampMap`]); late by the shortest
    /// delivery delay, no bound.
    ReceiveStamps,
    /// No host time (no exchange, no receive timestamp yet).
    None,
}

impl HostTimeSource {
    /// Name in rows.
    pub fn name(self) -> &'static str {
        match self {
            HostTimeSource::Exchanges => "exchanges",
            HostTimeSource::ReceiveStamps => "receive_stamps",
            HostTimeSource::None => "none",
        }
    }
}

/// How a record's sample time was found (docs/time.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleMethod {
    /// The box keeps its cells on its tick grid with time syncs (method c): the grid point
    /// the stamp less the path latency falls on.
    Synced,
    /// Estimated from the cell's stamps (method b, [`crate::sample_clock`]).
    Estimated,
}

impl SampleMethod {
    /// Name in rows and reports.
    pub fn name(self) -> &'static str {
        match self {
            SampleMethod::Synced => "synced",
            SampleMethod::Estimated => "estimated",
        }
    }
}

/// Which method [`Timing`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SampleTimeMode {
    /// Synced for the records of a box whose latest status datagram said it sends time
    /// syncs ([`skinbox_protocol::datagram::FLAG_TIME_SYNCS`]), estimated otherwise (before
    /// its first status datagram too).
    #[default]
    Auto,
    /// Synced for every record.
    Synced,
    /// Estimated for every record.
    Estimated,
}

/// Error bound of a synced sample time, ns: the cells' rate servo holds every cell of a
/// 66-cell bus within 0.1 us at p99 and its failure boundaries (5 ppm temperature steps,
/// 1 ppm/s wander, 30 % of the syncs lost at 0.1 s) within 1 us (docs/time.md, "The rate
/// servo"). A bound of the cells' specification, not measured by the host.
pub const SYNCED_SAMPLE_BOUND_NS: f64 = 1_000.0;

/// Longest a packet may wait in its bus before it leaves the root, ns: the root cell's
/// FIFO (32 packets of 50 us, the bus model's `fifo_packets`). An estimated sample time
/// is bounded by the stamp less the path latency and less this much more.
pub const ROOT_QUEUE_BOUND_NS: f64 = 32.0 * 50_000.0;

/// Records by how their sample times were found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SampleMethodCounts {
    /// On the box's grid (method c).
    pub synced: u64,
    /// Estimated from stamps (method b).
    pub estimated: u64,
}

/// The times of one record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordTimes {
    /// Estimated box time of the sample, s.
    pub sample_box_s: f64,
    /// The same in ns, as estimated (`sample_box_s` is it times 1e-9).
    pub sample_box_ns: f64,
    /// The cell's sample index on its sample clock (0: the sample of the first packet of
    /// the cell since its clock began).
    pub sample_index: i64,
    /// The sample's host time, ns on the host clock, if mapped.
    pub sample_host_ns: Option<f64>,
    /// How the sample time was found.
    pub method: SampleMethod,
    /// Error bound of the sample's box time, ns ([`SYNCED_SAMPLE_BOUND_NS`] when synced;
    /// when estimated, the farther end of the interval the bus allows: the stamp less the
    /// path latency, less up to [`ROOT_QUEUE_BOUND_NS`] of queueing). NaN where the cells'
    /// positions on their chains are unknown ([`crate::sample_clock::Positions::Unknown`]):
    /// then nothing bounds the path latency.
    pub sample_error_bound_ns: f64,
    /// Error bound of the sample's host time, ns: the sample's bound plus the mapping's,
    /// where the mapping has one (exchanges; receive timestamps give none).
    pub host_error_bound_ns: Option<f64>,
    /// Where the host time came from.
    pub source: HostTimeSource,
}

/// How one box's time is mapped to host time, for reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BoxTimeSummary {
    /// The box: its id ...
    pub box_id: u16,
    /// ... and the source address of its datagrams, where known.
    pub address: Option<SocketAddr>,
    /// Which map gives its host times.
    pub source: HostTimeSource,
    /// The box oscillator's drift against the host clock, ppm, where measured.
    pub drift_ppm: Option<f64>,
    /// Error bound of a host time at the last exchange's box time, ns (exchanges only).
    pub error_bound_ns: Option<f64>,
    /// Times the map started over on a box reset.
    pub restarts: u64,
}

/// How long an acknowledgement waits for its command's send stamp to be recorded
/// ([`Timing::with_send_stamps`]; it comes microseconds after the send, but the sending
/// thread may be preempted).
pub const SEND_STAMP_WAIT: Duration = Duration::from_millis(2);

/// How the exchanges' host send times were stamped (their receive times are the
/// datagrams' receive stamps: the kernel's for a live capture).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct ExchangeStampCounts {
    /// Exchanges whose send time is the kernel's software send stamp of the command
    /// (SO_TIMESTAMPING, [`crate::kernel_stamps`]).
    pub kernel: u64,
    /// Exchanges whose send time is the host time the command carries, read in user
    /// space just before it was sent.
    pub user_space: u64,
    /// Why exchanges fell back to the user-space send time although kernel stamps were
    /// asked for, by reason ([`crate::kernel_stamps::Fallback::name`]; `not_recorded`:
    /// the sender had not read its stamp within [`SEND_STAMP_WAIT`] of the
    /// acknowledgement).
    pub fallbacks: std::collections::BTreeMap<&'static str, u64>,
}

impl ExchangeStampCounts {
    /// Which send stamps the exchanges used: `kernel`, `user_space`, `mixed`, or `none`
    /// (no exchange yet).
    pub fn name(&self) -> &'static str {
        match (self.kernel, self.user_space) {
            (0, 0) => "none",
            (_, 0) => "kernel",
            (0, _) => "user_space",
            _ => "mixed",
        }
    }
}

/// Sample times and host times of every record, per box (box id and source address: two
/// boxes of one id from two addresses are two boxes with two maps).
#[derive(Debug, Clone)]
pub struct Timing {
    samples: SampleTimer,
    mode: SampleTimeMode,
    /// Each box's latest status: whether it sends time syncs.
    box_syncs: HashMap<BoxKey, bool>,
    method_counts: SampleMethodCounts,
    synced_bound_ns: f64,
    queue_bound_ns: f64,
    exchanges: BoxMap<ClockMap>,
    receive: BoxMap<ReceiveStampMap>,
    /// Each box's boot id, from its latest status datagram.
    boot_ids: HashMap<BoxKey, u32>,
    /// Read-tick acknowledgements that could not be used: no boot id seen yet, or an
    /// exchange that cannot be true.
    exchanges_unused: u64,
    /// The kernel's send stamps of the read-tick commands, where asked for.
    send_stamps: Option<crate::kernel_stamps::CommandSendStamps>,
    /// How the exchanges' send times were stamped.
    exchange_stamps: ExchangeStampCounts,
}

impl Timing {
    /// The same timing for cells on the box's time grid ([`SampleTimer::on_box_grid`]),
    /// whatever the boxes' status says ([`SampleTimeMode::Synced`]).
    pub fn on_box_grid(self) -> Timing {
        self.with_mode(SampleTimeMode::Synced)
    }

    /// The same timing with its method chosen by `mode`.
    pub fn with_mode(mut self, mode: SampleTimeMode) -> Timing {
        self.mode = mode;
        self
    }

    /// The same timing with other error bounds: a synced sample's `synced_ns`, and the
    /// longest queueing of a packet in its bus, `queue_ns`, for estimated ones.
    pub fn with_bounds(mut self, synced_ns: f64, queue_ns: f64) -> Timing {
        self.synced_bound_ns = synced_ns;
        self.queue_bound_ns = queue_ns;
        self
    }

    /// Records timed so far by each method.
    pub fn method_counts(&self) -> SampleMethodCounts {
        self.method_counts
    }

    /// The same timing with every sample clock fit recomputed from all its points
    /// ([`SampleTimer::batch`]): the reference for the incremental fits, O(window) a record.
    pub fn batch(mut self) -> Timing {
        self.samples = self.samples.batch();
        self
    }

    /// Cells sampling nominally at `sample_rate_hz` on paths of `paths`.
    pub fn new(sample_rate_hz: f64, paths: PathModel) -> Timing {
        Timing {
            samples: SampleTimer::new(sample_rate_hz, paths),
            mode: SampleTimeMode::Auto,
            box_syncs: HashMap::new(),
            method_counts: SampleMethodCounts::default(),
            synced_bound_ns: SYNCED_SAMPLE_BOUND_NS,
            queue_bound_ns: ROOT_QUEUE_BOUND_NS,
            exchanges: BoxMap::default(),
            receive: BoxMap::default(),
            boot_ids: HashMap::new(),
            exchanges_unused: 0,
            send_stamps: None,
            exchange_stamps: ExchangeStampCounts::default(),
        }
    }

    /// The same timing with the kernel's send stamps of the read-tick commands
    /// ([`crate::live::send_read_ticks_stamped`]): an acknowledgement's exchange takes its
    /// command's send stamp as host send time, else (counted in
    /// [`Timing::exchange_stamps`]) the host time the command carries. An acknowledgement
    /// waits up to [`SEND_STAMP_WAIT`] for its stamp.
    pub fn with_send_stamps(mut self, stamps: crate::kernel_stamps::CommandSendStamps) -> Timing {
        self.send_stamps = Some(stamps);
        self
    }

    /// How the exchanges' host send times were stamped.
    pub fn exchange_stamps(&self) -> &ExchangeStampCounts {
        &self.exchange_stamps
    }

    /// The next datagram, `payload`, from `source` (where known), was received at
    /// `receive` on the host clock (`None`: unknown). Its records were all stamped before it left: its latest record's tick
    /// against `receive` is a point above the receive-stamp envelope of its box, taken
    /// before any of its records is mapped. A payload that is no records datagram adds no
    /// point (the decoder counts it).
    ///
    /// A status datagram tells the box's boot id; the acknowledgement of a read-tick command
    /// whose host time is its send time on this clock (as `skinbox capture` sends them) is
    /// an exchange for the box's map ([`Timing::exchange`]), once its boot id is known.
    pub fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        if skinbox_protocol::command::peek_kind(payload)
            == Some(skinbox_protocol::command::KIND_ACK)
        {
            self.acknowledgement(receive, source, payload);
            return;
        }
        let Ok(d) = Datagram::new_checked(payload) else {
            return;
        };
        let key = BoxKey {
            box_id: d.box_id(),
            source,
        };
        if d.kind() == DatagramKind::Status {
            self.box_syncs.insert(
                key,
                d.flags() & skinbox_protocol::datagram::FLAG_TIME_SYNCS != 0,
            );
            if let Ok(skinbox_protocol::DatagramRepr {
                body: skinbox_protocol::datagram::DatagramBody::Status(status),
                ..
            }) = skinbox_protocol::DatagramRepr::parse(payload)
            {
                self.boot_ids.insert(key, status.boot_id);
            }
            return;
        }
        let Some(receive) = receive else {
            return;
        };
        if d.kind() != DatagramKind::Records {
            return;
        }
        let base = d.base_tick();
        let latest = d
            .records()
            .map(|r| base.saturating_add_signed(i64::from(r.tick_offset())))
            .max();
        if let Some(tick) = latest {
            self.receive
                .get_or_insert_with(key, ReceiveStampMap::default)
                .push(tick, receive.as_nanos() as u64);
        }
    }

    /// A read-tick acknowledgement received at `receive`: an exchange, if it is one.
    fn acknowledgement(
        &mut self,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        use skinbox_protocol::command::{AckRepr, AckResult, Opcode};
        let Ok(ack) = AckRepr::parse(payload) else {
            return;
        };
        if ack.opcode != Opcode::ReadTick as u8 || ack.result != AckResult::Ok {
            return;
        }
        let key = BoxKey {
            box_id: ack.box_id,
            source,
        };
        let (Some(receive), Some(&boot_id)) = (receive, self.boot_ids.get(&key)) else {
            self.exchanges_unused += 1;
            return;
        };
        let host_send_ns = match self
            .send_stamps
            .as_ref()
            .map(|s| s.take_waiting(ack.host_time, SEND_STAMP_WAIT))
        {
            Some(Some(Ok(stamp))) => {
                self.exchange_stamps.kernel += 1;
                stamp
            }
            fell_back => {
                self.exchange_stamps.user_space += 1;
                let why = match fell_back {
                    Some(Some(Err(why))) => Some(why.name()),
                    Some(None) => Some("not_recorded"),
                    _ => None,
                };
                if let Some(why) = why {
                    *self.exchange_stamps.fallbacks.entry(why).or_insert(0) += 1;
                }
                ack.host_time
            }
        };
        let exchange = TimeExchange {
            host_send_ns,
            box_receive_tick: ack.receive_tick,
            box_send_tick: ack.send_tick,
            host_receive_ns: receive.as_nanos() as u64,
        };
        if self.exchange_for(key, boot_id, exchange).is_err() {
            self.exchanges_unused += 1;
        }
    }

    /// Read-tick acknowledgements not used for a map (no boot id seen yet for the box, or
    /// an exchange that cannot be true).
    pub fn exchanges_unused(&self) -> u64 {
        self.exchanges_unused
    }

    /// An exchange with box `box_id` of boot id `boot_id` (from the box's "read tick"
    /// command); its map then takes precedence over receive timestamps.
    pub fn exchange(
        &mut self,
        box_id: u16,
        boot_id: u32,
        exchange: TimeExchange,
    ) -> Result<(), crate::clock_map::ExchangeError> {
        let key = BoxKey {
            box_id,
            source: None,
        };
        self.exchange_for(key, boot_id, exchange)
    }

    /// [`Timing::exchange`] with the box `key` (box id and source address).
    pub fn exchange_for(
        &mut self,
        key: BoxKey,
        boot_id: u32,
        exchange: TimeExchange,
    ) -> Result<(), crate::clock_map::ExchangeError> {
        self.exchanges
            .get_or_insert_with(key, ClockMap::default)
            .push(boot_id, exchange)
    }

    /// How each box's time is mapped, by box id and source address.
    pub fn summary(&self) -> Vec<BoxTimeSummary> {
        let mut ids: Vec<BoxKey> = self
            .exchanges
            .keys()
            .chain(self.receive.keys())
            .copied()
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids.into_iter()
            .map(
                |key| match (self.exchanges.get(&key), self.receive.get(&key)) {
                    (Some(m), _) if m.boot_id().is_some() => BoxTimeSummary {
                        box_id: key.box_id,
                        address: key.source,
                        source: HostTimeSource::Exchanges,
                        drift_ppm: m.drift_ppm(),
                        error_bound_ns: m.last_bound_ns(),
                        restarts: m.restarts(),
                    },
                    (_, Some(r)) => BoxTimeSummary {
                        box_id: key.box_id,
                        address: key.source,
                        source: HostTimeSource::ReceiveStamps,
                        drift_ppm: r.drift_ppm(),
                        error_bound_ns: None,
                        restarts: r.restarts(),
                    },
                    _ => BoxTimeSummary {
                        box_id: key.box_id,
                        address: key.source,
                        source: HostTimeSource::None,
                        drift_ppm: None,
                        error_bound_ns: None,
                        restarts: 0,
                    },
                },
            )
            .collect()
    }

    /// The times of `record` (records in datagram order).
    pub fn record(&mut self, record: &DecodedRecord) -> RecordTimes {
        let stamp_ns = record.tick * skinbox_protocol::TICK_NS;
        let key = BoxKey {
            box_id: record.box_id,
            source: record.source,
        };
        let cell_id = record.cell.cell_id();
        let synced = match self.mode {
            SampleTimeMode::Synced => true,
            SampleTimeMode::Estimated => false,
            SampleTimeMode::Auto => self.box_syncs.get(&key) == Some(&true),
        };
        let (sample, method, bound) = if synced {
            self.method_counts.synced += 1;
            let sample = self.samples.grid_point(cell_id, stamp_ns);
            (sample, SampleMethod::Synced, self.synced_bound_ns)
        } else {
            self.method_counts.estimated += 1;
            let sample = self.samples.push_for(key, record.port, cell_id, stamp_ns);
            // the sample lies between the stamp less the path latency (no queue) and that
            // less the longest queueing, and a tick before the stamp's rounding
            let latest = (stamp_ns + skinbox_protocol::TICK_NS) as f64
                - self.samples.paths().latency_ns(cell_id) as f64;
            let earliest = latest - self.queue_bound_ns - skinbox_protocol::TICK_NS as f64;
            let bound = (sample.sample_time_ns - earliest)
                .abs()
                .max((latest - sample.sample_time_ns).abs());
            (sample, SampleMethod::Estimated, bound)
        };
        // bounds only where each cell's path latency is known (its hops to the root)
        let sample_bound = match self.samples.paths().hops {
            crate::sample_clock::Positions::Unknown => f64::NAN,
            _ => bound,
        };
        let sample_box_ns = sample.sample_time_ns;
        let (host, source) = match self
            .exchanges
            .get(&key)
            .and_then(|m| m.ns_to_host(sample_box_ns))
        {
            Some(h) => (Some(h), HostTimeSource::Exchanges),
            None => match self.receive.get(&key).and_then(|m| {
                // The receive map is linear: the sample's host time is the stamp's less
                // the stamp-to-sample interval.
                m.to_host(record.tick).map(|h| HostTime {
                    host_ns: h.host_ns - (stamp_ns as f64 - sample_box_ns),
                    error_bound_ns: None,
                })
            }) {
                Some(h) => (Some(h), HostTimeSource::ReceiveStamps),
                None => (None, HostTimeSource::None),
            },
        };
        RecordTimes {
            sample_box_s: sample_box_ns * 1e-9,
            sample_box_ns,
            sample_index: sample.index,
            sample_host_ns: host.map(|h| h.host_ns),
            method,
            sample_error_bound_ns: sample_bound,
            host_error_bound_ns: host
                .and_then(|h| h.error_bound_ns)
                .map(|b| b + sample_bound)
                .filter(|b| !b.is_nan()),
            source,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::sample_clock::Positions;
    use skinbox_protocol::{CellRepr, DataRepr};

    fn record(box_id: u16, cell: u16, tick: u64) -> DecodedRecord {
        DecodedRecord {
            box_id,
            source: None,
            datagram_sequence: 0,
            port: 0,
            flags: 0,
            tick,
            cell: CellRepr::Data(DataRepr::from_raw(cell, [0; 9]).unwrap()),
            event_packets_missing_before: 0,
        }
    }

    /// A records datagram of box `box_id` holding one record of `cell` at each tick.
    pub(crate) fn datagram(box_id: u16, cell: u16, ticks: &[u64]) -> Vec<u8> {
        use skinbox_protocol::datagram::DatagramBody;
        use skinbox_protocol::{DatagramRepr, RecordRepr};
        let base = ticks.iter().copied().min().unwrap_or(0);
        DatagramRepr {
            box_id,
            port_count: 1,
            flags: 0,
            sequence: 0,
            base_tick: base,
            body: DatagramBody::Records(
                ticks
                    .iter()
                    .map(|&t| RecordRepr {
                        port: 0,
                        flags: 0,
                        tick_offset: (t - base) as i32,
                        cell_packet: DataRepr::from_raw(cell, [0; 9]).unwrap().to_bytes(),
                    })
                    .collect(),
            ),
        }
        .to_bytes()
    }

    #[test]
    fn two_boxes_land_on_one_host_time_line() {
        // Box 1 was reset 10 s before box 2 (host clock): the same host instant is 10 s
        // more box time on box 1. Each datagram is received 40 us after its latest record
        // (100 us after the first).
        let mut t = Timing::new(250.0, PathModel::bus_model(Positions::Unknown));
        let host_ns = 100_000_000_000u64;
        for (box_id, box_ns) in [(1u16, 30_000_000_000u64), (2, 20_000_000_000)] {
            let ticks = [box_ns / 8, (box_ns + 60_000) / 8];
            let payload = datagram(box_id, 5, &ticks);
            t.datagram_received(
                Some(Duration::from_nanos(host_ns + 100_000)),
                None,
                &payload,
            );
            let times = t.record(&record(box_id, 5, box_ns / 8));
            // Sample 20 us (processing) before the stamp, host time 40 us late.
            let expected = (host_ns - 20_000 + 40_000) as f64;
            let got = times.sample_host_ns.unwrap();
            assert!(
                (got - expected).abs() < 1.0,
                "box {box_id}: {got} vs {expected}"
            );
            assert_eq!(times.source, HostTimeSource::ReceiveStamps);
            assert_eq!(times.host_error_bound_ns, None);
        }
    }

    #[test]
    fn a_box_that_says_it_sends_time_syncs_has_its_records_on_its_grid() {
        use skinbox_protocol::datagram::FLAG_TIME_SYNCS;
        // one cell a bus: every cell is a root, its path latency the 20 us of processing
        let roots = || PathModel::bus_model(Positions::Numbered { cells_per_bus: 1 });
        let mut t = Timing::new(250.0, roots());
        t.datagram_received(None, None, &status_with_flags(1, 7, FLAG_TIME_SYNCS));
        t.datagram_received(None, None, &status_with_flags(2, 7, 0));
        // sampled at 4 ms, 20 us of processing, 3 us in the root's queue
        let true_ns = 4_000_000.0;
        let stamp_tick = (4_000_000 + 20_000 + 3_000) / 8;
        let synced = t.record(&record(1, 5, stamp_tick));
        assert_eq!(synced.method, SampleMethod::Synced);
        assert_eq!(synced.sample_box_ns, true_ns);
        assert_eq!(synced.sample_error_bound_ns, SYNCED_SAMPLE_BOUND_NS);
        // box 2 sends no syncs: an estimate, its bound the bus's queueing
        let estimated = t.record(&record(2, 5, stamp_tick));
        assert_eq!(estimated.method, SampleMethod::Estimated);
        assert!((estimated.sample_box_ns - true_ns).abs() <= estimated.sample_error_bound_ns);
        assert!(estimated.sample_error_bound_ns <= ROOT_QUEUE_BOUND_NS + 16.0);
        assert!(estimated.sample_error_bound_ns >= ROOT_QUEUE_BOUND_NS - 3_000.0);
        // box 1 stops sending syncs: its records are estimated from then on
        t.datagram_received(None, None, &status_with_flags(1, 7, 0));
        let after = t.record(&record(1, 5, stamp_tick + 500_000));
        assert_eq!(after.method, SampleMethod::Estimated);
        assert_eq!(
            t.method_counts(),
            SampleMethodCounts {
                synced: 1,
                estimated: 2
            }
        );
        // forced either way, whatever the status says
        let mut forced = Timing::new(250.0, roots()).with_mode(SampleTimeMode::Estimated);
        forced.datagram_received(None, None, &status_with_flags(1, 7, FLAG_TIME_SYNCS));
        assert_eq!(
            forced.record(&record(1, 5, stamp_tick)).method,
            SampleMethod::Estimated
        );
        let mut forced = Timing::new(250.0, roots()).on_box_grid();
        assert_eq!(
            forced.record(&record(1, 5, stamp_tick)).method,
            SampleMethod::Synced
        );
        // where the cells' hops are unknown nothing bounds their path latency: no bounds
        let unknown = || PathModel::bus_model(Positions::Unknown);
        for mut t in [
            Timing::new(250.0, unknown()),
            Timing::new(250.0, unknown()).on_box_grid(),
        ] {
            assert!(t
                .record(&record(1, 5, stamp_tick))
                .sample_error_bound_ns
                .is_nan());
        }
    }

    #[test]
    fn exchanges_take_precedence_and_carry_their_bound() {
        let paths = PathModel::bus_model(Positions::Numbered { cells_per_bus: 1 });
        let mut t = Timing::new(250.0, paths);
        t.exchange(
            3,
            9,
            TimeExchange {
                host_send_ns: 1_000_000,
                box_receive_tick: 1_000,
                box_send_tick: 1_001,
                host_receive_ns: 1_100_008,
            },
        )
        .unwrap();
        t.datagram_received(None, None, &datagram(3, 1, &[10_000]));
        let times = t.record(&record(3, 1, 10_000));
        assert_eq!(times.source, HostTimeSource::Exchanges);
        // the mapping's bound (half the 100 us round trip and more) plus the sample's
        let map_bound = t.summary()[0].error_bound_ns.unwrap();
        assert!(map_bound >= 50_000.0);
        assert!(
            times.host_error_bound_ns.unwrap() >= map_bound + times.sample_error_bound_ns - 1.0
        );
        assert_eq!(
            Timing::new(250.0, PathModel::bus_model(Positions::Unknown))
                .record(&record(3, 1, 10_000))
                .source,
            HostTimeSource::None
        );
    }

    fn status(box_id: u16, boot_id: u32) -> Vec<u8> {
        status_with_flags(box_id, boot_id, 0)
    }

    fn status_with_flags(box_id: u16, boot_id: u32, flags: u8) -> Vec<u8> {
        use skinbox_protocol::datagram::DatagramBody;
        use skinbox_protocol::{DatagramRepr, StatusRepr};
        DatagramRepr {
            box_id,
            port_count: 1,
            flags,
            sequence: 0,
            base_tick: 0,
            body: DatagramBody::Status(StatusRepr {
                boot_id,
                datagrams_sent: 0,
                records_sent: 0,
                first_port: 0,
                ports: vec![Default::default()],
            }),
        }
        .to_bytes()
    }

    fn read_tick_ack(box_id: u16, host_send_ns: u64, tick: u64) -> Vec<u8> {
        ack(
            box_id,
            host_send_ns,
            tick,
            skinbox_protocol::command::Opcode::ReadTick,
        )
    }

    fn ack(
        box_id: u16,
        host_send_ns: u64,
        tick: u64,
        opcode: skinbox_protocol::command::Opcode,
    ) -> Vec<u8> {
        use skinbox_protocol::command::{AckReply, AckRepr, AckResult};
        AckRepr {
            box_id,
            port_count: 1,
            sequence: 1,
            host_time: host_send_ns,
            opcode: opcode as u8,
            result: AckResult::Ok,
            last_accepted: 1,
            receive_tick: tick,
            send_tick: tick + 100,
            reply: AckReply::None,
        }
        .to_bytes()
    }

    #[test]
    fn read_tick_acknowledgements_are_exchanges_once_the_boot_id_is_known() {
        let mut t = Timing::new(
            250.0,
            PathModel::bus_model(Positions::Numbered { cells_per_bus: 1 }),
        );
        let at = |ns: u64| Some(Duration::from_nanos(ns));
        // before any status datagram: no boot id, not used
        t.datagram_received(at(2_000_000), None, &read_tick_ack(3, 1_000_000, 1_000));
        assert_eq!(t.exchanges_unused(), 1);
        assert!(t.summary().is_empty(), "no map yet");
        t.datagram_received(at(2_500_000), None, &status(3, 9));
        // host sent at 3.00 ms, the box took it at tick 20,000, answered 800 ns later, the
        // answer arrived 20 us after it left
        t.datagram_received(at(3_020_800), None, &read_tick_ack(3, 3_000_000, 20_000));
        assert_eq!(t.exchanges_unused(), 1);
        let s = &t.summary()[0];
        assert_eq!((s.source, s.restarts), (HostTimeSource::Exchanges, 0));
        // a record's sample maps within the bound of the exchange's midpoint offset (host
        // 3,010,400 ns at box 160,400 ns: host time = box time + 2.85 ms)
        t.datagram_received(None, None, &datagram(3, 1, &[20_000]));
        let times = t.record(&record(3, 1, 20_000));
        let mapped = times.sample_host_ns.unwrap();
        let truth = times.sample_box_s * 1e9 + 2_850_000.0;
        assert!((mapped - truth).abs() <= times.host_error_bound_ns.unwrap() + 1.0);
        // a new boot id: the next exchange starts the map over
        t.datagram_received(at(4_000_000), None, &status(3, 10));
        t.datagram_received(at(5_020_800), None, &read_tick_ack(3, 5_000_000, 1_000));
        assert_eq!(t.summary()[0].restarts, 1);
        // an acknowledgement of another command is no exchange
        let other = ack(
            3,
            6_000_000,
            2_000,
            skinbox_protocol::command::Opcode::StatusNow,
        );
        let before = t.exchanges_unused();
        t.datagram_received(at(6_020_000), None, &other);
        assert_eq!(t.exchanges_unused(), before);
    }

    #[test]
    fn an_exchange_takes_its_commands_kernel_send_stamp_or_counts_why_not() {
        use crate::kernel_stamps::{CommandSendStamps, Fallback};
        let stamps = CommandSendStamps::new();
        let mut t = Timing::new(250.0, PathModel::bus_model(Positions::Unknown))
            .with_send_stamps(stamps.clone());
        let at = |ns: u64| Some(Duration::from_nanos(ns));
        t.datagram_received(at(2_500_000), None, &status(3, 9));
        // the command carried 3.000 ms; the kernel sent it at 3.004 ms: the exchange's
        // round trip is 16.8 us less, its offset 2 us later
        stamps.record(3_000_000, Ok(3_004_000));
        t.datagram_received(at(3_020_800), None, &read_tick_ack(3, 3_000_000, 20_000));
        assert_eq!(t.exchange_stamps().kernel, 1);
        assert_eq!(t.exchange_stamps().name(), "kernel");
        let bound = t.summary()[0].error_bound_ns.unwrap();
        assert!(
            (bound - 8_000.0).abs() <= 1.0,
            "half of 16.8 - 0.8 us: {bound}"
        );
        // no stamp recorded, and one that says why: the user-space send time, counted
        stamps.record(4_000_000, Err(Fallback::NoSendStamp));
        t.datagram_received(at(4_020_800), None, &read_tick_ack(3, 4_000_000, 145_000));
        t.datagram_received(at(5_020_800), None, &read_tick_ack(3, 5_000_000, 270_000));
        let counts = t.exchange_stamps();
        assert_eq!((counts.kernel, counts.user_space), (1, 2));
        assert_eq!(counts.name(), "mixed");
        assert_eq!(counts.fallbacks.get("no_send_stamp"), Some(&1));
        assert_eq!(counts.fallbacks.get("not_recorded"), Some(&1));
        // without send stamps asked for, nothing is a fallback
        let mut plain = Timing::new(250.0, PathModel::bus_model(Positions::Unknown));
        plain.datagram_received(at(2_500_000), None, &status(3, 9));
        plain.datagram_received(at(3_020_800), None, &read_tick_ack(3, 3_000_000, 20_000));
        assert_eq!(plain.exchange_stamps().user_space, 1);
        assert!(plain.exchange_stamps().fallbacks.is_empty());
    }
}
