//! MacReceiver: Ethernet frames from GMII receive signals (in the box clock), as a byte
//! stream with the frame check done.
//!
//! A carrier (`gmii_rx_dv` high) starts with a preamble: any number of 0x55 bytes (none
//! too), then the start-of-frame delimiter 0xD5. A carrier whose first byte other than
//! 0x55 is not 0xD5 carries no frame: it gives no beat at all (a false start the PHY
//! should not send; nothing after it could be found reliably).
//!
//! After the SFD every byte is a beat (destination MAC first, FCS included). The block
//! holds one byte back so that it knows which byte is the last (the carrier fell after
//! it): that beat has `last`, and `error` when the frame is bad:
//!
//! - its length, FCS included, is outside [`MIN_RECEIVE_LEN`]..=[`MAX_RECEIVE_LEN`]:
//!   `length_error` is high with that beat too;
//! - its CRC-32 over all bytes including the FCS does not leave the residue
//!   [`CRC_RESIDUE`] (a wrong FCS);
//! - `gmii_rx_er` was high in a clock of the carrier (preamble or frame): the PHY saw a
//!   symbol error, so the bytes are not trustworthy; the frame counts as a bad FCS
//!   (`error` without `length_error`).
//!
//! A frame longer than [`MAX_RECEIVE_LEN`] gives its first [`MAX_RECEIVE_LEN`] bytes as
//! beats (none with `last`); when the carrier ends, one more beat with data 0 carries
//! `last`, `error` and `length_error`. A carrier that ends right after the SFD gives that
//! beat alone. So every frame that began with an SFD ends with one `last` beat and can be
//! counted. The MAC never waits: a beat is valid for one clock and `frame.ready` is not
//! read. Every output is a register. Cost (yosys `synth_ecp5` of the block alone): 106 LUT4,
//! 6 carry cells and 77 flip-flops, most of the LUT4 the CRC's XOR network; 179 MHz placed
//! alone on the ECP5-25 speed 6.

use crate::crc32::Crc32Byte;
use crate::hdl::*;
use crate::stream::ByteStreamSource;
use skinbox_protocol::link::{MAX_RECEIVE_LEN, MIN_RECEIVE_LEN};

/// Clocks from a byte on `gmii_rxd` (present before rising edge k) to its beat: the beat
/// is valid after edge `k + MAC_LATENCY` (the consumer takes it at the edge after). The
/// bytes are registered at their edge, held back one byte, then registered as the beat.
pub const MAC_LATENCY: u64 = 2;

/// The start-of-frame delimiter.
pub const SFD: u8 = 0xD5;
/// A preamble byte.
pub const PREAMBLE_BYTE: u8 = 0x55;

/// The CRC register (reflected, as [`Crc32Byte`] keeps it, started at all ones) after a
/// frame and its correct FCS: the IEEE 802.3 CRC-32 residue.
pub const CRC_RESIDUE: u32 = 0xDEBB_20E3;

#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
enum MacState {
    /// No carrier (the first variant is the reset state).
    Idle,
    /// Carrier, 0x55 bytes so far.
    Preamble,
    /// After the SFD: frame bytes.
    Frame,
    /// A carrier without SFD, or one in progress at reset: ignored until it ends.
    Discard,
}

/// The GMII receive MAC (see the module documentation).
#[derive(LogicBlock)]
pub struct MacReceiver {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Receive data, in the box clock.
    pub gmii_rxd: Signal<In, Bits<8>>,
    /// Receive data valid: the carrier.
    pub gmii_rx_dv: Signal<In, Bit>,
    /// Receive error (with `gmii_rx_dv`: a symbol error).
    pub gmii_rx_er: Signal<In, Bit>,
    /// The frame's bytes after the SFD; `ready` is ignored.
    pub frame: ByteStreamSource,
    /// With the last beat: the frame's length is outside 64..=1518 bytes.
    pub length_error: Signal<Out, Bit>,
    rx_byte: DFF<Bits<8>>,
    rx_dv: DFF<Bit>,
    rx_er: DFF<Bit>,
    state: DFF<MacState>,
    // the byte held back until the next one (or the carrier's end) shows whether it is last
    held: DFF<Bits<8>>,
    // frame bytes so far, up to MAX_RECEIVE_LEN
    count: DFF<Bits<11>>,
    // `count` is MAX_RECEIVE_LEN (kept beside it: no compare of the count before its step)
    count_at_max: DFF<Bit>,
    // more than MAX_RECEIVE_LEN bytes: no more beats
    giant: DFF<Bit>,
    error_seen: DFF<Bit>,
    crc: DFF<Bits<32>>,
    crc_byte: Crc32Byte,
    beat_data: DFF<Bits<8>>,
    beat_valid: DFF<Bit>,
    beat_last: DFF<Bit>,
    beat_error: DFF<Bit>,
    beat_length_error: DFF<Bit>,
    short: Signal<Local, Bit>,
    sfd: Constant<Bits<8>>,
    preamble_byte: Constant<Bits<8>>,
    residue: Constant<Bits<32>>,
    crc_start: Constant<Bits<32>>,
    min_len: Constant<Bits<11>>,
    max_len_less_one: Constant<Bits<11>>,
}

impl Default for MacReceiver {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            gmii_rxd: Default::default(),
            gmii_rx_dv: Default::default(),
            gmii_rx_er: Default::default(),
            frame: Default::default(),
            length_error: Default::default(),
            rx_byte: Default::default(),
            rx_dv: Default::default(),
            rx_er: Default::default(),
            state: Default::default(),
            held: Default::default(),
            count: Default::default(),
            count_at_max: Default::default(),
            giant: Default::default(),
            error_seen: Default::default(),
            crc: Default::default(),
            crc_byte: Default::default(),
            beat_data: Default::default(),
            beat_valid: Default::default(),
            beat_last: Default::default(),
            beat_error: Default::default(),
            beat_length_error: Default::default(),
            short: Default::default(),
            sfd: Constant::new(u64::from(SFD).into()),
            preamble_byte: Constant::new(u64::from(PREAMBLE_BYTE).into()),
            residue: Constant::new(u64::from(CRC_RESIDUE).into()),
            crc_start: Constant::new(0xFFFF_FFFF_u64.into()),
            min_len: Constant::new((MIN_RECEIVE_LEN as u64).into()),
            max_len_less_one: Constant::new((MAX_RECEIVE_LEN as u64 - 1).into()),
        }
    }
}

impl Logic for MacReceiver {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            rx_byte,
            rx_dv,
            rx_er,
            state,
            held,
            count,
            count_at_max,
            giant,
            error_seen,
            crc,
            beat_data,
            beat_valid,
            beat_last,
            beat_error,
            beat_length_error
        );
        self.rx_byte.d.next = self.gmii_rxd.val();
        self.rx_dv.d.next = self.gmii_rx_dv.val();
        self.rx_er.d.next = self.gmii_rx_er.val();
        self.crc_byte.register.next = self.crc.q.val();
        self.crc_byte.data.next = self.rx_byte.q.val();
        self.frame.data.next = self.beat_data.q.val();
        self.frame.valid.next = self.beat_valid.q.val();
        self.frame.last.next = self.beat_last.q.val();
        self.frame.error.next = self.beat_error.q.val();
        self.length_error.next = self.beat_length_error.q.val();
        self.short.next = self.count.q.val() < self.min_len.val();
        self.beat_data.d.next = self.held.q.val();
        self.beat_valid.d.next = false;
        self.beat_last.d.next = false;
        self.beat_error.d.next = false;
        self.beat_length_error.d.next = false;
        match self.state.q.val() {
            MacState::Idle => {
                self.crc.d.next = self.crc_start.val();
                self.count.d.next = 0.into();
                self.count_at_max.d.next = false;
                self.giant.d.next = false;
                self.error_seen.d.next = self.rx_er.q.val();
                if self.rx_dv.q.val() {
                    if self.rx_byte.q.val() == self.sfd.val() {
                        self.state.d.next = MacState::Frame;
                    } else if self.rx_byte.q.val() == self.preamble_byte.val() {
                        self.state.d.next = MacState::Preamble;
                    } else {
                        self.state.d.next = MacState::Discard;
                    }
                }
            }
            MacState::Preamble => {
                if !self.rx_dv.q.val() {
                    self.state.d.next = MacState::Idle;
                } else {
                    if self.rx_er.q.val() {
                        self.error_seen.d.next = true;
                    }
                    if self.rx_byte.q.val() == self.sfd.val() {
                        self.state.d.next = MacState::Frame;
                    } else if self.rx_byte.q.val() != self.preamble_byte.val() {
                        self.state.d.next = MacState::Discard;
                    }
                }
            }
            MacState::Frame => {
                if self.rx_dv.q.val() {
                    if self.rx_er.q.val() {
                        self.error_seen.d.next = true;
                    }
                    self.crc.d.next = self.crc_byte.updated.val();
                    if !self.giant.q.val() {
                        // the held byte was not the last: a beat
                        self.beat_valid.d.next = self.count.q.val().any();
                        self.held.d.next = self.rx_byte.q.val();
                        if self.count_at_max.q.val() {
                            self.giant.d.next = true;
                        } else {
                            self.count.d.next = self.count.q.val() + 1;
                            self.count_at_max.d.next =
                                self.count.q.val() == self.max_len_less_one.val();
                        }
                    }
                } else {
                    // the carrier ended: the held byte is the last
                    self.state.d.next = MacState::Idle;
                    self.beat_valid.d.next = true;
                    self.beat_last.d.next = true;
                    if self.giant.q.val() | !self.count.q.val().any() {
                        self.beat_data.d.next = 0.into();
                        self.beat_error.d.next = true;
                        self.beat_length_error.d.next = true;
                    } else {
                        self.beat_length_error.d.next = self.short.val();
                        self.beat_error.d.next = self.short.val()
                            | self.error_seen.q.val()
                            | (self.crc.q.val() != self.residue.val());
                    }
                }
            }
            MacState::Discard => {
                if !self.rx_dv.q.val() {
                    self.state.d.next = MacState::Idle;
                }
            }
            _ => {
                self.state.d.next = MacState::Idle;
            }
        }
        if self.reset.val() {
            // a carrier in progress is no frame: wait for its end
            self.state.d.next = MacState::Discard;
            self.beat_valid.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use etherparse::PacketBuilder;

    const FCS: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

    /// One clock of the GMII receive signals.
    #[derive(Debug, Clone, Copy, Default)]
    struct Rx {
        dv: bool,
        er: bool,
        data: u8,
    }

    /// One beat as the MAC gave it.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    struct Beat {
        data: u8,
        last: bool,
        error: bool,
        length_error: bool,
    }

    /// A UDP frame of `len` bytes with its FCS (len >= 46), built by etherparse, the FCS
    /// from the crc crate.
    fn udp_frame(len: usize, seed: u64) -> Vec<u8> {
        let mut rng = TestRng::new(seed);
        let payload: Vec<u8> = (0..len - 46).map(|_| rng.byte()).collect();
        let builder = PacketBuilder::ethernet2([2, 0, 0, 0, 0, 9], [2, 0x53, 0x4b, 0, 0, 1])
            .ipv4([192, 0, 2, 9], [192, 0, 2, 1], 64)
            .udp(5000, 49_152);
        let mut frame = Vec::new();
        builder.write(&mut frame, &payload).unwrap();
        with_fcs(frame)
    }

    fn with_fcs(mut frame: Vec<u8>) -> Vec<u8> {
        let fcs = FCS.checksum(&frame);
        frame.extend_from_slice(&fcs.to_le_bytes());
        frame
    }

    /// A frame on the wire: `preamble` bytes of 0x55, the SFD, the frame; `er_at` sets
    /// rx_er with that frame byte.
    fn carrier(preamble: usize, frame: &[u8], er_at: Option<usize>) -> Vec<Rx> {
        let mut wire: Vec<Rx> = (0..preamble)
            .map(|_| Rx {
                dv: true,
                er: false,
                data: PREAMBLE_BYTE,
            })
            .collect();
        wire.push(Rx {
            dv: true,
            er: false,
            data: SFD,
        });
        wire.extend(frame.iter().enumerate().map(|(i, &data)| Rx {
            dv: true,
            er: er_at == Some(i),
            data,
        }));
        wire
    }

    fn idle(clocks: usize) -> Vec<Rx> {
        vec![Rx::default(); clocks]
    }

    /// The beats the MAC must give for one frame (the bytes after the SFD), as the
    /// module documentation specifies them: an independent model of its rules.
    fn expected_beats(frame: &[u8], rx_er: bool) -> Vec<Beat> {
        let beat = |data| Beat {
            data,
            last: false,
            error: false,
            length_error: false,
        };
        if frame.is_empty() || frame.len() > MAX_RECEIVE_LEN {
            let mut beats: Vec<Beat> = frame
                .iter()
                .take(MAX_RECEIVE_LEN)
                .map(|&b| beat(b))
                .collect();
            beats.push(Beat {
                data: 0,
                last: true,
                error: true,
                length_error: true,
            });
            return beats;
        }
        let length_bad = frame.len() < MIN_RECEIVE_LEN;
        let fcs_bad = frame.len() < 4 || {
            let (body, fcs) = frame.split_at(frame.len() - 4);
            FCS.checksum(body).to_le_bytes() != fcs
        };
        let mut beats: Vec<Beat> = frame.iter().map(|&b| beat(b)).collect();
        let end = beats.last_mut().unwrap();
        end.last = true;
        end.error = length_bad || fcs_bad || rx_er;
        end.length_error = length_bad;
        beats
    }

    /// Runs the wire through a MAC; returns every beat with the clock it was valid after
    /// (edge number), and the edge each frame byte was presented before.
    fn run(wire: &[Rx]) -> (Vec<(u64, Beat)>, Bench<MacReceiver>) {
        let mut bench = Bench::new(MacReceiver::default(), |m| &mut m.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut beats = Vec::new();
        let tail = idle(8);
        for rx in wire.iter().chain(&tail) {
            bench.uut.gmii_rx_dv.next = rx.dv;
            bench.uut.gmii_rx_er.next = rx.er;
            bench.uut.gmii_rxd.next = u64::from(rx.data).into();
            bench.cycle();
            let u = &bench.uut;
            if u.frame.valid.val() {
                beats.push((
                    bench.cycles,
                    Beat {
                        data: u.frame.data.val().to_u8(),
                        last: u.frame.last.val(),
                        error: u.frame.error.val(),
                        length_error: u.length_error.val(),
                    },
                ));
            }
        }
        (beats, bench)
    }

    fn beats_only(beats: &[(u64, Beat)]) -> Vec<Beat> {
        beats.iter().map(|b| b.1).collect()
    }

    #[test]
    fn crc_residue_is_what_a_good_fcs_leaves() {
        // The bitwise CRC of the crc32 module's register form, over a frame and its FCS.
        let frame = udp_frame(100, 1);
        let mut register = 0xFFFF_FFFFu32;
        for &b in &frame {
            register ^= u32::from(b);
            for _ in 0..8 {
                register = if register & 1 == 1 {
                    (register >> 1) ^ crate::crc32::POLYNOMIAL_REFLECTED as u32
                } else {
                    register >> 1
                };
            }
        }
        assert_eq!(register, CRC_RESIDUE);
    }

    #[test]
    fn good_frames_come_out_byte_for_byte_after_mac_latency() {
        for (i, len) in [64, 65, 100, 333, 1000, 1517, 1518].into_iter().enumerate() {
            let frame = udp_frame(len, i as u64);
            let wire = [idle(3), carrier(7, &frame, None)].concat();
            let (beats, _) = run(&wire);
            assert_eq!(beats_only(&beats), expected_beats(&frame, false), "{len}");
            assert!(
                !beats.last().unwrap().1.error,
                "{len} bytes are a good frame"
            );
            // Frame byte j was presented before edge 1 (reset) + 3 + 8 + j + 1.
            for (j, (edge, _)) in beats.iter().enumerate() {
                let presented = 1 + 3 + 8 + j as u64 + 1;
                assert_eq!(*edge, presented + MAC_LATENCY, "{len} bytes, beat {j}");
            }
        }
    }

    #[test]
    fn runts_giants_bad_fcs_and_rx_er_end_with_an_error_beat() {
        let good = udp_frame(200, 7);
        let mut cases: Vec<(String, Vec<u8>, Option<usize>)> = Vec::new();
        // runts with a correct FCS of their own, and an empty frame
        for len in [0, 1, 4, 5, 46, 60, 63] {
            let frame = if len >= 4 {
                with_fcs(good[..len - 4].to_vec())
            } else {
                good[..len].to_vec()
            };
            cases.push((format!("runt {len}"), frame, None));
        }
        // giants: good FCS, yet too long
        for len in [1519, 2000] {
            cases.push((format!("giant {len}"), udp_frame(len, len as u64), None));
        }
        // one bit flipped anywhere, FCS included
        for bit in [0, 7, 8 * 14 + 3, 8 * 100, 8 * 196 - 1, 8 * 196, 8 * 200 - 1] {
            let mut frame = good.clone();
            frame[bit / 8] ^= 1 << (bit % 8);
            cases.push((format!("bit {bit} flipped"), frame, None));
        }
        for at in [0, 50, 199] {
            cases.push((format!("rx_er at {at}"), good.clone(), Some(at)));
        }
        for (name, frame, er_at) in cases {
            let (beats, _) = run(&[idle(2), carrier(7, &frame, er_at)].concat());
            let beats = beats_only(&beats);
            assert_eq!(beats, expected_beats(&frame, er_at.is_some()), "{name}");
            let end = beats.last().unwrap();
            assert!(end.last && end.error, "{name}");
            assert_eq!(beats.iter().filter(|b| b.last).count(), 1, "{name}");
        }
    }

    #[test]
    fn short_preambles_false_carriers_and_back_to_back_frames() {
        let frames: Vec<Vec<u8>> = (0..7)
            .map(|i| udp_frame(64 + i * 30, 100 + i as u64))
            .collect();
        let mut wire = idle(4);
        let mut expected = Vec::new();
        for (i, frame) in frames.iter().enumerate() {
            // preamble of 1..7 bytes, then the minimum gap of 12 idle clocks
            wire.extend(carrier(i + 1, frame, None));
            wire.extend(idle(12));
            expected.extend(expected_beats(frame, false));
            // a carrier without SFD between them: no beats
            if i % 2 == 0 {
                let mut false_carrier = carrier(3, frame, None);
                false_carrier[3].data = 0x5D;
                wire.extend(false_carrier);
                wire.extend(idle(12));
            }
        }
        // A carrier of preamble only, then one whose first byte is neither 0x55 nor SFD.
        wire.extend(vec![
            Rx {
                dv: true,
                er: false,
                data: PREAMBLE_BYTE
            };
            9
        ]);
        wire.extend(idle(12));
        wire.extend(vec![
            Rx {
                dv: true,
                er: false,
                data: 0
            };
            70
        ]);
        wire.extend(idle(12));
        // No preamble at all: the SFD alone starts a frame.
        wire.extend(carrier(0, &frames[0], None));
        expected.extend(expected_beats(&frames[0], false));
        let (beats, _) = run(&wire);
        assert_eq!(beats_only(&beats), expected);
    }

    /// At least 100 random frames and faults back to back, seeded: lengths from empty to
    /// giant, bit flips, rx_er, false carriers, preambles of 0 to 7 bytes, gaps of 12 to
    /// 20 idle clocks; every beat as the model says.
    #[test]
    fn random_frames_and_faults_match_the_model() {
        let mut rng = TestRng::new(2026);
        let mut wire = idle(2);
        let mut expected = Vec::new();
        let mut kinds = [0usize; 6];
        for n in 0..140 {
            let r = rng.next_u64();
            let len = match r % 10 {
                0 => (r >> 8) as usize % 64,
                1 => 1500 + (r >> 8) as usize % 60,
                _ => 64 + (r >> 8) as usize % 200,
            };
            let mut frame = if len >= 46 {
                udp_frame(len, r)
            } else {
                (0..len).map(|_| rng.byte()).collect()
            };
            let preamble = (rng.next_u64() % 8) as usize;
            let fault = rng.next_u64() % 6;
            kinds[fault as usize] += 1;
            let mut er_at = None;
            match fault {
                1 if !frame.is_empty() => {
                    let bit = rng.next_u64() as usize % (frame.len() * 8);
                    frame[bit / 8] ^= 1 << (bit % 8);
                }
                2 if !frame.is_empty() => er_at = Some(rng.next_u64() as usize % frame.len()),
                3 => {
                    // false carrier: a byte other than 0x55 or SFD in the preamble
                    let mut c = carrier(preamble + 1, &frame, None);
                    c[preamble] = Rx {
                        dv: true,
                        er: false,
                        data: rng.byte() | 0x80,
                    };
                    if c[preamble].data == SFD {
                        c[preamble].data = 0x80;
                    }
                    wire.extend(c);
                    wire.extend(idle(12 + n % 9));
                    continue;
                }
                _ => {}
            }
            wire.extend(carrier(preamble, &frame, er_at));
            wire.extend(idle(12 + n % 9));
            expected.extend(expected_beats(&frame, er_at.is_some()));
        }
        assert!(kinds.iter().all(|&k| k > 10), "{kinds:?}");
        let (beats, _) = run(&wire);
        let beats = beats_only(&beats);
        assert_eq!(beats.len(), expected.len());
        for (i, (got, want)) in beats.iter().zip(&expected).enumerate() {
            assert_eq!(got, want, "beat {i}");
        }
        let errors = beats.iter().filter(|b| b.last && b.error).count();
        let goods = beats.iter().filter(|b| b.last && !b.error).count();
        assert!(
            errors > 30 && goods > 30,
            "{errors} bad, {goods} good frames"
        );
    }

    #[test]
    fn reset_drops_a_frame_in_flight_and_verilog_passes_lint() {
        let frame = udp_frame(100, 3);
        let mut bench = Bench::new(MacReceiver::default(), |m| &mut m.clock);
        let wire = [carrier(7, &frame, None), idle(4)].concat();
        for (i, rx) in wire.iter().enumerate() {
            bench.uut.reset.next = i == 50;
            bench.uut.gmii_rx_dv.next = rx.dv;
            bench.uut.gmii_rxd.next = u64::from(rx.data).into();
            bench.cycle();
            if i > 52 {
                assert!(
                    !bench.uut.frame.valid.val(),
                    "no beat after a reset mid-frame"
                );
            }
        }
        let mut uut = MacReceiver::default();
        uut.connect_all();
        let dir = std::env::temp_dir().join(format!("skinbox-mac-lint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&generate_verilog(&uut), &dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
