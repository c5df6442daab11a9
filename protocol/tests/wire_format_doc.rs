//! docs/wire-format.md and the code describe the same bytes.

use skinbox_protocol::{
    box_counters, cell, cell_command, command, data, datagram, event, record, status, LayoutRow,
};

/// The rows of the table marked `<!-- layout: NAME -->`, as (field, first byte, last byte).
fn doc_table(doc: &str, name: &str) -> Vec<(String, usize, usize)> {
    let marker = format!("<!-- layout: {name} -->");
    let start = doc
        .find(&marker)
        .unwrap_or_else(|| panic!("docs/wire-format.md has no table marked {marker}"));
    doc[start + marker.len()..]
        .lines()
        .skip_while(|l| l.trim().is_empty())
        .take_while(|l| l.starts_with('|'))
        .skip(2) // heading and separator
        .map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            let (first, last) = match cells[1].split_once('-') {
                Some((a, b)) => (a.parse().unwrap(), b.parse().unwrap()),
                None => (cells[1].parse().unwrap(), cells[1].parse().unwrap()),
            };
            (cells[2].to_string(), first, last)
        })
        .collect()
}

fn code_table(rows: Vec<LayoutRow>) -> Vec<(String, usize, usize)> {
    rows.into_iter()
        .map(|r| (r.name.to_string(), r.bytes.start, r.bytes.end - 1))
        .collect()
}

#[test]
fn every_documented_table_matches_the_code() {
    let doc = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/wire-format.md"
    ))
    .expect("read docs/wire-format.md");
    let formats = [
        ("cell", cell::layout()),
        ("data", data::layout()),
        ("event", event::layout()),
        ("datagram", datagram::layout()),
        ("record", record::layout()),
        ("status", status::layout()),
        ("port_counters", status::port_counters_layout()),
        ("box_counters", box_counters::layout()),
        ("command", command::layout()),
        ("destination", command::destination_layout()),
        ("cell_command", command::cell_command_layout()),
        ("ack", command::ack_layout()),
        ("ack_body", command::ack_body_layout()),
        ("cell_command_packet", cell_command::layout()),
    ];
    for (name, rows) in formats {
        assert_eq!(doc_table(&doc, name), code_table(rows), "table {name}");
    }
    for code in cell_command::CommandCode::ALL {
        let name = format!("cell_command_{}", code.name());
        let rows = cell_command::arguments_layout(code);
        assert_eq!(doc_table(&doc, &name), code_table(rows), "table {name}");
    }
}

#[test]
fn layouts_are_contiguous_and_fill_their_format() {
    let formats = [
        (data::layout(), cell::PACKET_LEN),
        (event::layout(), cell::PACKET_LEN),
        (datagram::layout(), datagram::HEADER_LEN),
        (record::layout(), record::RECORD_LEN),
        (status::layout(), status::STATUS_FIXED_LEN),
        (status::port_counters_layout(), status::PORT_COUNTERS_LEN),
        (box_counters::layout(), box_counters::BOX_COUNTERS_LEN),
        (command::layout(), command::HEADER_LEN),
        (command::ack_layout(), command::HEADER_LEN),
        (command::ack_body_layout(), command::ACK_FIXED_LEN),
        (command::destination_layout(), command::DESTINATION_LEN),
        (command::cell_command_layout(), command::CELL_COMMAND_LEN),
        (cell_command::layout(), cell::PACKET_LEN),
    ];
    for (rows, len) in formats {
        let mut at = 0;
        for r in &rows {
            assert_eq!(r.bytes.start, at, "gap or overlap before {}", r.name);
            at = r.bytes.end;
        }
        assert_eq!(at, len);
    }
}
