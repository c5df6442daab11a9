//! The verilated box, driven through the safe `Dut`: a cell packet on a pin comes out as
//! a record in a valid Ethernet frame (checked by `frames::check`: crc crate, etherparse).

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::{BoxConfig, RESET_LATENCY};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{DataRepr, DatagramRepr};

#[test]
fn a_packet_on_a_pin_becomes_a_record() {
    let config = BoxConfig {
        ports: 2,
        flush_timeout_ticks: 1_000,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let mut out = vec![];
    dut.set_reset(true);
    dut.run(3, |b| out.push(b));
    dut.set_reset(false);
    dut.run(997, |b| out.push(b));
    // 8N1 at exactly 31.25 clocks per bit, start bit from cycle 1000 on (edges 1001...)
    let packet = DataRepr::from_raw(77, [1, 2, 3, 4, 5, 6, 7, 8, 9])
        .unwrap()
        .to_bytes();
    let mut levels = vec![];
    for byte in packet {
        levels.push(false);
        levels.extend((0..8).map(|i| byte >> i & 1 == 1));
        levels.push(true);
    }
    let mut t = 1000.0_f64;
    for level in levels {
        let until = t + 31.25;
        let cycles = (until.ceil() - t.ceil()) as u64;
        dut.set_rx(1, level);
        dut.run(cycles, |b| out.push(b));
        t = until;
    }
    dut.run(5_000, |b| out.push(b));
    assert_eq!(dut.tx_errors(), 0);

    let (frames, _) = assemble(&out);
    let datagrams: Vec<DatagramRepr> = frames
        .iter()
        .map(|f| DatagramRepr::parse(check(&f.bytes).unwrap().1).unwrap())
        .collect();
    assert_eq!(datagrams.len(), 2, "status at boot, then the records");
    let DatagramBody::Records(records) = &datagrams[1].body else {
        panic!("records expected")
    };
    assert_eq!(records.len(), 1);
    assert_eq!((records[0].port, records[0].cell_packet), (1, packet));
    // reset pin high for cycles 1..=3, the box's reset register one more: the tick reads
    // e - 3 - RESET_LATENCY after edge e; edge 1001 sampled low
    assert_eq!(
        records[0].tick(datagrams[1].base_tick),
        1001 - 3 - RESET_LATENCY
    );
}
