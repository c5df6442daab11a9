//! Checks one Ethernet frame as it left the box on GMII, with code that is not the box's:
//! preamble and SFD, FCS with the crc crate, Ethernet II / IPv4 / UDP structure, lengths
//! and both checksums with etherparse, zero padding, minimum size. Used by the gateware's
//! block tests and by the co-simulation.

/// What is wrong with a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Shorter than the preamble and the 64-byte minimum frame.
    #[error("{len} bytes: shorter than preamble + 64-byte minimum frame")]
    TooShort {
        /// The frame's length, preamble to FCS.
        len: usize,
    },
    /// The preamble and SFD are not 7 x 0x55 and 0xD5.
    #[error("preamble/SFD {0:02x?}")]
    Preamble([u8; 8]),
    /// The FCS does not match the frame (little-endian bytes as on the wire).
    #[error("FCS {found:02x?}, computed {computed:02x?}")]
    Fcs {
        /// FCS bytes of the frame.
        found: [u8; 4],
        /// FCS computed over the frame.
        computed: [u8; 4],
    },
    /// etherparse could not read the Ethernet, IPv4 or UDP headers.
    #[error("headers: {0}")]
    Headers(String),
    /// Not an IPv4 packet.
    #[error("not IPv4")]
    NotIpv4,
    /// The IPv4 header checksum is wrong.
    #[error("IPv4 checksum {found:#06x}, computed {computed:#06x}")]
    Ipv4Checksum {
        /// Checksum in the header.
        found: u16,
        /// Checksum computed over the header.
        computed: u16,
    },
    /// Not a UDP datagram.
    #[error("not UDP")]
    NotUdp,
    /// The IPv4 and UDP lengths do not agree with each other or the frame.
    #[error("lengths: IPv4 total {ipv4_total}, UDP {udp}")]
    Lengths {
        /// IPv4 total length.
        ipv4_total: u16,
        /// UDP length.
        udp: u16,
    },
    /// The UDP checksum is wrong.
    #[error("UDP checksum {found:#06x}, computed {computed:#06x}")]
    UdpChecksum {
        /// Checksum in the header.
        found: u16,
        /// Checksum computed over header and payload.
        computed: u16,
    },
    /// Bytes after the IPv4 packet that are not zero.
    #[error("non-zero padding after the IPv4 packet")]
    Padding,
    /// [`encode`] could not build the frame (the payload does not fit one IPv4 packet).
    #[error("encoding: {0}")]
    Encode(String),
}

/// Checks a frame with code that is not the box's: preamble and SFD, FCS with the crc
/// crate, Ethernet II / IPv4 / UDP with etherparse (both checksums, lengths), zero
/// padding, minimum size. Returns the Ethernet frame without preamble and FCS, and the
/// UDP payload.
pub fn check(frame: &[u8]) -> Result<(&[u8], &[u8]), FrameError> {
    use etherparse::{NetHeaders, PacketHeaders, TransportHeader};
    if frame.len() < 8 + 64 {
        return Err(FrameError::TooShort { len: frame.len() });
    }
    if frame[..7] != [0x55; 7] || frame[7] != 0xD5 {
        let mut preamble = [0; 8];
        preamble.copy_from_slice(&frame[..8]);
        return Err(FrameError::Preamble(preamble));
    }
    let (ethernet, fcs) = frame[8..].split_at(frame.len() - 12);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(ethernet);
    if fcs != crc.to_le_bytes() {
        let mut found = [0; 4];
        found.copy_from_slice(fcs);
        return Err(FrameError::Fcs {
            found,
            computed: crc.to_le_bytes(),
        });
    }
    let headers = PacketHeaders::from_ethernet_slice(ethernet)
        .map_err(|e| FrameError::Headers(e.to_string()))?;
    let Some(NetHeaders::Ipv4(ip, _)) = &headers.net else {
        return Err(FrameError::NotIpv4);
    };
    if ip.header_checksum != ip.calc_header_checksum() {
        return Err(FrameError::Ipv4Checksum {
            found: ip.header_checksum,
            computed: ip.calc_header_checksum(),
        });
    }
    let Some(TransportHeader::Udp(udp)) = &headers.transport else {
        return Err(FrameError::NotUdp);
    };
    let rest = headers.payload.slice();
    let udp_len = usize::from(udp.length);
    if udp_len < 8 || udp_len - 8 > rest.len() || usize::from(ip.total_len) != 20 + udp_len {
        return Err(FrameError::Lengths {
            ipv4_total: ip.total_len,
            udp: udp.length,
        });
    }
    let payload = &rest[..udp_len - 8];
    let sum = udp
        .calc_checksum_ipv4(ip, payload)
        .map_err(|e| FrameError::Headers(e.to_string()))?;
    if udp.checksum != sum {
        return Err(FrameError::UdpChecksum {
            found: udp.checksum,
            computed: sum,
        });
    }
    // padding: the bytes after the IPv4 packet (etherparse's payload stops at its end)
    let packet_end = 14 + usize::from(ip.total_len);
    if ethernet
        .get(packet_end..)
        .is_some_and(|pad| pad.iter().any(|b| *b != 0))
    {
        return Err(FrameError::Padding);
    }
    Ok((ethernet, payload))
}

/// Addresses of a UDP frame for [`encode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpAddresses {
    /// Source MAC.
    pub source_mac: [u8; 6],
    /// Destination MAC.
    pub destination_mac: [u8; 6],
    /// Source IPv4 address.
    pub source_ip: [u8; 4],
    /// Destination IPv4 address.
    pub destination_ip: [u8; 4],
    /// Source UDP port.
    pub source_port: u16,
    /// Destination UDP port.
    pub destination_port: u16,
}

/// Builds the frame a box sends for `payload`, with etherparse and the crc crate (not the
/// box's code): preamble and SFD, Ethernet II, IPv4 (identification 0, don't fragment,
/// TTL 64), UDP with its checksum, zero padding to the 60-byte minimum, FCS. Fails when
/// the payload does not fit one IPv4 packet.
pub fn encode(addresses: &UdpAddresses, payload: &[u8]) -> Result<Vec<u8>, FrameError> {
    let a = addresses;
    let mut ip = etherparse::Ipv4Header::new(
        0,
        64,
        etherparse::IpNumber::UDP,
        a.source_ip,
        a.destination_ip,
    )
    .map_err(|e| FrameError::Encode(e.to_string()))?;
    ip.dont_fragment = true;
    let builder = etherparse::PacketBuilder::ethernet2(a.source_mac, a.destination_mac)
        .ip(etherparse::IpHeaders::Ipv4(ip, Default::default()))
        .udp(a.source_port, a.destination_port);
    let mut ethernet = Vec::with_capacity(builder.size(payload.len()).max(60));
    builder
        .write(&mut ethernet, payload)
        .map_err(|e| FrameError::Encode(e.to_string()))?;
    ethernet.resize(ethernet.len().max(60), 0);
    let mut frame = vec![0x55; 7];
    frame.push(0xD5);
    frame.extend_from_slice(&ethernet);
    let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&ethernet);
    frame.extend_from_slice(&fcs.to_le_bytes());
    Ok(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Preamble, an Ethernet/IPv4/UDP frame built by etherparse, zero padding to 60 bytes,
    /// and the FCS.
    fn frame(payload: &[u8]) -> Vec<u8> {
        let builder = etherparse::PacketBuilder::ethernet2([2, 0, 0, 0, 0, 1], [0xFF; 6])
            .ipv4([192, 0, 2, 10], [192, 0, 2, 1], 64)
            .udp(54091, 54091);
        let mut ethernet = Vec::new();
        builder.write(&mut ethernet, payload).unwrap();
        ethernet.resize(ethernet.len().max(60), 0);
        with_fcs(&ethernet)
    }

    /// A valid IPv4 frame that carries TCP.
    fn tcp_frame() -> Vec<u8> {
        let builder = etherparse::PacketBuilder::ethernet2([2, 0, 0, 0, 0, 1], [0xFF; 6])
            .ipv4([192, 0, 2, 10], [192, 0, 2, 1], 64)
            .tcp(54091, 80, 1, 1024);
        let mut ethernet = Vec::new();
        builder.write(&mut ethernet, &[0; 20]).unwrap();
        with_fcs(&ethernet)
    }

    fn with_fcs(ethernet: &[u8]) -> Vec<u8> {
        let mut out = vec![0x55; 7];
        out.push(0xD5);
        out.extend_from_slice(ethernet);
        let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(ethernet);
        out.extend_from_slice(&fcs.to_le_bytes());
        out
    }

    /// Changes one byte of the Ethernet part and recomputes the FCS, so only the layer under
    /// test is wrong.
    fn corrupt(frame: &[u8], at: usize) -> Vec<u8> {
        let mut ethernet = frame[8..frame.len() - 4].to_vec();
        ethernet[at] ^= 0x40;
        with_fcs(&ethernet)
    }

    #[test]
    fn encoded_frames_pass_the_check_and_carry_their_payload() {
        let a = UdpAddresses {
            source_mac: [2, 0x53, 0x4B, 0, 0, 1],
            destination_mac: [0xFF; 6],
            source_ip: [192, 0, 2, 10],
            destination_ip: [192, 0, 2, 1],
            source_port: 54091,
            destination_port: 54091,
        };
        for len in [0, 1, 17, 18, 19, 100, 1472] {
            let payload: Vec<u8> = (0..len).map(|i| (i * 7 + 3) as u8).collect();
            let frame = encode(&a, &payload).unwrap();
            assert_eq!(frame.len(), 8 + (14 + 28 + len).max(60) + 4, "{len}");
            let (ethernet, got) = check(&frame).unwrap();
            assert_eq!(got, &payload[..]);
            // IPv4 flags: don't fragment, no offset; identification 0; TTL 64
            assert_eq!(&ethernet[18..23], &[0, 0, 0x40, 0, 64]);
        }
        assert!(
            encode(&a, &[0; 65_508]).is_err(),
            "IPv4 holds at most 65,507 UDP payload bytes"
        );
    }

    #[test]
    fn a_good_frame_gives_its_payload() {
        for len in [0, 1, 5, 100, 1472] {
            let payload: Vec<u8> = (0..len).map(|i| (i * 7) as u8).collect();
            let f = frame(&payload);
            let (ethernet, got) = check(&f).unwrap();
            assert_eq!(got, &payload[..], "payload of {len} bytes");
            assert_eq!(ethernet.len(), f.len() - 12);
        }
    }

    #[test]
    fn every_kind_of_damage_is_named() {
        use FrameError as E;
        let good = frame(b"sixteen bytes...");
        type Is = fn(&FrameError) -> bool;
        let cases: Vec<(Vec<u8>, Is, &str)> = vec![
            (
                good[..70].to_vec(),
                |e| matches!(e, E::TooShort { len: 70 }),
                "shorter than",
            ),
            (
                [
                    &[0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0xD4][..],
                    &good[8..],
                ]
                .concat(),
                |e| matches!(e, E::Preamble(p) if p[7] == 0xD4),
                "preamble",
            ),
            (
                {
                    let mut f = good.clone();
                    *f.last_mut().unwrap() ^= 1;
                    f
                },
                |e| matches!(e, E::Fcs { found, computed } if found != computed),
                "FCS",
            ),
            // TTL
            (
                corrupt(&good, 14 + 8),
                |e| matches!(e, E::Ipv4Checksum { .. }),
                "IPv4 checksum",
            ),
            // first payload byte
            (
                corrupt(&good, 14 + 20 + 8),
                |e| matches!(e, E::UdpChecksum { .. }),
                "UDP checksum",
            ),
            // EtherType
            (corrupt(&good, 12), |e| *e == E::NotIpv4, "not IPv4"),
            // IP protocol: the header checksum is then stale, and caught first
            (
                corrupt(&good, 14 + 9),
                |e| matches!(e, E::Ipv4Checksum { .. }),
                "IPv4 checksum",
            ),
            (tcp_frame(), |e| *e == E::NotUdp, "not UDP"),
        ];
        for (frame, is, expected) in cases {
            let err = check(&frame).expect_err(expected);
            assert!(is(&err), "{expected}: got {err:?}");
            assert!(err.to_string().contains(expected), "{expected}: got {err}");
        }
        // non-zero padding after a short payload
        let mut ethernet = good[8..good.len() - 4].to_vec();
        *ethernet.last_mut().unwrap() = 7;
        let err = check(&with_fcs(&ethernet)).unwrap_err();
        assert_eq!(err, E::Padding);
        assert!(err.to_string().contains("padding"), "{err}");
        // too big for one IPv4 packet
        assert!(matches!(
            encode(
                &UdpAddresses {
                    source_mac: [0; 6],
                    destination_mac: [0; 6],
                    source_ip: [0; 4],
                    destination_ip: [0; 4],
                    source_port: 0,
                    destination_port: 0,
                },
                &[0; 65_508]
            ),
            Err(E::Encode(_))
        ));
    }
}
