//! A co-simulation pcap is a real capture: tshark reads it with checksum validation on and
//! finds nothing wrong, and the host client decodes exactly the packets that were sent.

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::harness::play;
use skinbox_cosim::line::{back_to_back, transitions};
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::{CellRepr, Channel, DataRepr, EventRepr, TICK_NS};
use std::process::Command;

#[test]
fn tshark_accepts_the_pcap_and_the_host_decodes_what_was_sent() {
    let config = BoxConfig {
        ports: 2,
        flush_timeout_ticks: 3_000,
        status_period_ticks: 40_000,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let mut sent: Vec<Vec<CellRepr>> = vec![vec![], vec![]];
    let mut lines = vec![];
    for (port, sent) in sent.iter_mut().enumerate() {
        let mut bytes = vec![];
        for k in 0..30u16 {
            let cell = if k % 3 == 0 {
                CellRepr::Event(
                    EventRepr::new(
                        100 + k,
                        k,
                        false,
                        &[(Channel::Proximity, i32::from(k) * 99)],
                    )
                    .unwrap(),
                )
            } else {
                CellRepr::Data(
                    DataRepr::from_raw(200 + k, [i32::from(k), -3, 256, 0, 7, 0, 300, 60, 0])
                        .unwrap(),
                )
            };
            bytes.extend(cell.to_bytes(&Default::default()));
            sent.push(cell);
        }
        // port 1 runs 1 % fast
        let bit_ns = 250.0 / (1.0 + port as f64 * 0.01);
        lines.push(transitions(&back_to_back(
            &bytes,
            20_000.0 + port as f64 * 777.0,
            bit_ns,
        )));
    }
    let out = play(&mut dut, &lines, 3, 200_000);
    let (frames, min_gap) = assemble(&out);
    assert!(min_gap.unwrap() >= 12);

    let dir = std::env::temp_dir().join(format!("skinbox-tshark-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cosim.pcap");
    let mut pcap = PcapFrameWriter::new(std::fs::File::create(&path).unwrap()).unwrap();
    for f in &frames {
        let (ethernet, _) = check(&f.bytes).unwrap();
        pcap.write_frame(
            std::time::Duration::from_nanos(f.first_cycle * TICK_NS),
            ethernet,
        )
        .unwrap();
    }
    pcap.finish().unwrap();

    // with the project's dissector, which claims the datagrams before Wireshark's ADwin
    // heuristic (which, without it, takes some payload lengths on any port)
    let plugin = dir.join(skinbox_host::wireshark::PLUGIN_FILE);
    std::fs::write(&plugin, skinbox_host::wireshark::dissector_lua()).unwrap();
    let tshark = Command::new("tshark")
        .arg("-X")
        .arg(format!("lua_script:{}", plugin.display()))
        .args(["-n", "-r"])
        .arg(&path)
        .args([
            "-o",
            "ip.check_checksum:TRUE",
            "-o",
            "udp.check_checksum:TRUE",
        ])
        .args([
            "-T",
            "fields",
            "-e",
            "frame.number",
            "-e",
            "frame.protocols",
            "-e",
            "skinbox.entry_count",
            "-e",
            "skinbox.kind",
            "-e",
            "ip.checksum.status",
            "-e",
            "udp.checksum.status",
            "-e",
            "_ws.malformed",
            "-e",
            "_ws.expert.severity",
        ])
        .output()
        .expect("run tshark (scripts/test installs it)");
    assert!(
        tshark.status.success(),
        "{}",
        String::from_utf8_lossy(&tshark.stderr)
    );
    let text = String::from_utf8(tshark.stdout).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split('\t').collect()).collect();
    assert_eq!(rows.len(), frames.len(), "{text}");
    let mut records_dissected = 0;
    for row in &rows {
        // every frame a skinbox datagram; checksum status 1 = good (0 bad, 2 unverified);
        // no malformed flag, no expert info of any severity
        assert_eq!(row[1], "eth:ethertype:ip:udp:skinbox", "frame {}", row[0]);
        if row[3] == "1" {
            records_dissected += row[2].parse::<usize>().unwrap();
        }
        assert_eq!((row[4], row[5]), ("1", "1"), "frame {}: {text}", row[0]);
        assert!(
            row[6..].iter().all(|f| f.is_empty()),
            "frame {}: {row:?}",
            row[0]
        );
    }
    assert_eq!(records_dissected, sent.iter().map(Vec::len).sum::<usize>());

    let decoded = skinbox_host::decode_pcap_file(&path, &Default::default()).unwrap();
    for (port, sent) in sent.iter().enumerate() {
        let got: Vec<CellRepr> = decoded
            .records
            .iter()
            .filter(|r| usize::from(r.port) == port)
            .map(|r| r.cell)
            .collect();
        assert_eq!(&got, sent, "port {port}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
