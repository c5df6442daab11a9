//! A Wireshark dissector for every skinbox datagram, generated from the protocol crate.
//!
//! [`dissector_lua`] writes a Lua plugin (Wireshark and tshark load Lua plugins) whose
//! tables of byte positions, field types, names and constants are made here from the
//! `layout()` tables and constants of `skinbox-protocol`, the same tables that
//! `protocol/tests/wire_format_doc.rs` checks against docs/wire-format.md. The dissection
//! logic (`dissector.lua`) reads every position through those tables, so the plugin cannot
//! drift from the formats: a renamed or moved field changes the plugin with it.

use skinbox_protocol::box_counters::{self, BoxCounter, BOX_COUNTERS_LEN};
use skinbox_protocol::cell::{self, DATA_HEADER, END_OF_PACKET, EVENT_HEADER, PACKET_LEN};
use skinbox_protocol::cell_command::{self, CellMode, CommandCode, SampleRate, COMMAND_HEADER};
use skinbox_protocol::command::{
    self, AckResult, Opcode, ACK_FIXED_LEN, ALL_PORTS, CELL_COMMAND_LEN, DESTINATION_LEN, KIND_ACK,
    KIND_COMMAND, MAX_FLUSH_TIMEOUT_TICKS, MIN_STATUS_PERIOD_TICKS,
};
use skinbox_protocol::datagram::{
    self, DatagramKind, FLAG_BOX_COUNTERS, FLAG_FLUSH_TIMEOUT, HEADER_LEN, MAGIC,
    MAX_STATUS_PORTS_WITH_BOX_COUNTERS,
};
use skinbox_protocol::event::MASK_SECOND_PART;
use skinbox_protocol::link::DEFAULT_PORT;
use skinbox_protocol::record::{self, FLAG_LOSS_BEFORE, RECORD_LEN};
use skinbox_protocol::status::{self, PortCounter, PORT_COUNTERS_LEN, STATUS_FIXED_LEN};
use skinbox_protocol::{data, event, Channel, ChannelMask, LayoutRow, TICK_NS};
use std::fmt::Write as _;
use std::path::PathBuf;

/// File name of the plugin.
pub const PLUGIN_FILE: &str = "skinbox.lua";

/// The dissection logic; [`dissector_lua`] puts the generated tables in front of it.
const LOGIC: &str = include_str!("dissector.lua");

/// A format's layout as the plugin names it: `P.<format>.<field>`, field abbreviations
/// `<prefix>.<field>`.
struct Format {
    name: &'static str,
    prefix: &'static str,
    rows: Vec<LayoutRow>,
}

fn formats() -> Vec<Format> {
    vec![
        Format {
            name: "datagram",
            prefix: "skinbox",
            rows: datagram::layout(),
        },
        Format {
            name: "record",
            prefix: "skinbox.record",
            rows: record::layout(),
        },
        Format {
            name: "cell",
            prefix: "skinbox.cell",
            rows: cell::layout(),
        },
        Format {
            name: "data",
            prefix: "skinbox.data",
            rows: data::layout(),
        },
        Format {
            name: "event",
            prefix: "skinbox.event",
            rows: event::layout(),
        },
        Format {
            name: "status",
            prefix: "skinbox.status",
            rows: status::layout(),
        },
        Format {
            name: "port_counters",
            prefix: "skinbox.port_counters",
            rows: status::port_counters_layout(),
        },
        Format {
            name: "box_counters",
            prefix: "skinbox.box_counters",
            rows: box_counters::layout(),
        },
        Format {
            name: "command",
            prefix: "skinbox.command",
            rows: command::layout(),
        },
        Format {
            name: "ack",
            prefix: "skinbox.ack",
            rows: command::ack_layout(),
        },
        Format {
            name: "ack_body",
            prefix: "skinbox.ack",
            rows: command::ack_body_layout()
                .into_iter()
                // the body's opcode and reserved bytes share names with the header's
                .map(|mut r| {
                    r.name = match r.name {
                        "opcode" => "command_opcode",
                        "reserved" => "body_reserved",
                        n => n,
                    };
                    r
                })
                .collect(),
        },
        Format {
            name: "destination",
            prefix: "skinbox.destination",
            rows: command::destination_layout(),
        },
        Format {
            name: "cell_command",
            prefix: "skinbox.cell_command",
            rows: command::cell_command_layout(),
        },
    ]
}

/// Lua `ProtoField` constructor and arguments for one layout row.
fn proto_field(format: &str, row: &LayoutRow) -> String {
    let len = row.bytes.len();
    let channel = Channel::ALL.into_iter().find(|c| c.name() == row.name);
    let signed = match (format, row.name) {
        ("record", "tick_offset") => true,
        ("data", _) => channel.is_some_and(|c| *c.data_range().start() < 0),
        _ => false,
    };
    let hex = matches!(
        row.name,
        "header" | "flags" | "mask" | "boot_id" | "end_of_packet"
    );
    let base = if hex { "base.HEX" } else { "base.DEC" };
    let int = |bits: u32| {
        let kind = if signed { "int" } else { "uint" };
        let base = if signed { "base.DEC" } else { base };
        format!("{kind}{bits}(%ABBR%, %NAME%, {base})")
    };
    match (row.name, len) {
        ("magic", _) => "string(%ABBR%, %NAME%)".to_string(),
        ("mac", 6) => "ether(%ABBR%, %NAME%)".to_string(),
        ("ip", 4) => "ipv4(%ABBR%, %NAME%)".to_string(),
        ("opcode" | "command_opcode", 1) => {
            "uint8(%ABBR%, %NAME%, base.DEC, OPCODE_NAMES)".to_string()
        }
        ("result", 1) => "uint8(%ABBR%, %NAME%, base.DEC, RESULT_NAMES)".to_string(),
        ("kind", 1) => "uint8(%ABBR%, %NAME%, base.DEC, KIND_NAMES)".to_string(),
        ("header", 1) => "uint8(%ABBR%, %NAME%, base.HEX, HEADER_NAMES)".to_string(),
        (_, 1) => int(8),
        (_, 2) => int(16),
        (_, 4) => int(32),
        (_, 8) => int(64),
        _ => "bytes(%ABBR%, %NAME%)".to_string(),
    }
}

fn lua_string(s: &str) -> String {
    format!("{s:?}")
}

/// A label from a field name: `tick_offset` -> `Tick offset`.
fn label(name: &str) -> String {
    let text = name.replace('_', " ");
    let mut chars = text.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => text,
    }
}

/// The generated tables: positions, fields, constants, channels and counters.
fn tables() -> String {
    let mut out = String::new();
    let w = &mut out;
    let _ = writeln!(
        w,
        "-- Byte positions {{offset, length}} of every field, from the layout() tables."
    );
    let _ = writeln!(w, "local P = {{}}");
    let _ = writeln!(w, "local F = {{}}");
    let formats = formats();
    let cell_rows = cell::layout();
    for f in &formats {
        let _ = writeln!(w, "P.{} = {{", f.name);
        for row in &f.rows {
            let _ = writeln!(
                w,
                "    {} = {{ {}, {} }},",
                row.name,
                row.bytes.start,
                row.bytes.len()
            );
        }
        let _ = writeln!(w, "}}");
    }
    let _ = writeln!(w, "-- Field names of every format in wire order.");
    let _ = writeln!(w, "local ROWS = {{}}");
    for f in &formats {
        let names: Vec<String> = f.rows.iter().map(|r| lua_string(r.name)).collect();
        let _ = writeln!(w, "ROWS.{} = {{ {} }}", f.name, names.join(", "));
    }
    let _ = writeln!(w, "local KIND_NAMES = {{");
    for kind in DatagramKind::ALL {
        let _ = writeln!(w, "    [{}] = {:?},", kind as u8, kind.name());
    }
    let _ = writeln!(w, "    [{KIND_COMMAND}] = \"command\",");
    let _ = writeln!(w, "    [{KIND_ACK}] = \"acknowledgement\",");
    let _ = writeln!(w, "}}");
    let _ = writeln!(w, "local OPCODE_NAMES = {{");
    for op in Opcode::ALL {
        let _ = writeln!(w, "    [{}] = {:?},", op as u8, op.name());
    }
    let _ = writeln!(w, "}}");
    let _ = writeln!(w, "local RESULT_NAMES = {{");
    for r in AckResult::ALL {
        let _ = writeln!(w, "    [{}] = {:?},", r as u8, r.name());
    }
    let _ = writeln!(w, "}}");
    let _ = writeln!(w, "local BOX_COUNTERS = {{");
    for c in BoxCounter::ALL {
        let _ = writeln!(w, "    {:?},", c.name());
    }
    let _ = writeln!(w, "}}");
    let _ = writeln!(
        w,
        "local HEADER_NAMES = {{ [{DATA_HEADER}] = \"data\", [{EVENT_HEADER}] = \"event\" }}"
    );
    for f in &formats {
        let _ = writeln!(w, "F.{} = {{}}", f.name);
        for row in &f.rows {
            // data and event packets share the cell packet's header, id and end byte
            let shared = matches!(f.name, "data" | "event") && cell_rows.contains(row);
            if shared || (f.name == "cell" && row.name == "body") {
                continue;
            }
            let ctor = proto_field(f.name, row)
                .replace("%ABBR%", &lua_string(&format!("{}.{}", f.prefix, row.name)))
                .replace("%NAME%", &lua_string(&label(row.name)));
            let _ = writeln!(w, "F.{}.{} = ProtoField.{ctor}", f.name, row.name);
        }
    }
    // Fields that are not byte ranges of a layout: subtrees, flag bits, mask bits, values
    // derived from several fields.
    let derived = [
        "F.record.record = ProtoField.none(\"skinbox.record\", \"Record\")".to_string(),
        "F.status.status = ProtoField.none(\"skinbox.status\", \"Status\")".to_string(),
        "F.port_counters.block = ProtoField.none(\"skinbox.port_counters\", \"Port counters\")"
            .to_string(),
        "F.port_counters.port = ProtoField.uint8(\"skinbox.port_counters.port\", \"Port\", base.DEC)"
            .to_string(),
        "F.box_counters.block = ProtoField.none(\"skinbox.box_counters\", \"Box counters\")"
            .to_string(),
        "F.destination.block = ProtoField.none(\"skinbox.destination\", \"Destination\")"
            .to_string(),
        "F.command.ticks = ProtoField.uint32(\"skinbox.command.ticks\", \"Ticks\", base.DEC)"
            .to_string(),
        format!(
            "F.flags = {{ flush_timeout = ProtoField.bool(\"skinbox.flags.flush_timeout\", \
             \"Sent by flush timeout\", 8, nil, {FLAG_FLUSH_TIMEOUT}), box_counters = \
             ProtoField.bool(\"skinbox.flags.box_counters\", \"Box counters follow\", 8, nil, \
             {FLAG_BOX_COUNTERS}), reserved = \
             ProtoField.uint8(\"skinbox.flags.reserved\", \"Reserved flags\", base.HEX, nil, {}) }}",
            !(FLAG_FLUSH_TIMEOUT | FLAG_BOX_COUNTERS)
        ),
        format!(
            "F.record_flags = {{ loss_before = ProtoField.bool(\"skinbox.record.flags.loss_before\", \
             \"Packets of this port dropped before\", 8, nil, {FLAG_LOSS_BEFORE}) }}"
        ),
        "F.record_extra = { tick = ProtoField.uint64(\"skinbox.record.tick\", \"Tick\", base.DEC), \
         time = ProtoField.double(\"skinbox.record.time\", \"Box time (s)\") }"
            .to_string(),
        "F.event_extra = { second_part = ProtoField.bool(\"skinbox.event.second_part\", \
         \"Second packet of a sample\"), missing_before = \
         ProtoField.uint16(\"skinbox.event.missing_before\", \
         \"Event packets of this cell missing before\", base.DEC) }"
            .to_string(),
        "F.datagram_extra = { missing_before = ProtoField.uint32(\"skinbox.missing_before\", \
         \"Datagrams missing before\", base.DEC) }"
            .to_string(),
        "F.mask = {}".to_string(),
        "F.channel = {}".to_string(),
        "F.channel_raw = {}".to_string(),
    ];
    for line in derived {
        let _ = writeln!(w, "{line}");
    }
    let reserved_mask = !(ChannelMask::CHANNEL_BITS | MASK_SECOND_PART);
    for c in Channel::ALL {
        let name = c.name();
        let _ = writeln!(
            w,
            "F.mask.{name} = ProtoField.bool(\"skinbox.event.mask.{name}\", \"{name}\", 16, nil, {})",
            1u32 << c.index()
        );
        let unit = if c.unit().is_empty() {
            String::new()
        } else {
            format!(" ({})", c.unit())
        };
        let _ = writeln!(
            w,
            "F.channel.{name} = ProtoField.double(\"skinbox.{name}\", \"{name}{unit}\")"
        );
        let _ = writeln!(
            w,
            "F.channel_raw.{name} = ProtoField.int32(\"skinbox.{name}.raw\", \"{name} raw\", base.DEC)"
        );
    }
    let _ = writeln!(
        w,
        "F.mask.second_part = ProtoField.bool(\"skinbox.event.mask.second_part\", \
         \"Second packet of a sample\", 16, nil, {MASK_SECOND_PART})"
    );
    let _ = writeln!(
        w,
        "F.mask.reserved = ProtoField.uint16(\"skinbox.event.mask.reserved\", \"Reserved bits\", \
         base.HEX, nil, {reserved_mask})"
    );

    let _ = writeln!(w, "local CHANNELS = {{");
    for c in Channel::ALL {
        let _ = writeln!(
            w,
            "    {{ name = {:?}, index = {}, signed = {}, units_per_lsb = {:e}, unit = {:?} }},",
            c.name(),
            c.index(),
            *c.word_range().start() < 0,
            c.units_per_lsb(),
            c.unit()
        );
    }
    let _ = writeln!(w, "}}");
    let _ = writeln!(w, "local COUNTERS = {{");
    for counter in PortCounter::ALL {
        let _ = writeln!(
            w,
            "    {{ name = {:?}, loss = {} }},",
            counter.name(),
            counter.is_packet_loss()
        );
    }
    let _ = writeln!(w, "}}");

    let records = DatagramKind::Records as u8;
    let status = DatagramKind::Status as u8;
    let constants = [
        (
            "magic",
            lua_string(std::str::from_utf8(&MAGIC).unwrap_or("SK")),
        ),
        ("version", datagram::VERSION.to_string()),
        ("header_len", HEADER_LEN.to_string()),
        ("record_len", RECORD_LEN.to_string()),
        ("cell_packet_len", PACKET_LEN.to_string()),
        ("status_fixed_len", STATUS_FIXED_LEN.to_string()),
        ("port_counters_len", PORT_COUNTERS_LEN.to_string()),
        ("kind_records", records.to_string()),
        (
            "entry_len",
            format!("{{ [{records}] = {RECORD_LEN}, [{status}] = {PORT_COUNTERS_LEN} }}"),
        ),
        (
            "fixed_len",
            format!("{{ [{records}] = 0, [{status}] = {STATUS_FIXED_LEN} }}"),
        ),
        (
            "max_entries",
            format!(
                "{{ [{records}] = {}, [{status}] = {} }}",
                DatagramKind::Records.max_entries(),
                DatagramKind::Status.max_entries()
            ),
        ),
        ("data_header", DATA_HEADER.to_string()),
        ("event_header", EVENT_HEADER.to_string()),
        ("end_of_packet", END_OF_PACKET.to_string()),
        ("flag_flush_timeout", FLAG_FLUSH_TIMEOUT.to_string()),
        ("flag_box_counters", FLAG_BOX_COUNTERS.to_string()),
        ("flag_time_syncs", datagram::FLAG_TIME_SYNCS.to_string()),
        ("box_counters_len", BOX_COUNTERS_LEN.to_string()),
        (
            "max_status_ports_with_box_counters",
            MAX_STATUS_PORTS_WITH_BOX_COUNTERS.to_string(),
        ),
        ("kind_command", KIND_COMMAND.to_string()),
        ("kind_ack", KIND_ACK.to_string()),
        ("ack_fixed_len", ACK_FIXED_LEN.to_string()),
        ("destination_len", DESTINATION_LEN.to_string()),
        ("cell_command_len", CELL_COMMAND_LEN.to_string()),
        ("opcode_stream_to", (Opcode::StreamTo as u8).to_string()),
        (
            "opcode_cell_command",
            (Opcode::CellCommand as u8).to_string(),
        ),
        ("max_ports", datagram::MAX_PORTS.to_string()),
        ("flags_defined_records", FLAG_FLUSH_TIMEOUT.to_string()),
        (
            "flags_defined_status",
            (FLAG_FLUSH_TIMEOUT | FLAG_BOX_COUNTERS | datagram::FLAG_TIME_SYNCS).to_string(),
        ),
        ("record_flags_defined", FLAG_LOSS_BEFORE.to_string()),
        ("max_cell_id", cell::CELL_ID_BROADCAST.to_string()),
        (
            "accel_min",
            skinbox_protocol::channel::ACCEL_MIN.to_string(),
        ),
        (
            "accel_max",
            skinbox_protocol::channel::ACCEL_MAX.to_string(),
        ),
        (
            "max_link_speed",
            (skinbox_protocol::box_counters::LinkSpeed::Unknown as u8).to_string(),
        ),
        ("opcode_status_now", (Opcode::StatusNow as u8).to_string()),
        (
            "opcode_set_flush_timeout",
            (Opcode::SetFlushTimeout as u8).to_string(),
        ),
        (
            "opcode_set_status_period",
            (Opcode::SetStatusPeriod as u8).to_string(),
        ),
        ("min_status_period", MIN_STATUS_PERIOD_TICKS.to_string()),
        ("max_flush_timeout", MAX_FLUSH_TIMEOUT_TICKS.to_string()),
        ("all_ports", ALL_PORTS.to_string()),
        ("result_ok", (AckResult::Ok as u8).to_string()),
        ("result_replay", (AckResult::Replay as u8).to_string()),
        ("result_other_box", (AckResult::OtherBox as u8).to_string()),
        (
            "result_unknown_opcode",
            (AckResult::UnknownOpcode as u8).to_string(),
        ),
        (
            "result_downlink_full",
            (AckResult::DownlinkFull as u8).to_string(),
        ),
        (
            "arguments_len",
            format!(
                "{{ [{}] = 4, [{}] = 4, [{}] = 0, [{}] = 0, [{}] = {CELL_COMMAND_LEN} }}",
                Opcode::SetFlushTimeout as u8,
                Opcode::SetStatusPeriod as u8,
                Opcode::StatusNow as u8,
                Opcode::ReadTick as u8,
                Opcode::CellCommand as u8
            ),
        ),
        ("cc_header", COMMAND_HEADER.to_string()),
        (
            "cc_arguments_end",
            format!(
                "{{ {} }}",
                CommandCode::ALL
                    .iter()
                    .map(|c| {
                        let end = cell_command::arguments_layout(*c)
                            .iter()
                            .filter(|r| r.name != "reserved")
                            .map(|r| r.bytes.end)
                            .max()
                            .unwrap_or(0);
                        format!("[{}] = {end}", *c as u8)
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ),
        ("cc_mode", (CommandCode::Mode as u8).to_string()),
        ("cc_rate", (CommandCode::SampleRate as u8).to_string()),
        ("cc_enable", (CommandCode::EnableMask as u8).to_string()),
        ("cc_max_mode", (CellMode::Event as u8).to_string()),
        ("cc_max_rate", (SampleRate::ALL.len() - 1).to_string()),
        (
            "cc_enable_reserved",
            (!ChannelMask::CHANNEL_BITS).to_string(),
        ),
        ("mask_second_part", MASK_SECOND_PART.to_string()),
        ("mask_reserved", reserved_mask.to_string()),
        ("tick_ns", TICK_NS.to_string()),
        ("udp_port", DEFAULT_PORT.to_string()),
        ("sequence_window", crate::sequence::WINDOW.to_string()),
        (
            "restart_tag_drop",
            crate::sequence::RESTART_TAG_DROP.to_string(),
        ),
    ];
    let _ = writeln!(w, "local C = {{");
    for (name, value) in constants {
        let _ = writeln!(w, "    {name} = {value},");
    }
    let _ = writeln!(w, "}}");
    out
}

/// The whole plugin: generated tables, then the dissection logic.
pub fn dissector_lua() -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "-- skinbox dissector for Wireshark and tshark (Lua), version {}.\n\
         -- Generated by `skinbox wireshark` from the skinbox-protocol crate's layouts;\n\
         -- do not edit: run `skinbox wireshark --install` again after a format change.\n",
        env!("CARGO_PKG_VERSION")
    );
    out.push_str(&tables());
    out.push('\n');
    out.push_str(LOGIC);
    out
}

/// Wireshark's folder for the user's own Lua plugins: `$XDG_CONFIG_HOME/wireshark/plugins`
/// when that folder exists, else `~/.local/lib/wireshark/plugins` (what `tshark -G folders`
/// calls "Personal Lua Plugins" on Linux).
pub fn personal_plugin_dir() -> Option<PathBuf> {
    if let Some(config) = std::env::var_os("XDG_CONFIG_HOME") {
        let dir = PathBuf::from(config).join("wireshark").join("plugins");
        if dir.is_dir() {
            return Some(dir);
        }
    }
    let home = std::env::var_os("HOME")?;
    Some(
        PathBuf::from(home)
            .join(".local")
            .join("lib")
            .join("wireshark")
            .join("plugins"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_layout_row_has_a_position_and_the_logic_names_only_known_fields() {
        let lua = dissector_lua();
        for f in formats() {
            for row in &f.rows {
                let line = format!(
                    "    {} = {{ {}, {} }},",
                    row.name,
                    row.bytes.start,
                    row.bytes.len()
                );
                assert!(lua.contains(&line), "{}.{}: {line}", f.name, row.name);
            }
        }
        // every `P.format.name` and `"format", "name"` the logic reads is a layout row
        let known: Vec<(String, String)> = formats()
            .iter()
            .flat_map(|f| {
                f.rows
                    .iter()
                    .map(|r| (f.name.to_string(), r.name.to_string()))
                    .collect::<Vec<_>>()
            })
            .collect();
        for (format, name) in quoted_pairs(LOGIC) {
            // `"value_" .. slot`: a prefix of numbered rows
            let numbered = name.ends_with('_')
                && known
                    .iter()
                    .any(|(f, n)| *f == format && n.starts_with(&name));
            assert!(
                numbered || known.contains(&(format.clone(), name.clone())),
                "the logic reads {format}.{name}, which no layout has"
            );
        }
    }

    /// `"format", "name"` argument pairs in the Lua logic.
    fn quoted_pairs(text: &str) -> Vec<(String, String)> {
        let formats: Vec<&str> = formats().iter().map(|f| f.name).collect();
        let mut pairs = vec![];
        for f in formats {
            let needle = format!("\"{f}\", \"");
            for (at, _) in text.match_indices(&needle) {
                let rest = &text[at + needle.len()..];
                if let Some(end) = rest.find('"') {
                    pairs.push((f.to_string(), rest[..end].to_string()));
                }
            }
            let needle = format!("P.{f}.");
            for (at, _) in text.match_indices(&needle) {
                let rest = &text[at + needle.len()..];
                let end = rest
                    .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                    .unwrap_or(rest.len());
                pairs.push((f.to_string(), rest[..end].to_string()));
            }
        }
        pairs
    }

    #[test]
    fn labels_read_as_words() {
        assert_eq!(label("tick_offset"), "Tick offset");
        assert_eq!(label("x"), "X");
    }
}
