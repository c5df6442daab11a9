//! Decoded records and samples as CSV or JSON lines, in physical units with box time; with
//! [`RowWriter::with_timing`] also each sample's estimated box time and its host time
//! ([`crate::timing`]).

use crate::convert::Sample;
use crate::decoder::{DecodedRecord, RecordSink};
use crate::timing::{RecordTimes, Timing};
use skinbox_protocol::{CellRepr, Channel};
use std::io::{self, Write};

/// Text format of the rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowFormat {
    /// Comma-separated values with a header line.
    Csv,
    /// One JSON object per line.
    JsonLines,
}

/// What one row is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// One row per cell packet as received (data and event packets).
    Packets,
    /// One row per cell packet: the cell's full sample after it (event-to-data converter).
    Samples,
}

/// A row's box source address: `IP:port`, or empty where unknown.
fn source_text(source: Option<std::net::SocketAddr>) -> String {
    source.map(|a| a.to_string()).unwrap_or_default()
}

/// A [`RecordSink`] writing rows. The first write error stops writing and is kept.
pub struct RowWriter<W: Write> {
    out: W,
    format: RowFormat,
    kind: RowKind,
    header_written: bool,
    rows: u64,
    error: Option<io::Error>,
    timing: Option<Timing>,
    /// Times of the last record (its sample row follows it).
    last_times: Option<RecordTimes>,
}

/// The columns [`RowWriter::with_timing`] appends to every CSV row.
pub const TIME_COLUMNS: &str =
    "sample_box_time_s,sample_method,sample_time_bound_ns,sample_host_time_ns,host_time_bound_ns,host_time_source";

impl<W: Write> RowWriter<W> {
    /// A writer of `kind` rows in `format`.
    pub fn new(out: W, format: RowFormat, kind: RowKind) -> Self {
        RowWriter {
            out,
            format,
            kind,
            header_written: false,
            rows: 0,
            error: None,
            timing: None,
            last_times: None,
        }
    }

    /// Also writes each row's sample time: its box time, how it was found and its error
    /// bound, its host time, the host time's error bound (empty where the mapping has
    /// none) and its source.
    pub fn with_timing(mut self, timing: Timing) -> Self {
        self.timing = Some(timing);
        self
    }

    /// The timing, to read its summary.
    pub fn timing(&self) -> Option<&Timing> {
        self.timing.as_ref()
    }

    /// The timing, to feed exchanges with the boxes.
    pub fn timing_mut(&mut self) -> Option<&mut Timing> {
        self.timing.as_mut()
    }

    fn time_csv(&mut self) -> io::Result<()> {
        if self.timing.is_none() {
            return Ok(());
        }
        match self.last_times {
            Some(t) => write!(
                self.out,
                ",{:.9},{},{:.0},{},{},{}",
                t.sample_box_s,
                t.method.name(),
                t.sample_error_bound_ns,
                t.sample_host_ns
                    .map(|v| format!("{v:.0}"))
                    .unwrap_or_default(),
                t.host_error_bound_ns
                    .map(|v| format!("{v:.0}"))
                    .unwrap_or_default(),
                t.source.name()
            ),
            None => self.out.write_all(b",,,,,,none"),
        }
    }

    fn time_json(&self, row: &mut serde_json::Value) {
        if self.timing.is_none() {
            return;
        }
        if let (Some(t), Some(map)) = (self.last_times, row.as_object_mut()) {
            map.insert("sample_box_time_s".into(), t.sample_box_s.into());
            map.insert("sample_index".into(), t.sample_index.into());
            map.insert("sample_method".into(), t.method.name().into());
            map.insert(
                "sample_time_bound_ns".into(),
                t.sample_error_bound_ns.round().into(),
            );
            map.insert(
                "sample_host_time_ns".into(),
                t.sample_host_ns.map(|v| v.round()).into(),
            );
            map.insert(
                "host_time_bound_ns".into(),
                t.host_error_bound_ns.map(|v| v.round()).into(),
            );
            map.insert("host_time_source".into(), t.source.name().into());
        }
    }

    /// Rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes; returns the first error.
    pub fn finish(self) -> io::Result<u64> {
        self.finish_into().map(|(rows, _)| rows)
    }

    /// Flushes; returns the rows written and the output, or the first error.
    pub fn finish_into(mut self) -> io::Result<(u64, W)> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        if !self.header_written && self.format == RowFormat::Csv {
            self.header()?;
        }
        self.out.flush()?;
        Ok((self.rows, self.out))
    }

    fn header(&mut self) -> io::Result<()> {
        self.header_written = true;
        let channels: Vec<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
        let times = if self.timing.is_some() {
            format!(",{TIME_COLUMNS}")
        } else {
            String::new()
        };
        match self.kind {
            RowKind::Packets => writeln!(
                self.out,
                "time_s,tick,box_id,source,datagram_sequence,port,flags,cell_id,kind,event_sequence,second_part,event_packets_missing_before,{}{times}",
                channels.join(",")
            ),
            RowKind::Samples => writeln!(
                self.out,
                "time_s,tick,box_id,source,cell_id,updated_mask,stale_mask,known_mask,{}{times}",
                channels.join(",")
            ),
        }
    }

    fn write_packet(&mut self, r: &DecodedRecord) -> io::Result<()> {
        let mut values: [Option<f64>; Channel::COUNT] = [None; Channel::COUNT];
        let (kind, sequence, second) = match &r.cell {
            CellRepr::Data(d) => {
                for c in Channel::ALL {
                    values[c.index()] = Some(c.to_units(d.raw(c)));
                }
                ("data", None, false)
            }
            CellRepr::Event(e) => {
                for (c, raw) in e.events() {
                    values[c.index()] = Some(c.to_units(raw));
                }
                ("event", Some(e.sequence), e.second_part)
            }
        };
        match self.format {
            RowFormat::Csv => {
                if !self.header_written {
                    self.header()?;
                }
                write!(
                    self.out,
                    "{:.9},{},{},{},{},{},{},{},{},{},{},{}",
                    r.time_s(),
                    r.tick,
                    r.box_id,
                    source_text(r.source),
                    r.datagram_sequence,
                    r.port,
                    r.flags,
                    r.cell.cell_id(),
                    kind,
                    sequence.map(|s| s.to_string()).unwrap_or_default(),
                    u8::from(second),
                    r.event_packets_missing_before
                )?;
                for v in values {
                    match v {
                        Some(v) => write!(self.out, ",{v}")?,
                        None => self.out.write_all(b",")?,
                    }
                }
                self.time_csv()?;
                self.out.write_all(b"\n")
            }
            RowFormat::JsonLines => {
                let map: serde_json::Map<String, serde_json::Value> = Channel::ALL
                    .iter()
                    .filter_map(|c| values[c.index()].map(|v| (c.name().to_string(), v.into())))
                    .collect();
                let mut row = serde_json::json!({
                    "time_s": r.time_s(),
                    "tick": r.tick,
                    "box_id": r.box_id,
                    "source": r.source.map(|a| a.to_string()),
                    "datagram_sequence": r.datagram_sequence,
                    "port": r.port,
                    "flags": r.flags,
                    "cell_id": r.cell.cell_id(),
                    "kind": kind,
                    "event_sequence": sequence,
                    "second_part": second,
                    "event_packets_missing_before": r.event_packets_missing_before,
                    "values": map,
                });
                self.time_json(&mut row);
                serde_json::to_writer(&mut self.out, &row)?;
                self.out.write_all(b"\n")
            }
        }
    }

    fn write_sample(&mut self, s: &Sample) -> io::Result<()> {
        match self.format {
            RowFormat::Csv => {
                if !self.header_written {
                    self.header()?;
                }
                write!(
                    self.out,
                    "{:.9},{},{},{},{},{},{},{}",
                    s.time_s(),
                    s.tick,
                    s.box_id,
                    source_text(s.source),
                    s.cell_id,
                    s.updated.bits(),
                    s.stale.bits(),
                    s.known.bits()
                )?;
                for c in Channel::ALL {
                    write!(self.out, ",{}", s.value(c))?;
                }
                self.time_csv()?;
                self.out.write_all(b"\n")
            }
            RowFormat::JsonLines => {
                let map: serde_json::Map<String, serde_json::Value> = Channel::ALL
                    .iter()
                    .map(|c| (c.name().to_string(), s.value(*c).into()))
                    .collect();
                let mut row = serde_json::json!({
                    "time_s": s.time_s(),
                    "tick": s.tick,
                    "box_id": s.box_id,
                    "source": s.source.map(|a| a.to_string()),
                    "cell_id": s.cell_id,
                    "updated": s.updated.iter().map(|c| c.name()).collect::<Vec<_>>(),
                    "stale": s.stale.iter().map(|c| c.name()).collect::<Vec<_>>(),
                    "known": s.known.iter().map(|c| c.name()).collect::<Vec<_>>(),
                    "values": map,
                });
                self.time_json(&mut row);
                serde_json::to_writer(&mut self.out, &row)?;
                self.out.write_all(b"\n")
            }
        }
    }
}

impl<W: Write> RecordSink for RowWriter<W> {
    fn record(&mut self, record: &DecodedRecord) {
        if let Some(timing) = &mut self.timing {
            self.last_times = Some(timing.record(record));
        }
        if self.kind != RowKind::Packets || self.error.is_some() {
            return;
        }
        match self.write_packet(record) {
            Ok(()) => self.rows += 1,
            Err(e) => self.error = Some(e),
        }
    }

    fn wants_samples(&self) -> bool {
        self.kind == RowKind::Samples
    }

    fn datagram_received(
        &mut self,
        receive: Option<std::time::Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        if let Some(timing) = &mut self.timing {
            timing.datagram_received(receive, source, payload);
        }
    }

    fn sample(&mut self, sample: &Sample) {
        if self.error.is_some() {
            return;
        }
        match self.write_sample(sample) {
            Ok(()) => self.rows += 1,
            Err(e) => self.error = Some(e),
        }
    }
}

/// Reads a row's sample host time.
type HostTimeKey = Box<dyn Fn(&str) -> Option<f64>>;

/// Rows written with timing, put in order of their sample's host time: the records of
/// several boxes, each box's time mapped on its own, merged on one host time line. A CSV
/// header stays first; rows without a host time come first, in their order.
pub fn sort_by_host_time(text: &str, format: RowFormat) -> String {
    let mut lines = text.lines();
    let (header, key): (Option<&str>, HostTimeKey) = match format {
        RowFormat::Csv => {
            let header = lines.next();
            let column = header.and_then(|h| h.split(',').position(|c| c == "sample_host_time_ns"));
            (
                header,
                Box::new(move |l: &str| column.and_then(|k| l.split(',').nth(k)?.parse().ok())),
            )
        }
        RowFormat::JsonLines => (
            None,
            Box::new(|l: &str| {
                serde_json::from_str::<serde_json::Value>(l)
                    .ok()?
                    .get("sample_host_time_ns")?
                    .as_f64()
            }),
        ),
    };
    let mut rows: Vec<(f64, &str)> = lines
        .map(|l| (key(l).unwrap_or(f64::NEG_INFINITY), l))
        .collect();
    // stable: rows of equal time keep their order
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = String::with_capacity(text.len());
    for l in header.into_iter().chain(rows.into_iter().map(|r| r.1)) {
        out.push_str(l);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::{DataRepr, EventRepr};

    fn record(cell: CellRepr) -> DecodedRecord {
        DecodedRecord {
            box_id: 1,
            source: None,
            datagram_sequence: 9,
            port: 2,
            flags: 0,
            tick: 250_000_000,
            cell,
            event_packets_missing_before: 0,
        }
    }

    #[test]
    fn csv_rows_hold_units_and_box_time() {
        let data = DataRepr::from_raw(17, [2, -3, 258, 1, 0, 2, 310, 61, 0]).unwrap();
        let event = EventRepr::new(17, 41, false, &[(Channel::Force1, 512)]).unwrap();
        let mut w = RowWriter::new(Vec::new(), RowFormat::Csv, RowKind::Packets);
        w.record(&record(CellRepr::Data(data)));
        w.record(&record(CellRepr::Event(event)));
        let text = String::from_utf8(w.out.clone()).unwrap();
        assert_eq!(w.finish().unwrap(), 2);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        // 2 s = 250 M ticks of 8 ns; raw steps 1/256 g, 1/1024, 1/65536, 0.5 C.
        let proximity = 310.0f64 / 65536.0;
        assert_eq!(
            lines[1],
            format!(
                "2.000000000,250000000,1,,9,2,0,17,data,,0,0,0.0078125,-0.01171875,1.0078125,\
                 0.0009765625,0,0.001953125,{proximity},30.5,0"
            )
        );
        assert_eq!(
            lines[2],
            "2.000000000,250000000,1,,9,2,0,17,event,41,0,0,,,,0.5,,,,,"
        );
    }

    #[test]
    fn rows_of_two_boxes_merge_on_host_time() {
        use crate::sample_clock::{PathModel, Positions};
        use std::time::Duration;
        // Box 2 was reset 5 s after box 1: its ticks are 5 s behind for the same host time.
        let timing = Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
        let mut w =
            RowWriter::new(Vec::new(), RowFormat::Csv, RowKind::Packets).with_timing(timing);
        let data = |cell| CellRepr::Data(DataRepr::from_raw(cell, [0; 9]).unwrap());
        for (i, host_ms) in [10u64, 30, 50].into_iter().enumerate() {
            // box 2's datagrams come first at each step, but 1 ms later in host time
            for (box_id, reset_ms) in [(2u16, 5_000u64), (1, 0)] {
                let host = host_ms + u64::from(box_id);
                let tick = (host + 6_000 - reset_ms) * 125_000;
                let payload = crate::timing::tests::datagram(box_id, box_id, &[tick]);
                w.datagram_received(Some(Duration::from_millis(host + 1_000)), None, &payload);
                w.record(&DecodedRecord {
                    box_id,
                    tick,
                    datagram_sequence: i as u32,
                    ..record(data(box_id))
                });
            }
        }
        let (_, bytes) = w.finish_into().unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let arrived: Vec<&str> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap())
            .collect();
        assert_eq!(arrived, ["2", "1", "2", "1", "2", "1"]);
        let sorted = sort_by_host_time(&text, RowFormat::Csv);
        let boxes: Vec<&str> = sorted
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap())
            .collect();
        assert_eq!(boxes, ["1", "2", "1", "2", "1", "2"]);
        assert!(sorted.starts_with("time_s,"));
    }

    #[test]
    fn jsonl_rows_parse() {
        let event = EventRepr::new(5, 7, true, &[(Channel::Temperature1, 61)]).unwrap();
        let mut w = RowWriter::new(Vec::new(), RowFormat::JsonLines, RowKind::Packets);
        w.record(&record(CellRepr::Event(event)));
        let v: serde_json::Value = serde_json::from_slice(&w.out).unwrap();
        assert_eq!(v["values"]["temperature_1"], 30.5);
        assert_eq!(v["second_part"], true);
        assert_eq!(v["time_s"], 2.0);
    }
}
