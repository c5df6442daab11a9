//! The verilated box, driven through the safe `Dut`: a cell packet on a pin comes out as
//! a record in a valid Ethernet frame.

use skinbox_cosim::{Dut, GmiiByte, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{DataRepr, DatagramRepr};

/// Frames from GMII bytes: a frame ends where consecutive cycles stop.
fn frames(bytes: &[GmiiByte]) -> Vec<Vec<u8>> {
    let mut frames: Vec<Vec<u8>> = vec![];
    let mut last = None;
    for b in bytes {
        if last != Some(b.cycle - 1) {
            frames.push(vec![]);
        }
        frames.last_mut().unwrap().push(b.data);
        last = Some(b.cycle);
    }
    frames
}

/// The UDP payload after checking the FCS with the crc crate and the checksums with
/// etherparse.
fn payload(frame: &[u8]) -> Vec<u8> {
    assert_eq!(
        &frame[..8],
        &[0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0xD5]
    );
    let (body, fcs) = frame[8..].split_at(frame.len() - 12);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(body);
    assert_eq!(fcs, crc.to_le_bytes());
    let h = etherparse::PacketHeaders::from_ethernet_slice(body).unwrap();
    let Some(etherparse::NetHeaders::Ipv4(ip, _)) = &h.net else {
        panic!("not IPv4")
    };
    assert_eq!(ip.header_checksum, ip.calc_header_checksum());
    let Some(etherparse::TransportHeader::Udp(udp)) = &h.transport else {
        panic!("not UDP")
    };
    let data = &h.payload.slice()[..usize::from(udp.length) - 8];
    assert_eq!(udp.checksum, udp.calc_checksum_ipv4(ip, data).unwrap());
    data.to_vec()
}

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

    let datagrams: Vec<DatagramRepr> = frames(&out)
        .iter()
        .map(|f| DatagramRepr::parse(&payload(f)).unwrap())
        .collect();
    assert_eq!(datagrams.len(), 2, "status at boot, then the records");
    let DatagramBody::Records(records) = &datagrams[1].body else {
        panic!("records expected")
    };
    assert_eq!(records.len(), 1);
    assert_eq!((records[0].port, records[0].cell_packet), (1, packet));
    // reset for cycles 1..=3: the tick reads e - 3 after edge e; edge 1001 sampled low
    assert_eq!(records[0].tick(datagrams[1].base_tick), 1001 - 3);
}
