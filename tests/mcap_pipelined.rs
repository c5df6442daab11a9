//! `skinbox decode --mcap` and `capture --mcap` write through [`RosSink::pipelined`] (the
//! messages and the file on a thread of their own): the recording is byte for byte the one
//! [`RosSink::new`] writes on one thread, and an output's error still ends in an error.

use skinbox_cosim::synthetic::{generate, SyntheticConfig};
use skinbox_host::decoder::{Decoder, DecoderConfig};
use skinbox_host::sample_clock::{PathModel, Positions};
use skinbox_host::timing::Timing;
use skinbox_host::RecordSink;
use skinbox_ros::mcap_out::McapOutput;
use skinbox_ros::sink::{Output, Published, RosSink, SinkSettings, Topic};
use std::time::Duration;

fn decode(
    payloads: &[Vec<u8>],
    outputs: Vec<Box<dyn Output + Send>>,
    pipelined: bool,
) -> std::io::Result<Published> {
    let timing = Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
    let mut sink = if pipelined {
        RosSink::pipelined(timing, SinkSettings::default(), outputs)?
    } else {
        RosSink::new(timing, SinkSettings::default(), outputs)
    };
    let mut decoder = Decoder::new(DecoderConfig::default());
    let t0 = Duration::from_secs(1_700_000_000);
    for (i, p) in payloads.iter().enumerate() {
        // 1 ms apart: an activity message every 100 datagrams.
        sink.datagram_received(Some(t0 + Duration::from_millis(i as u64)), None, p);
        decoder.push_datagram(p, &mut sink);
    }
    sink.finish()
}

#[test]
fn the_pipelined_recording_is_the_one_thread_recording() {
    // 2,677 samples in 200 datagrams: several of the pipeline's batches; status every 100 ms.
    let payloads = generate(&SyntheticConfig::default()).unwrap().payloads();
    let dir = std::env::temp_dir().join(format!("skinbox-mcap-pipelined-{}", std::process::id()));
    let mut files = Vec::new();
    let mut published = Vec::new();
    for pipelined in [false, true] {
        let way = dir.join(if pipelined { "pipelined" } else { "one-thread" });
        std::fs::create_dir_all(&way).unwrap();
        let path = way.join("rec.mcap");
        let out = McapOutput::create(&path).unwrap();
        published.push(decode(&payloads, vec![Box::new(out)], pipelined).unwrap());
        files.push(std::fs::read(&path).unwrap());
    }
    let _ = std::fs::remove_dir_all(&dir);
    let p = published[0];
    assert!(
        p.samples > 2_000 && p.status_messages > 0 && p.activity_messages > 0,
        "{p:?}"
    );
    assert_eq!(published[0], published[1]);
    assert!(files[0] == files[1], "the two recordings differ");
}

/// Takes `left` messages, then fails.
struct Failing {
    left: usize,
    closed: bool,
}

impl Output for Failing {
    fn publish(&mut self, _: Topic, _: u64, _: &[u8]) -> std::io::Result<()> {
        if self.left == 0 {
            return Err(std::io::Error::other("disk full"));
        }
        self.left -= 1;
        Ok(())
    }

    fn close(&mut self) -> std::io::Result<()> {
        self.closed = true;
        Ok(())
    }
}

#[test]
fn an_outputs_error_ends_the_pipelined_sink_in_that_error() {
    let payloads = generate(&SyntheticConfig::default()).unwrap().payloads();
    for pipelined in [false, true] {
        let out = Failing {
            left: 10,
            closed: false,
        };
        let e = decode(&payloads, vec![Box::new(out)], pipelined).unwrap_err();
        assert_eq!(e.to_string(), "disk full", "pipelined {pipelined}");
    }
}
