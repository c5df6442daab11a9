//! `skinbox examples`: what the formats look like on the wire, decoded.

use serde::Serialize;
use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
use skinbox_protocol::record::FLAG_LOSS_BEFORE;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::*;

#[derive(Serialize)]
struct Example {
    name: &'static str,
    hex: String,
    decoded: serde_json::Value,
    text: String,
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn example<T: Serialize + std::fmt::Display>(
    name: &'static str,
    bytes: &[u8],
    decoded: Result<T>,
) -> anyhow::Result<Example> {
    let decoded = decoded.map_err(|e| anyhow::anyhow!("example {name} does not decode: {e}"))?;
    Ok(Example {
        name,
        hex: hex(bytes),
        decoded: serde_json::to_value(&decoded)?,
        text: decoded.to_string(),
    })
}

/// Builds the examples: a resting cell's data packet, event packets of a touch, a records
/// datagram carrying them and a status datagram.
fn examples() -> anyhow::Result<Vec<Example>> {
    let framing = CellFraming::DEFAULT;
    // A cell at rest: 1 g on z, a little proximity, 30.5 C (docs/design.md section 2).
    let rest = DataRepr::from_raw(17, [2, -3, 258, 1, 0, 2, 310, 61, 0])?;
    // A touch: force and proximity fire together.
    let touch = EventRepr::new(
        17,
        41,
        false,
        &[
            (Channel::Force1, 212),
            (Channel::Force2, 180),
            (Channel::Proximity, 9_400),
        ],
    )?;
    // A hammer blow shakes everything: nine events split into two packets.
    let blow: Vec<_> = [60, -95, 511, 300, 280, 260, 12_000, 62, 1]
        .iter()
        .zip(Channel::ALL)
        .map(|(v, c)| (c, *v))
        .collect();
    let (blow_first, blow_second) = EventRepr::split(23, 7, &blow)?;
    let blow_second = blow_second.expect("nine events make two packets");

    let cells = [
        rest.to_bytes(),
        touch.to_bytes(),
        blow_first.to_bytes(),
        blow_second.to_bytes(),
    ];
    let records = cells
        .iter()
        .enumerate()
        .map(|(i, cell)| RecordRepr {
            port: if i == 0 { 0 } else { 3 },
            flags: if i == 2 { FLAG_LOSS_BEFORE } else { 0 },
            tick_offset: i as i32 * 6_250, // 50 us apart: back to back on one bus
            cell_packet: *cell,
        })
        .collect();
    let base_tick = TICKS_PER_SECOND * 12 + 4_321;
    let datagram = DatagramRepr {
        box_id: 1,
        port_count: 8,
        flags: FLAG_FLUSH_TIMEOUT,
        sequence: 1_024,
        base_tick,
        body: DatagramBody::Records(records),
    };
    let mut port3 = PortCounters::default();
    port3.set(PortCounter::PacketsGood, 48_112);
    port3.set(PortCounter::DroppedOverflow, 3);
    port3.set(PortCounter::FramingErrors, 1);
    port3.set(PortCounter::RejectedFraming, 1);
    let status = DatagramRepr {
        box_id: 1,
        port_count: 8,
        flags: 0,
        sequence: 1_025,
        base_tick: base_tick + 40_000,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 0x5eed_0001,
            datagrams_sent: 1_024,
            records_sent: 96_224,
            first_port: 2,
            ports: vec![PortCounters::default(), port3],
        }),
    };

    let datagram_bytes = datagram.to_bytes();
    let status_bytes = status.to_bytes();
    Ok(vec![
        example(
            "data packet",
            &cells[0],
            CellRepr::parse(&cells[0], &framing),
        )?,
        example(
            "event packet",
            &cells[1],
            CellRepr::parse(&cells[1], &framing),
        )?,
        example(
            "event packet, 1st of 2",
            &cells[2],
            CellRepr::parse(&cells[2], &framing),
        )?,
        example(
            "event packet, 2nd of 2",
            &cells[3],
            CellRepr::parse(&cells[3], &framing),
        )?,
        example(
            "records datagram",
            &datagram_bytes,
            DatagramRepr::parse(&datagram_bytes),
        )?,
        example(
            "status datagram",
            &status_bytes,
            DatagramRepr::parse(&status_bytes),
        )?,
    ])
}

/// Prints the examples.
pub fn run(json: bool) -> anyhow::Result<()> {
    let examples = examples()?;
    if json {
        return super::print_json(&examples);
    }
    for e in examples {
        println!("{} ({} bytes)", e.name, e.hex.len().div_ceil(3));
        for line in e.hex.as_bytes().chunks(16 * 3) {
            println!("  {}", String::from_utf8_lossy(line).trim_end());
        }
        for line in e.text.lines() {
            println!("  {line}");
        }
        println!();
    }
    Ok(())
}
