//! Rows written without times in one thread and timed in another: the sample clocks are
//! most of the cost of a timed record, so `Capture` (live.rs) and `read` (files.rs) decode
//! rows with `RowWriter` and no `Timing` in one thread, keeping each datagram the timing
//! reads in its place among the rows, and a second thread replays those datagrams and
//! records into one `Timing` in the same order as a single thread would, filling in each
//! row's five time fields: the times are those of `RowWriter` with the timing, bit for bit.

use skinbox_host::decoder::DecodedRecord;
use skinbox_host::rows::{host_time_source_code, RecordRow};
use skinbox_host::timing::Timing;
use std::net::SocketAddr;
use std::time::Duration;

/// A datagram the timing reads, in its place among the rows: it came before row `at_row`.
pub struct Received {
    pub at_row: usize,
    pub receive: Option<Duration>,
    pub source: Option<SocketAddr>,
    /// Its bytes in the batch's payloads.
    pub payload: std::ops::Range<usize>,
}

/// The datagrams of a batch of rows: where each came and its bytes.
#[derive(Default)]
pub struct Datagrams {
    pub list: Vec<Received>,
    pub payloads: Vec<u8>,
}

impl Datagrams {
    /// Keeps the datagram `payload`, which came before row `at_row` of the batch.
    #[inline]
    pub fn push(
        &mut self,
        at_row: usize,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        let start = self.payloads.len();
        self.payloads.extend_from_slice(payload);
        self.list.push(Received {
            at_row,
            receive,
            source,
            payload: start..self.payloads.len(),
        });
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Emptied, its memory kept for reuse (memory written before costs less than new).
    pub fn clear(&mut self) {
        self.list.clear();
        self.payloads.clear();
    }
}

/// `v.round()`, as `skinbox_host::rows` rounds the host times: without the library call
/// where `v` is an integer already (every `f64` of magnitude 2^52 or more).
#[inline]
fn round(v: f64) -> f64 {
    if v.abs() >= 4_503_599_627_370_496.0 {
        v
    } else {
        v.round()
    }
}

/// Fills in the times of a batch's `rows`, taking its datagrams in their places, as the
/// decoding thread's `RowWriter` would have; `timing.record` reads a record's box (id and
/// the source of its datagram: `source`, the last one taken, which may be in an earlier
/// batch), port, cell and tick, which the row holds.
pub fn time_rows(
    timing: &mut Timing,
    source: &mut Option<SocketAddr>,
    rows: &mut [RecordRow],
    datagrams: &Datagrams,
) {
    use skinbox_protocol::{CellRepr, DataRepr};
    let mut list = datagrams.list.iter().peekable();
    for (i, row) in rows.iter_mut().enumerate() {
        while let Some(d) = list.next_if(|d| d.at_row <= i) {
            timing.datagram_received(d.receive, d.source, &datagrams.payloads[d.payload.clone()]);
            *source = d.source;
        }
        // (the timing reads only the cell id of the packet)
        let cell = DataRepr {
            cell_id: row.cell_id,
            ..DataRepr::default()
        };
        let times = timing.record(&DecodedRecord {
            box_id: row.box_id,
            source: *source,
            datagram_sequence: row.datagram_sequence,
            port: row.port,
            flags: row.flags,
            tick: row.tick,
            cell: CellRepr::Data(cell),
            event_packets_missing_before: row.event_packets_missing_before,
        });
        row.sample_box_time_ns = times.sample_box_ns;
        row.sample_index = times.sample_index;
        row.host_time_ns = times.sample_host_ns.map_or(0, |v| round(v) as i64);
        row.host_time_bound_ns = times.host_error_bound_ns.map_or(f64::NAN, round);
        row.host_time_source = host_time_source_code(times.source);
    }
    for d in list {
        timing.datagram_received(d.receive, d.source, &datagrams.payloads[d.payload.clone()]);
        *source = d.source;
    }
}
