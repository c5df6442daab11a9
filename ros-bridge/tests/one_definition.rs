//! One definition: what the Rust side writes is decoded by a CDR decoder that reads only
//! the `.msg` files of `ros/skinbox_msgs`, and must say the same, field by field; the
//! `.msg` constants are the Rust side's; the schema text carries the files as they are.
//! A field changed in a `.msg` file without the Rust side (or the reverse) fails here.

use skinbox_host::rows::{
    HOST_TIME_EXCHANGES, HOST_TIME_NONE, HOST_TIME_RECEIVE_STAMPS, KIND_DATA, KIND_EVENT,
};
use skinbox_protocol::box_counters::LinkSpeed;
use skinbox_protocol::status::{PortCounter, PortCounters as Wire};
use skinbox_ros::cdr::CdrWriter;
use skinbox_ros::msg::*;
use skinbox_ros::msgdef::{self, Value};

/// Distinct values in every field, so a swapped or shifted field shows.
fn sample(i: u16) -> CellSample {
    let mut values = [f64::NAN; 9];
    for (k, v) in values.iter_mut().enumerate() {
        if k % 2 == 0 {
            *v = f64::from(i) + k as f64 / 16.0;
        }
    }
    CellSample {
        box_id: 7 + i,
        port: 3,
        cell_id: 300 + i,
        kind: KIND_EVENT,
        event_mask: 0b1_0101_0101,
        values,
        event_sequence: -5 - i32::from(i),
        second_part: true,
        event_packets_missing_before: 11,
        flags: 1,
        datagram_sequence: 0xDEAD_0000 + u32::from(i),
        box_time_ns: 123_456_789_000 + u64::from(i),
        sample_box_time_ns: 123_456_000_000.5,
        host_time_ns: 1_700_000_000_123_456_789,
        host_time_bound_ns: 812.0,
        host_time_source: HOST_TIME_EXCHANGES,
    }
}

fn check<M: RosMessage>(m: &M) {
    let mut w = CdrWriter::new();
    m.encode(&mut w);
    let decoded = msgdef::decode(M::NAME, w.bytes()).unwrap_or_else(|e| {
        panic!(
            "{}: the .msg file reads the Rust bytes otherwise: {e}",
            M::NAME
        )
    });
    let Value::Message(fields) = decoded else {
        panic!("{}: not a message", M::NAME)
    };
    let ours = m.fields();
    let names = |v: &[(String, Value)]| v.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(
        names(&fields),
        names(&ours),
        "{}: field names and order",
        M::NAME
    );
    for ((name, theirs), (_, ours)) in fields.iter().zip(&ours) {
        assert_eq!(theirs, ours, "{}.{name}", M::NAME);
    }
}

#[test]
fn every_message_reads_back_through_its_msg_file() {
    check(&Time {
        sec: 17,
        nanosec: 999,
    });
    check(&sample(1));
    check(&CellSampleBatch {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 5,
        },
        box_id: 2,
        box_address: "127.0.0.1:5000".into(),
        datagram_sequence: 77,
        samples: (0..3).map(sample).collect(),
    });
    check(&CellSampleBatch::default());
    let mut counters = Wire::default();
    for c in PortCounter::ALL {
        counters.set(c, 1000 + c.index() as u32);
    }
    let port = |p| PortCounters { port: p, counters };
    check(&port(4));
    check(&BoxStatus {
        stamp: Time { sec: 3, nanosec: 4 },
        box_id: 9,
        box_address: "10.0.0.2:54090".into(),
        boot_id: 0xABCD,
        link_up: true,
        link_speed: 2,
        datagrams_sent: 55,
        records_sent: 66,
        ports: vec![port(0), port(1)],
        datagrams_received: 101,
        datagrams_missing: 102,
        records_received: 103,
        event_packets_missing: 104,
        records_flagged_loss_before: 105,
        host_time_source: HOST_TIME_RECEIVE_STAMPS,
        drift_ppm: -3.25,
        time_error_bound_ns: f64::NAN,
        time_map_restarts: 106,
    });
    check(&SkinActivity {
        stamp: Time { sec: 8, nanosec: 9 },
        box_id: 1,
        period_s: 0.1,
        channel: 3,
        channel_name: "force_1".into(),
        ports: vec![PortActivity {
            port: 2,
            packets_per_s: 125.5,
            events_per_s: 300.25,
            cells_active: 65,
            channel_max: 0.75,
            channel_mean: f64::NAN,
        }],
        datagrams_missing: 1,
        event_packets_missing: 2,
    });
}

#[test]
fn the_constants_are_the_rust_sides() {
    let consts = msgdef::constants().unwrap();
    let get = |msg: &str, name: &str| -> u64 {
        let c = consts
            .get(&(format!("skinbox_msgs/{msg}"), name.to_string()))
            .unwrap_or_else(|| panic!("{msg}.{name} is missing"));
        c.value.parse().unwrap()
    };
    assert_eq!(get("CellSample", "KIND_DATA"), u64::from(KIND_DATA));
    assert_eq!(get("CellSample", "KIND_EVENT"), u64::from(KIND_EVENT));
    assert_eq!(
        get("CellSample", "HOST_TIME_NONE"),
        u64::from(HOST_TIME_NONE)
    );
    assert_eq!(
        get("CellSample", "HOST_TIME_RECEIVE_STAMPS"),
        u64::from(HOST_TIME_RECEIVE_STAMPS)
    );
    assert_eq!(
        get("CellSample", "HOST_TIME_EXCHANGES"),
        u64::from(HOST_TIME_EXCHANGES)
    );
    assert_eq!(get("BoxStatus", "LINK_SPEED_10M"), LinkSpeed::Mbit10 as u64);
    assert_eq!(
        get("BoxStatus", "LINK_SPEED_100M"),
        LinkSpeed::Mbit100 as u64
    );
    assert_eq!(
        get("BoxStatus", "LINK_SPEED_1000M"),
        LinkSpeed::Mbit1000 as u64
    );
    assert_eq!(
        get("BoxStatus", "LINK_SPEED_UNKNOWN"),
        LinkSpeed::Unknown as u64
    );
    // the values array holds the protocol's nine channels
    let def = msgdef::definition("skinbox_msgs/CellSample").unwrap();
    let values = def.fields.iter().find(|f| f.name == "values").unwrap();
    assert_eq!(
        values.arity,
        msgdef::Arity::Fixed(skinbox_protocol::Channel::COUNT)
    );
}

#[test]
fn the_schema_text_is_the_msg_files_with_their_dependencies() {
    let text = msgdef::schema_text("skinbox_msgs/CellSampleBatch").unwrap();
    let sep = format!("{}\n", "=".repeat(80));
    let parts: Vec<&str> = text.split(&sep).collect();
    assert_eq!(parts.len(), 3, "{text}");
    assert_eq!(
        parts[0],
        msgdef::definition_text("skinbox_msgs/CellSampleBatch").unwrap()
    );
    assert!(parts[1].starts_with("MSG: builtin_interfaces/Time\n"));
    assert!(parts[2].starts_with("MSG: skinbox_msgs/CellSample\n"));
    assert_eq!(
        CellSampleBatch::type_name(),
        "skinbox_msgs/msg/CellSampleBatch"
    );
    // the CMakeLists names every .msg file the Rust side compiles in
    let cmake = include_str!("../../ros/skinbox_msgs/CMakeLists.txt");
    for (name, _) in msgdef::DEFINITIONS {
        if let Some(msg) = name.strip_prefix("skinbox_msgs/") {
            assert!(
                cmake.contains(&format!("\"msg/{msg}.msg\"")),
                "{msg} not in CMakeLists.txt"
            );
        }
    }
    let files = std::fs::read_dir(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../ros/skinbox_msgs/msg"
    ))
    .unwrap()
    .count();
    assert_eq!(
        files,
        msgdef::DEFINITIONS.len() - 1,
        "a .msg file the Rust side does not know"
    );
}

#[test]
fn a_changed_msg_file_is_caught() {
    // The decoder on a definition with one field retyped reads the bytes otherwise.
    let text = msgdef::definition_text("skinbox_msgs/PortActivity").unwrap();
    let changed = text.replace("uint16 cells_active", "uint32 cells_active");
    let def = msgdef::parse("skinbox_msgs", &changed).unwrap();
    let original = msgdef::parse("skinbox_msgs", text).unwrap();
    assert_ne!(def, original);
    let bad = msgdef::parse("skinbox_msgs", "uint8 ok\nnonsense\n");
    assert!(bad.unwrap_err().contains("line 2"));
}

/// A message with a part of a batch's samples (as DDS sends a large datagram's) is the
/// batch with only those samples, byte for byte, and reads back through the `.msg` file;
/// nine samples fit the largest message rustdds sends unfragmented.
#[test]
fn a_batch_in_parts_is_batches_of_its_samples() {
    let batch = CellSampleBatch {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 5,
        },
        box_id: 2,
        box_address: "192.168.100.200:54091".into(),
        datagram_sequence: 77,
        samples: (0..23).map(sample).collect(),
    };
    let mut w = CdrWriter::new();
    for size in 1..=batch.samples.len() {
        for part in batch.samples.chunks(size) {
            batch.encode_header(&mut w);
            let header = w.len();
            w.truncate(header);
            batch.encode_samples(&mut w, part);
            let alone = CellSampleBatch {
                samples: part.to_vec(),
                ..batch.clone()
            };
            let mut v = CdrWriter::new();
            alone.encode(&mut v);
            assert_eq!(w.bytes(), v.bytes(), "{size} samples a part");
            check(&alone);
        }
    }
    batch.encode_header(&mut w);
    batch.encode_samples(&mut w, &batch.samples[..9]);
    assert!(
        w.len() <= skinbox_ros::dds::MAX_UNFRAGMENTED_MESSAGE_BYTES,
        "{} bytes",
        w.len()
    );
}
