//! Fuzzes the pcap path: any bytes as a pcap file, through frames to datagrams.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinbox_host::pcap::{decode_pcap_bytes, PcapOptions};

fuzz_target!(|data: &[u8]| {
    let _ = decode_pcap_bytes(data, &PcapOptions::default());
});
