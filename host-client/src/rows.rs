//! Records and samples as fixed-layout rows, written by [`RecordSink`]s straight into
//! memory the caller owns: the Python package's numpy arrays are these rows
//! (`python/`, docs/python.md). Every field is the one `skinbox decode --jsonl` prints,
//! from the same decoder and the same [`Timing`].
//!
//! [`RECORD_FIELDS`] and [`SAMPLE_FIELDS`] name each field with its numpy type and byte
//! offset, so a structured dtype can be built over the rows without re-typing the layout.

use crate::convert::Sample;
use crate::decoder::{DecodedRecord, RecordSink};
use crate::timing::{HostTimeSource, RecordTimes, SampleMethod, Timing};
use core::mem::offset_of;
use skinbox_protocol::{CellRepr, Channel, ChannelMask};
use std::time::Duration;

/// [`RecordRow::kind`] of a data packet.
pub const KIND_DATA: u8 = 0;
/// [`RecordRow::kind`] of an event packet.
pub const KIND_EVENT: u8 = 1;

/// `host_time_source` of a row without host time.
pub const HOST_TIME_NONE: u8 = 0;
/// `host_time_source` of a row timed by the datagrams' receive timestamps.
pub const HOST_TIME_RECEIVE_STAMPS: u8 = 1;
/// `host_time_source` of a row timed by exchanges with the box.
pub const HOST_TIME_EXCHANGES: u8 = 2;

/// The code of a host time source in rows.
pub fn host_time_source_code(source: HostTimeSource) -> u8 {
    match source {
        HostTimeSource::None => HOST_TIME_NONE,
        HostTimeSource::ReceiveStamps => HOST_TIME_RECEIVE_STAMPS,
        HostTimeSource::Exchanges => HOST_TIME_EXCHANGES,
    }
}

/// One decoded record (a cell packet) with its times.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RecordRow {
    /// 64-bit box tick (8 ns) of the packet's first start bit.
    pub tick: u64,
    /// The same in ns of box time.
    pub box_time_ns: u64,
    /// Estimated box time of the packet's sample, ns.
    pub sample_box_time_ns: f64,
    /// The sample's host time, ns on the host clock, rounded (0 without one: see
    /// `host_time_source`).
    pub host_time_ns: i64,
    /// The host time's error bound, ns (NaN where the mapping has none).
    pub host_time_bound_ns: f64,
    /// The cell's sample index on its sample clock.
    pub sample_index: i64,
    /// The nine channels in physical units; NaN where an event packet has no value.
    pub values: [f64; Channel::COUNT],
    /// Sequence number of the datagram that carried it.
    pub datagram_sequence: u32,
    /// The cell's event sequence number (-1 for a data packet).
    pub event_sequence: i32,
    /// IPv4 source address of the box's datagram, as an integer (`u32::from(Ipv4Addr)`);
    /// 0 where unknown or not IPv4 (see [`source_fields`]).
    pub source_ip: u32,
    /// Box that sent it.
    pub box_id: u16,
    /// The cell.
    pub cell_id: u16,
    /// Channels present in `values`, bit `i` for channel `i` (all nine for data).
    pub mask: u16,
    /// Event packets of this cell missing just before this one.
    pub event_packets_missing_before: u16,
    /// UDP source port of the box's datagram (0 where unknown).
    pub source_port: u16,
    /// UART port of the box.
    pub port: u8,
    /// [`KIND_DATA`] or [`KIND_EVENT`].
    pub kind: u8,
    /// Record flags (`FLAG_LOSS_BEFORE`).
    pub flags: u8,
    /// 1 for the second packet of a split event sample.
    pub second_part: u8,
    /// [`HOST_TIME_NONE`], [`HOST_TIME_RECEIVE_STAMPS`] or [`HOST_TIME_EXCHANGES`].
    pub host_time_source: u8,
}

/// A datagram's source address as the rows' `source_ip` and `source_port`: the IPv4
/// address as an integer (an IPv4-mapped IPv6 address as its IPv4 one) and the port; both 0
/// where the source is unknown, and the address 0 for other IPv6 sources (the box speaks
/// IPv4).
pub fn source_fields(source: Option<std::net::SocketAddr>) -> (u32, u16) {
    match source {
        None => (0, 0),
        Some(std::net::SocketAddr::V4(a)) => (u32::from(*a.ip()), a.port()),
        Some(std::net::SocketAddr::V6(a)) => {
            (a.ip().to_ipv4_mapped().map_or(0, u32::from), a.port())
        }
    }
}

/// `v.round()`, without the library call where `v` is an integer already: every `f64` of
/// magnitude 2^52 or more is one, as host times in ns since 1970 are.
#[inline]
fn round(v: f64) -> f64 {
    if v.abs() >= 4_503_599_627_370_496.0 {
        v
    } else {
        v.round()
    }
}

/// A record's host time fields as the rows carry them: the host time in ns, rounded (0
/// without one), its error bound in ns, rounded (NaN without one), and its source's code
/// ([`host_time_source_code`]).
#[inline]
pub fn host_time(times: &RecordTimes) -> (i64, f64, u8) {
    (
        times.sample_host_ns.map_or(0, |v| round(v) as i64),
        times.host_error_bound_ns.map_or(f64::NAN, round),
        host_time_source_code(times.source),
    )
}

impl RecordRow {
    /// The row of `record` with its `times`.
    #[inline]
    pub fn new(record: &DecodedRecord, times: &RecordTimes) -> RecordRow {
        let mut values = [f64::NAN; Channel::COUNT];
        let (kind, mask, event_sequence, second_part) = match &record.cell {
            CellRepr::Data(d) => {
                for c in Channel::ALL {
                    values[c.index()] = c.to_units(d.raw(c));
                }
                (KIND_DATA, ChannelMask::ALL.bits(), -1, 0)
            }
            CellRepr::Event(e) => {
                for (c, raw) in e.events() {
                    values[c.index()] = c.to_units(raw);
                }
                (
                    KIND_EVENT,
                    e.channels.bits(),
                    i32::from(e.sequence),
                    u8::from(e.second_part),
                )
            }
        };
        let (host_time_ns, host_time_bound_ns, host_time_source) = host_time(times);
        let (source_ip, source_port) = source_fields(record.source);
        RecordRow {
            tick: record.tick,
            box_time_ns: record.tick.wrapping_mul(skinbox_protocol::TICK_NS),
            sample_box_time_ns: times.sample_box_ns,
            host_time_ns,
            host_time_bound_ns,
            sample_index: times.sample_index,
            values,
            datagram_sequence: record.datagram_sequence,
            event_sequence,
            source_ip,
            box_id: record.box_id,
            cell_id: record.cell.cell_id(),
            mask,
            event_packets_missing_before: record.event_packets_missing_before,
            source_port,
            port: record.port,
            kind,
            flags: record.flags,
            second_part,
            host_time_source,
        }
    }
}

/// One full sample of a cell after a packet (event to data), with its times.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SampleRow {
    /// Box tick of the packet that produced the sample.
    pub tick: u64,
    /// The same in ns of box time.
    pub box_time_ns: u64,
    /// Estimated box time of the sample, ns.
    pub sample_box_time_ns: f64,
    /// The sample's host time, ns on the host clock, rounded (0 without one).
    pub host_time_ns: i64,
    /// The host time's error bound, ns (NaN where the mapping has none).
    pub host_time_bound_ns: f64,
    /// The cell's sample index on its sample clock.
    pub sample_index: i64,
    /// The nine channels in physical units (0 where never received: see `known`).
    pub values: [f64; Channel::COUNT],
    /// IPv4 source address of the box, as in [`RecordRow::source_ip`].
    pub source_ip: u32,
    /// Box the cell is on.
    pub box_id: u16,
    /// The cell.
    pub cell_id: u16,
    /// Channels this packet carried.
    pub updated: u16,
    /// Channels not refreshed since an event sequence gap of the cell.
    pub stale: u16,
    /// Channels received at least once.
    pub known: u16,
    /// UDP source port of the box (0 where unknown).
    pub source_port: u16,
    /// [`HOST_TIME_NONE`], [`HOST_TIME_RECEIVE_STAMPS`] or [`HOST_TIME_EXCHANGES`].
    pub host_time_source: u8,
}

impl SampleRow {
    /// The row of `sample` with the times of the record that produced it.
    #[inline]
    pub fn new(sample: &Sample, times: &RecordTimes) -> SampleRow {
        let mut values = [0.0; Channel::COUNT];
        for c in Channel::ALL {
            values[c.index()] = sample.value(c);
        }
        let (host_time_ns, host_time_bound_ns, host_time_source) = host_time(times);
        let (source_ip, source_port) = source_fields(sample.source);
        SampleRow {
            tick: sample.tick,
            box_time_ns: sample.tick.wrapping_mul(skinbox_protocol::TICK_NS),
            sample_box_time_ns: times.sample_box_ns,
            host_time_ns,
            host_time_bound_ns,
            sample_index: times.sample_index,
            values,
            source_ip,
            box_id: sample.box_id,
            cell_id: sample.cell_id,
            updated: sample.updated.bits(),
            stale: sample.stale.bits(),
            known: sample.known.bits(),
            source_port,
            host_time_source,
        }
    }
}

/// A field of a row: name, numpy type (little-endian; a `(9,)` prefix for the channels)
/// and byte offset.
pub type RowField = (&'static str, &'static str, usize);

/// The fields of [`RecordRow`], in memory order.
pub const RECORD_FIELDS: &[RowField] = &[
    ("tick", "<u8", offset_of!(RecordRow, tick)),
    ("box_time_ns", "<u8", offset_of!(RecordRow, box_time_ns)),
    (
        "sample_box_time_ns",
        "<f8",
        offset_of!(RecordRow, sample_box_time_ns),
    ),
    ("host_time_ns", "<i8", offset_of!(RecordRow, host_time_ns)),
    (
        "host_time_bound_ns",
        "<f8",
        offset_of!(RecordRow, host_time_bound_ns),
    ),
    ("sample_index", "<i8", offset_of!(RecordRow, sample_index)),
    ("values", "(9,)<f8", offset_of!(RecordRow, values)),
    (
        "datagram_sequence",
        "<u4",
        offset_of!(RecordRow, datagram_sequence),
    ),
    (
        "event_sequence",
        "<i4",
        offset_of!(RecordRow, event_sequence),
    ),
    ("source_ip", "<u4", offset_of!(RecordRow, source_ip)),
    ("box_id", "<u2", offset_of!(RecordRow, box_id)),
    ("cell_id", "<u2", offset_of!(RecordRow, cell_id)),
    ("mask", "<u2", offset_of!(RecordRow, mask)),
    (
        "event_packets_missing_before",
        "<u2",
        offset_of!(RecordRow, event_packets_missing_before),
    ),
    ("source_port", "<u2", offset_of!(RecordRow, source_port)),
    ("port", "u1", offset_of!(RecordRow, port)),
    ("kind", "u1", offset_of!(RecordRow, kind)),
    ("flags", "u1", offset_of!(RecordRow, flags)),
    ("second_part", "u1", offset_of!(RecordRow, second_part)),
    (
        "host_time_source",
        "u1",
        offset_of!(RecordRow, host_time_source),
    ),
];

/// The fields of [`SampleRow`], in memory order.
pub const SAMPLE_FIELDS: &[RowField] = &[
    ("tick", "<u8", offset_of!(SampleRow, tick)),
    ("box_time_ns", "<u8", offset_of!(SampleRow, box_time_ns)),
    (
        "sample_box_time_ns",
        "<f8",
        offset_of!(SampleRow, sample_box_time_ns),
    ),
    ("host_time_ns", "<i8", offset_of!(SampleRow, host_time_ns)),
    (
        "host_time_bound_ns",
        "<f8",
        offset_of!(SampleRow, host_time_bound_ns),
    ),
    ("sample_index", "<i8", offset_of!(SampleRow, sample_index)),
    ("values", "(9,)<f8", offset_of!(SampleRow, values)),
    ("source_ip", "<u4", offset_of!(SampleRow, source_ip)),
    ("box_id", "<u2", offset_of!(SampleRow, box_id)),
    ("cell_id", "<u2", offset_of!(SampleRow, cell_id)),
    ("updated", "<u2", offset_of!(SampleRow, updated)),
    ("stale", "<u2", offset_of!(SampleRow, stale)),
    ("known", "<u2", offset_of!(SampleRow, known)),
    ("source_port", "<u2", offset_of!(SampleRow, source_port)),
    (
        "host_time_source",
        "u1",
        offset_of!(SampleRow, host_time_source),
    ),
];

/// The times of a row written without a [`Timing`]: no sample time (NaN, index -1), no
/// host time.
pub const UNTIMED: RecordTimes = RecordTimes {
    sample_box_s: f64::NAN,
    sample_box_ns: f64::NAN,
    sample_index: -1,
    sample_host_ns: None,
    method: SampleMethod::Estimated,
    sample_error_bound_ns: f64::NAN,
    host_error_bound_ns: None,
    source: HostTimeSource::None,
};

/// An upper bound of the records a capture of `capture_bytes` bytes holds: each takes at
/// least [`skinbox_protocol::record::RECORD_LEN`] bytes of it.
pub fn max_records(capture_bytes: usize) -> usize {
    capture_bytes / skinbox_protocol::record::RECORD_LEN
}

/// A [`RecordSink`] writing one [`RecordRow`] per record (or, with samples, one
/// [`SampleRow`] per sample) into a slice the caller allocated, in decoding order, with the
/// times of `timing` (or [`UNTIMED`]). Rows beyond the slice are counted in
/// [`RowWriter::beyond`], not written.
///
/// This is the one record path into rows: `read` fills one slice with it, and the Python
/// package's `Reader` fills its reused buffer batch by batch, handing the slice over when
/// [`RowWriter::is_full`] and going on in the next with [`RowWriter::retarget`].
pub struct RowWriter<'a, R> {
    rows: &'a mut [R],
    written: usize,
    beyond: u64,
    timing: Option<Timing>,
    last_times: RecordTimes,
}

impl<'a, R> RowWriter<'a, R> {
    /// A writer into `rows` from the first, with the sample and host times of `timing`
    /// (`None`: [`UNTIMED`], and no time estimation cost).
    pub fn new(rows: &'a mut [R], timing: Option<Timing>) -> Self {
        RowWriter {
            rows,
            written: 0,
            beyond: 0,
            timing,
            last_times: UNTIMED,
        }
    }

    #[inline]
    fn times(&mut self, record: &DecodedRecord) -> RecordTimes {
        match &mut self.timing {
            Some(t) => t.record(record),
            None => UNTIMED,
        }
    }

    /// Rows written.
    pub fn written(&self) -> usize {
        self.written
    }

    /// Rows that did not fit.
    pub fn beyond(&self) -> u64 {
        self.beyond
    }

    /// Whether every row of the slice is written: the next row would only be counted in
    /// [`RowWriter::beyond`]. True of an empty slice.
    #[inline]
    pub fn is_full(&self) -> bool {
        self.written == self.rows.len()
    }

    /// Goes on writing into `rows` from its first row, releasing the slice before it, and
    /// returns the rows written into that one. Everything else carries over as if the one
    /// slice went on in the other: the timing's state, the times of the last record (for
    /// the samples it still produces) and [`RowWriter::beyond`]; the rows are those that
    /// one slice of both lengths would hold. An empty `rows` only releases the slice: rows
    /// are then counted in [`RowWriter::beyond`], their times still estimated.
    pub fn retarget(&mut self, rows: &'a mut [R]) -> usize {
        self.swap_rows(rows).len()
    }

    /// As [`RowWriter::retarget`], returning the rows written into the slice before (the
    /// rest of it released) rather than their count: for a caller that hands them on, as
    /// the Python package's `read` hands each part of its array to the thread that fills in
    /// the rows' times.
    pub fn swap_rows(&mut self, rows: &'a mut [R]) -> &'a mut [R] {
        let before = std::mem::replace(&mut self.rows, rows);
        let written = std::mem::replace(&mut self.written, 0);
        before.split_at_mut(written).0
    }

    /// The timing, for its summary.
    pub fn timing(&self) -> Option<&Timing> {
        self.timing.as_ref()
    }

    /// The timing, the slice released.
    pub fn into_timing(self) -> Option<Timing> {
        self.timing
    }

    #[inline]
    fn put(&mut self, row: R) {
        match self.rows.get_mut(self.written) {
            Some(slot) => {
                *slot = row;
                self.written += 1;
            }
            None => self.beyond += 1,
        }
    }
}

impl RecordSink for RowWriter<'_, RecordRow> {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        let times = self.times(record);
        self.put(RecordRow::new(record, &times));
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        if let Some(t) = &mut self.timing {
            t.datagram_received(receive, source, payload);
        }
    }
}

impl RecordSink for RowWriter<'_, SampleRow> {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        self.last_times = self.times(record);
    }

    fn wants_samples(&self) -> bool {
        true
    }

    #[inline]
    fn sample(&mut self, sample: &Sample) {
        let times = self.last_times;
        self.put(SampleRow::new(sample, &times));
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        if let Some(t) = &mut self.timing {
            t.datagram_received(receive, source, payload);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sample_clock::{PathModel, Positions};
    use skinbox_protocol::{DataRepr, EventRepr};

    #[test]
    fn fields_cover_each_row_without_overlap() {
        let size = |t: &str| -> usize {
            let n: usize = t[t.len() - 1..].parse().unwrap();
            if t.starts_with("(9,)") {
                9 * n
            } else {
                n
            }
        };
        for (fields, row_size) in [
            (RECORD_FIELDS, std::mem::size_of::<RecordRow>()),
            (SAMPLE_FIELDS, std::mem::size_of::<SampleRow>()),
        ] {
            let mut end = 0;
            for (name, t, offset) in fields {
                assert!(*offset >= end, "{name} overlaps the field before it");
                end = offset + size(t);
            }
            assert!(end <= row_size && row_size - end < 8, "{end} of {row_size}");
        }
    }

    #[test]
    fn round_is_f64_round() {
        for v in [
            0.5,
            -0.5,
            1.5,
            2.5,
            -2.5,
            4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
            1.795e18,
            -1.795e18,
            f64::INFINITY,
        ] {
            assert_eq!(round(v), v.round(), "{v}");
        }
        assert!(round(f64::NAN).is_nan());
    }

    #[test]
    fn rows_name_the_source_address_of_their_box() {
        use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
        let v4 = SocketAddr::from(([192, 0, 2, 10], 54_091));
        assert_eq!(source_fields(Some(v4)), (0xC000_020A, 54_091));
        let mapped = SocketAddr::from((Ipv4Addr::new(10, 1, 2, 3).to_ipv6_mapped(), 7));
        assert_eq!(source_fields(Some(mapped)), (0x0A01_0203, 7));
        let v6 = SocketAddr::from((Ipv6Addr::LOCALHOST, 9));
        assert_eq!(source_fields(Some(v6)), (0, 9));
        assert_eq!(source_fields(None), (0, 0));
        let record = DecodedRecord {
            box_id: 4,
            source: Some(v4),
            datagram_sequence: 1,
            port: 2,
            flags: 0,
            tick: 100,
            cell: CellRepr::Data(DataRepr::from_raw(9, [0; 9]).unwrap()),
            event_packets_missing_before: 0,
        };
        let row = RecordRow::new(&record, &UNTIMED);
        assert_eq!(
            (row.box_id, Ipv4Addr::from(row.source_ip), row.source_port),
            (4, Ipv4Addr::new(192, 0, 2, 10), 54_091)
        );
    }

    #[test]
    fn rows_hold_units_masks_and_sequences() {
        let timing = Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
        let mut rows = [RecordRow::default(); 2];
        let mut w = RowWriter::new(&mut rows, Some(timing));
        let data = DataRepr::from_raw(17, [2, -3, 258, 1, 0, 2, 310, 61, 0]).unwrap();
        let event = EventRepr::new(17, 41, true, &[(Channel::Force1, 512)]).unwrap();
        for cell in [
            CellRepr::Data(data),
            CellRepr::Event(event),
            CellRepr::Data(data),
        ] {
            w.record(&DecodedRecord {
                box_id: 3,
                source: None,
                datagram_sequence: 9,
                port: 2,
                flags: 0,
                tick: 250_000_000,
                cell,
                event_packets_missing_before: 0,
            });
        }
        assert_eq!((w.written(), w.beyond()), (2, 1));
        let [d, e] = rows;
        assert_eq!((d.kind, d.mask, d.event_sequence), (KIND_DATA, 0x1FF, -1));
        assert_eq!(d.values[2], 258.0 / 256.0);
        assert_eq!(d.box_time_ns, 2_000_000_000);
        assert_eq!(
            (e.kind, e.mask, e.event_sequence, e.second_part),
            (KIND_EVENT, 1 << 3, 41, 1)
        );
        assert_eq!(e.values[3], 0.5);
        assert!(e.values[0].is_nan());
        assert_eq!((e.box_id, e.cell_id, e.port), (3, 17, 2));
        assert_eq!(e.host_time_source, HOST_TIME_NONE);
        assert!(e.host_time_bound_ns.is_nan());
    }

    #[test]
    fn a_retargeted_writer_writes_the_rows_of_one_slice() {
        let timing = || Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
        let records: Vec<DecodedRecord> = (0..5u16)
            .map(|i| DecodedRecord {
                box_id: 3,
                source: None,
                datagram_sequence: u32::from(i),
                port: 1,
                flags: 0,
                tick: 1_000_000 * u64::from(i + 1),
                cell: CellRepr::Data(DataRepr::from_raw(7, [i32::from(i); 9]).unwrap()),
                event_packets_missing_before: 0,
            })
            .collect();
        let mut whole = [RecordRow::default(); 5];
        let mut w = RowWriter::new(&mut whole, Some(timing()));
        records.iter().for_each(|r| w.record(r));
        assert_eq!((w.written(), w.beyond()), (5, 0));

        let (mut first, mut second) = ([RecordRow::default(); 2], [RecordRow::default(); 3]);
        let mut w = RowWriter::new(&mut [][..], Some(timing()));
        assert!(w.is_full());
        assert_eq!(w.retarget(&mut first), 0);
        let (mut counts, mut next) = (vec![], Some(&mut second[..]));
        for r in &records {
            if w.is_full() {
                counts.push(w.retarget(next.take().unwrap()));
            }
            w.record(r);
        }
        counts.push(w.retarget(&mut []));
        assert_eq!((counts, w.beyond()), (vec![2, 3], 0));
        // released, it counts rows and still times them
        w.record(&records[0]);
        assert_eq!((w.written(), w.beyond()), (0, 1));
        // (Debug, as the rows' NaN bounds are not equal to themselves)
        assert_eq!(
            format!("{:?}", [&first[..], &second[..]].concat()),
            format!("{whole:?}")
        );
    }

    #[test]
    fn untimed_rows_have_no_times_and_the_bound_holds_every_record() {
        let mut rows = [SampleRow::default(); 1];
        let mut w = RowWriter::new(&mut rows, None);
        let data = DataRepr::from_raw(5, [0; 9]).unwrap();
        let record = DecodedRecord {
            box_id: 1,
            source: None,
            datagram_sequence: 0,
            port: 0,
            flags: 0,
            tick: 8,
            cell: CellRepr::Data(data),
            event_packets_missing_before: 0,
        };
        w.record(&record);
        w.sample(&crate::EventToData::new().push(8, &record.cell, false));
        assert_eq!(w.written(), 1);
        assert!(rows[0].sample_box_time_ns.is_nan());
        assert_eq!((rows[0].sample_index, rows[0].host_time_ns), (-1, 0));
        assert_eq!(rows[0].host_time_source, HOST_TIME_NONE);
        // a datagram of one record in its frame: 24 + 26 bytes of payload and more
        assert_eq!(max_records(24 + 26), 1);
        assert_eq!(max_records(25), 0);
    }
}
