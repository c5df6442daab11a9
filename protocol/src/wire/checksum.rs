//! The Internet checksum (RFC 1071) of IPv4 headers, ICMP messages and UDP datagrams, and
//! the IPv4 pseudo header UDP sums over (RFC 768).

/// The one's complement of the one's complement sum of the 16-bit words of `parts`: 0 over
/// bytes whose checksum field is right, the value to write over bytes whose field is 0. An
/// odd part is padded with a zero byte (only the last part may be odd).
pub fn checksum(parts: &[&[u8]]) -> u16 {
    let mut sum: u64 = 0;
    for part in parts {
        for pair in part.chunks(2) {
            sum += u64::from(u16::from_be_bytes([
                pair[0],
                pair.get(1).copied().unwrap_or(0),
            ]));
        }
        // fold as we go so that no length of input overflows
        sum = u64::from(fold(sum));
    }
    !fold(sum)
}

/// A plain sum of 16-bit words folded to 16 bits, each carry added back in (end-around):
/// their one's complement sum.
pub fn fold(mut sum: u64) -> u16 {
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    sum as u16
}

/// The IPv4 pseudo header of a transport message (RFC 768): source, destination, zero,
/// protocol and the message's length.
pub fn ipv4_pseudo_header(
    source: [u8; 4],
    destination: [u8; 4],
    protocol: u8,
    length: u16,
) -> [u8; 12] {
    let [s0, s1, s2, s3] = source;
    let [d0, d1, d2, d3] = destination;
    let [l0, l1] = length.to_be_bytes();
    [s0, s1, s2, s3, d0, d1, d2, d3, 0, protocol, l0, l1]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RFC 1071 section 3: the words 0001 f203 f4f5 f6f7 sum to ddf2.
    #[test]
    fn rfc_1071_example() {
        let bytes = [0x00, 0x01, 0xF2, 0x03, 0xF4, 0xF5, 0xF6, 0xF7];
        assert_eq!(checksum(&[&bytes]), !0xDDF2);
        // split anywhere even, the same
        assert_eq!(checksum(&[&bytes[..2], &bytes[2..6], &bytes[6..]]), !0xDDF2);
        // with its checksum appended the sum verifies to 0
        let mut with = bytes.to_vec();
        with.extend_from_slice(&(!0xDDF2u16).to_be_bytes());
        assert_eq!(checksum(&[&with]), 0);
    }

    #[test]
    fn an_odd_tail_is_padded_with_zero() {
        assert_eq!(checksum(&[&[0x12, 0x34, 0x56]]), !0x6834);
    }
}
