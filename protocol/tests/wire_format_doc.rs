//! docs/wire-format.md and the code describe the same bytes.

use skinbox_protocol::wire::{arp, ethernet, icmp, ipv4, udp};
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
        ("ethernet", ethernet::layout()),
        ("arp", arp::layout()),
        ("ipv4", ipv4::layout()),
        ("icmp_echo", icmp::layout()),
        ("udp", udp::layout()),
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
        (ethernet::layout(), ethernet::HEADER_LEN),
        (arp::layout(), arp::PACKET_LEN),
        (ipv4::layout(), ipv4::HEADER_LEN),
        (icmp::layout(), icmp::HEADER_LEN),
        (udp::layout(), udp::HEADER_LEN),
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

fn read_doc() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/wire-format.md"
    ))
    .expect("read docs/wire-format.md")
}

/// The meaning column of every row of the table marked `<!-- layout: NAME -->` whose field
/// is `reserved`, with its byte range.
fn reserved_rows(doc: &str, name: &str) -> Vec<(usize, usize, String)> {
    let marker = format!("<!-- layout: {name} -->");
    let start = doc.find(&marker).expect("marked table");
    doc[start + marker.len()..]
        .lines()
        .skip_while(|l| l.trim().is_empty())
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .filter_map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            (cells[2] == "reserved").then(|| {
                let (a, b) = cells[1].split_once('-').unwrap_or((cells[1], cells[1]));
                (a.parse().unwrap(), b.parse().unwrap(), cells[4].to_string())
            })
        })
        .collect()
}

/// Every reserved field the document lists is ignored or refused by the code, as its row
/// says: each is set to 1 in a valid instance of its format, which must then still parse
/// ("ignored on input") or fail ("refused").
#[test]
fn every_reserved_field_is_ignored_or_refused_as_documented() {
    use skinbox_protocol::cell_command::{
        CellCommand, CellCommandRepr, CellMode, CommandCode, ModalityThresholds, SampleRate,
    };
    use skinbox_protocol::command::{
        AckReply, AckRepr, AckResult, CommandRepr, Opcode, Request, HEADER_LEN,
    };
    use skinbox_protocol::datagram::DatagramBody;
    use skinbox_protocol::{ChannelMask, DatagramRepr, StatusRepr};
    let doc = read_doc();
    type Parse = Box<dyn Fn(&[u8]) -> bool>;
    let status = DatagramRepr {
        box_id: 1,
        port_count: 2,
        flags: 0,
        sequence: 0,
        base_tick: 0,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 1,
            datagrams_sent: 0,
            records_sent: 0,
            first_port: 0,
            ports: vec![Default::default(); 2],
        }),
    }
    .to_bytes();
    let counters = skinbox_protocol::BoxCounters::default();
    let mut counter_bytes = vec![0u8; box_counters::BOX_COUNTERS_LEN];
    counters.emit(&mut counter_bytes);
    let command = |request| {
        CommandRepr {
            box_id: 1,
            sequence: 1,
            host_time: 0,
            request,
        }
        .to_bytes()
    };
    let cell_packet = |command| {
        CellCommandRepr {
            cell_id: 1,
            command,
        }
        .to_bytes()
    };
    let ack = AckRepr {
        box_id: 1,
        port_count: 2,
        sequence: 1,
        host_time: 0,
        opcode: Opcode::ReadTick as u8,
        result: AckResult::Ok,
        last_accepted: 1,
        receive_tick: 0,
        send_tick: 0,
        reply: AckReply::None,
    }
    .to_bytes();
    let datagram_ok: Parse = Box::new(|b| DatagramRepr::parse_box_counters(b).is_ok());
    let command_ok: Parse = Box::new(|b| CommandRepr::parse(b, 2).is_ok());
    let ack_ok: Parse = Box::new(|b| AckRepr::parse(b).is_ok());
    let cell_ok = || -> Parse { Box::new(|b| CellCommandRepr::parse(b).is_ok()) };
    // (table, a valid instance, where the table's bytes begin in it, its parser)
    let mut cases: Vec<(String, Vec<u8>, usize, Parse)> = vec![
        ("datagram".into(), status.clone(), 0, datagram_ok),
        (
            "status".into(),
            status,
            datagram::HEADER_LEN,
            Box::new(|b| DatagramRepr::parse(b).is_ok()),
        ),
        (
            "box_counters".into(),
            counter_bytes,
            0,
            Box::new(|b| skinbox_protocol::BoxCounters::parse(b).is_ok()),
        ),
        ("command".into(), command(Request::ReadTick), 0, command_ok),
        (
            "cell_command".into(),
            command(Request::CellCommand {
                port: 1,
                packet: cell_packet(CellCommand::Mode(CellMode::Event)),
            }),
            HEADER_LEN,
            Box::new(|b| CommandRepr::parse(b, 2).is_ok()),
        ),
        ("ack".into(), ack.clone(), 0, ack_ok),
        (
            "ack_body".into(),
            ack,
            HEADER_LEN,
            Box::new(|b| AckRepr::parse(b).is_ok()),
        ),
    ];
    for code in CommandCode::ALL {
        let c = match code {
            CommandCode::Mode => CellCommand::Mode(CellMode::Data),
            CommandCode::SampleRate => CellCommand::SampleRate(SampleRate::Hz125),
            CommandCode::Thresholds => CellCommand::Thresholds(ModalityThresholds::table_i()),
            CommandCode::EnableMask => CellCommand::EnableMask(ChannelMask::ALL),
            CommandCode::TimeSync => CellCommand::TimeSync { box_tick: 7 },
        };
        cases.push((
            format!("cell_command_{}", code.name()),
            cell_packet(c).to_vec(),
            0,
            cell_ok(),
        ));
    }
    let mut checked = 0;
    for (name, valid, at, parses) in &cases {
        assert!(parses(valid), "{name}: the valid instance parses");
        let rows = reserved_rows(&doc, name);
        for (first, last, meaning) in rows {
            let ignored = meaning.contains("ignored on input");
            let refused = meaning.contains("refused");
            assert!(
                ignored != refused,
                "{name} bytes {first}-{last}: the row must say ignored or refused: {meaning}"
            );
            for byte in first..=last {
                let mut b = valid.clone();
                b[at + byte] = 1;
                assert_eq!(
                    parses(&b),
                    ignored,
                    "{name} reserved byte {byte}: the document says {meaning}"
                );
                checked += 1;
            }
        }
    }
    // datagram 2, status 3, box counters 2, command 2, cell command 3, ack 2, ack body 2,
    // and the cell command packets' reserved bytes
    assert!(checked > 16 + 14, "{checked} reserved bytes checked");
}

/// The figures the document gives in its text, as the code defines them.
#[test]
fn documented_figures_match_the_code() {
    use skinbox_protocol::command::{ACK_FIXED_LEN, DESTINATION_LEN};
    let doc = read_doc().split_whitespace().collect::<Vec<_>>().join(" ");
    let counters = box_counters::BOX_COUNTERS_LEN;
    let figures = [
        format!(
            "bytes after the header: {}, {} or {}",
            ACK_FIXED_LEN,
            ACK_FIXED_LEN + DESTINATION_LEN,
            ACK_FIXED_LEN + counters
        ),
        format!(
            "status-now's box counter block ({counters} bytes, this command counted): a body of {}, {} or {} bytes",
            ACK_FIXED_LEN,
            ACK_FIXED_LEN + DESTINATION_LEN,
            ACK_FIXED_LEN + counters
        ),
        format!(
            "24 bytes of body, {} for stream-to `ok`, {} for status-now `ok`",
            ACK_FIXED_LEN + DESTINATION_LEN,
            ACK_FIXED_LEN + counters
        ),
        format!("the {counters}-byte box counter block"),
        format!(
            "at most {} port counter blocks fit one datagram (the length is header + {} + {} x entries + {counters})",
            datagram::MAX_STATUS_PORTS_WITH_BOX_COUNTERS,
            status::STATUS_FIXED_LEN,
            status::PORT_COUNTERS_LEN
        ),
        format!(
            "records (at most {}) or port counter blocks (at most {})",
            datagram::MAX_RECORDS,
            datagram::MAX_STATUS_PORTS
        ),
        format!(
            "{} records make a {}-byte payload",
            datagram::MAX_RECORDS,
            datagram::HEADER_LEN + datagram::MAX_RECORDS * record::RECORD_LEN
        ),
        format!(
            "Then `entry_count` blocks of {} bytes",
            status::PORT_COUNTERS_LEN
        ),
        format!("The payload is a {}-byte header", datagram::HEADER_LEN),
        format!("Every cell packet is {} bytes", cell::PACKET_LEN),
        format!(
            "| 6 cell command | {} bytes (below)",
            command::CELL_COMMAND_LEN
        ),
        format!(
            "or {} bytes, a destination",
            command::DESTINATION_LEN
        ),
    ];
    for f in &figures {
        assert!(
            doc.contains(f.as_str()),
            "docs/wire-format.md does not say: {f}"
        );
    }
}
