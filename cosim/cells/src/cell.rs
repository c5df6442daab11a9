//! One skin cell: quantisation to raw units, data mode, and event mode by send-on-delta
//! exactly as Algorithm 1 of Bergner et al. (2nd paper).
//!
//! Algorithm 1, per sample and per enabled channel: when `|current - last_sent| > threshold`
//! (strict, on raw integer units) the channel fires, its current value is sent and becomes
//! its `last_sent`; channels that did not fire keep their `last_sent`. A sample with at least
//! one fired channel makes an event packet; with seven to nine fired channels the first six
//! (in mask-bit order) go in one packet and the rest in a second one
//! ([`EventRepr::split`]). Every event packet takes the cell's next sequence number.
//!
//! A cell starts with no value sent, so its first sample fires every enabled channel: the
//! host then holds a full state from the start.
//!
//! An optional periodic full refresh (not in the papers; [`CellConfig::refresh_every_samples`])
//! sends one data packet with every channel every N samples in event mode, and takes its
//! values as `last_sent`: a host that lost an event, or the cell's first packets, holds the
//! true state again after at most one refresh period.

use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::cell_command::{CellCommand, CellMode};
use skinbox_protocol::{Channel, ChannelMask, DataRepr, EventRepr, Modality};

/// What a cell sends: every sample, or send-on-delta events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Conventional mode: one data packet per sample.
    Data,
    /// Event mode: send-on-delta (Algorithm 1).
    Event,
}

impl From<CellMode> for Mode {
    fn from(m: CellMode) -> Mode {
        match m {
            CellMode::Data => Mode::Data,
            CellMode::Event => Mode::Event,
        }
    }
}

/// Raw values the cell's sensors produce (docs/design.md section 2): acceleration 10-bit signed
/// (+-2 g), force 10-bit (0..1 of the normalised force), proximity a 16-bit count,
/// temperature 8-bit in 0.5 C steps.
pub fn sensor_range_raw(channel: Channel) -> core::ops::RangeInclusive<i32> {
    match channel.modality() {
        Modality::Acceleration => -512..=511,
        Modality::Force => 0..=1023,
        Modality::Proximity => 0..=65535,
        Modality::Temperature => 0..=255,
    }
}

/// Full range of a channel in host units (4 g, 1, 1, 128 C): the reference of the
/// reconstruction error in percent.
pub fn full_range_units(channel: Channel) -> f64 {
    let r = sensor_range_raw(channel);
    f64::from(r.end() - r.start() + 1) * channel.units_per_lsb()
}

/// Quantises a physical value to the channel's raw units: rounds to the nearest step and
/// saturates at the sensor's range, as the cell's ADC does.
pub fn quantise(channel: Channel, value_units: f64) -> i32 {
    let range = sensor_range_raw(channel);
    let steps = value_units / channel.units_per_lsb();
    // Round half away from zero; `as` truncates, saturates infinities to the i32 limits and
    // NaN to 0, and the clamp does the rest.
    let raw = if steps >= 0.0 {
        (steps + 0.5) as i32
    } else {
        (steps - 0.5) as i32
    };
    raw.clamp(*range.start(), *range.end())
}

/// Per-channel send-on-delta thresholds in raw units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Thresholds {
    /// Threshold of each channel in raw steps, in channel order.
    pub raw: [u16; Channel::COUNT],
}

impl Thresholds {
    /// The papers' Table I: 0.02 g, 0.001, 0.0001, 0.5 C (5, 1, 6 and 1 raw steps).
    pub fn table_i() -> Thresholds {
        Thresholds {
            raw: Channel::ALL.map(|c| c.table_i_threshold_raw()),
        }
    }

    /// Thresholds from host units per modality, rounded down to whole raw steps as
    /// [`Channel::table_i_threshold_raw`] does.
    pub fn from_units(accel_g: f64, force: f64, proximity: f64, temperature_c: f64) -> Thresholds {
        Thresholds {
            raw: Channel::ALL.map(|c| {
                let host = match c.modality() {
                    Modality::Acceleration => accel_g,
                    Modality::Force => force,
                    Modality::Proximity => proximity,
                    Modality::Temperature => temperature_c,
                };
                (host / c.units_per_lsb() + 1e-9)
                    .floor()
                    .clamp(0.0, 65535.0) as u16
            }),
        }
    }
}

/// Algorithm 1 state of one cell: thresholds, enable mask and the last value sent per channel.
#[derive(Debug, Clone)]
pub struct SendOnDelta {
    thresholds: Thresholds,
    enabled: ChannelMask,
    last_sent: [Option<i32>; Channel::COUNT],
}

/// The channels one sample fired, with their values, in channel order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fired {
    events: [(u8, i32); Channel::COUNT],
    len: usize,
}

impl Fired {
    /// The fired `(channel, raw value)` pairs in channel order.
    pub fn events(&self) -> impl Iterator<Item = (Channel, i32)> + '_ {
        self.events[..self.len]
            .iter()
            .filter_map(|&(i, v)| Channel::from_index(usize::from(i)).map(|c| (c, v)))
    }

    /// Number of fired channels.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no channel fired.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The fired channels.
    pub fn mask(&self) -> ChannelMask {
        self.events().map(|(c, _)| c).collect()
    }
}

impl SendOnDelta {
    /// A fresh state: nothing sent yet, so the first sample fires every enabled channel.
    pub fn new(thresholds: Thresholds, enabled: ChannelMask) -> SendOnDelta {
        SendOnDelta {
            thresholds,
            enabled,
            last_sent: [None; Channel::COUNT],
        }
    }

    /// Takes `raw` as sent on every enabled channel (a full refresh carried them all).
    pub fn refresh(&mut self, raw: &[i32; Channel::COUNT]) {
        for c in self.enabled.iter() {
            self.last_sent[c.index()] = Some(raw[c.index()]);
        }
    }

    /// The value last sent on `channel`, if any.
    pub fn last_sent(&self, channel: Channel) -> Option<i32> {
        self.last_sent[channel.index()]
    }

    /// One sample of raw values: the channels that fire (`|current - last_sent| >
    /// threshold`), whose `last_sent` become their current value.
    pub fn step(&mut self, raw: &[i32; Channel::COUNT]) -> Fired {
        let mut fired = Fired::default();
        for c in Channel::ALL {
            let i = c.index();
            if !self.enabled.contains(c) {
                continue;
            }
            let fire = match self.last_sent[i] {
                None => true,
                Some(last) => (raw[i] - last).unsigned_abs() > u32::from(self.thresholds.raw[i]),
            };
            if fire {
                self.last_sent[i] = Some(raw[i]);
                fired.events[fired.len] = (i as u8, raw[i]);
                fired.len += 1;
            }
        }
        fired
    }
}

/// Static configuration of one cell.
#[derive(Debug, Clone)]
pub struct CellConfig {
    /// Cell id (1..=16382; 0 is "none" and 16383 the broadcast id).
    pub cell_id: u16,
    /// Data or event mode.
    pub mode: Mode,
    /// Send-on-delta thresholds (event mode).
    pub thresholds: Thresholds,
    /// Channels enabled for events (event mode).
    pub enabled: ChannelMask,
    /// Event mode: every this many samples (counted from the first, which fires every
    /// channel anyway) send one data packet with every channel instead of events; 0 never.
    pub refresh_every_samples: u32,
}

/// Up to two 20-byte packets one sample produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SamplePackets {
    packets: [[u8; PACKET_LEN]; 2],
    len: usize,
    fired: ChannelMask,
}

impl SamplePackets {
    /// The packets, in sending order.
    pub fn as_slice(&self) -> &[[u8; PACKET_LEN]] {
        &self.packets[..self.len]
    }

    /// The channels whose values these packets carry (every channel in data mode).
    pub fn fired(&self) -> ChannelMask {
        self.fired
    }

    fn push(&mut self, bytes: [u8; PACKET_LEN]) {
        self.packets[self.len] = bytes;
        self.len += 1;
    }
}

/// A skin cell's packet logic: quantised samples in, packets out.
#[derive(Debug, Clone)]
pub struct Cell {
    config: CellConfig,
    send_on_delta: SendOnDelta,
    next_sequence: u16,
    samples: u64,
}

impl Cell {
    /// A cell that has sent nothing yet.
    pub fn new(config: CellConfig) -> Cell {
        Cell {
            send_on_delta: SendOnDelta::new(config.thresholds, config.enabled),
            config,
            next_sequence: 0,
            samples: 0,
        }
    }

    /// Applies a cell command at a sample boundary (before the sample): a mode change
    /// starts Algorithm 1 afresh, so the next sample sends every channel as at start-up;
    /// thresholds keep the values sent; a newly enabled channel fires at the next sample.
    /// Sample rate and time sync concern the cell's clock, which the caller runs
    /// ([`crate::Scene::generate`]); here they change nothing.
    pub fn apply(&mut self, command: &CellCommand) {
        match *command {
            CellCommand::Mode(m) => {
                let mode = Mode::from(m);
                if mode != self.config.mode {
                    self.config.mode = mode;
                    self.send_on_delta =
                        SendOnDelta::new(self.config.thresholds, self.config.enabled);
                }
            }
            CellCommand::Thresholds(t) => {
                let raw = Channel::ALL.map(|c| t.of(c.modality()));
                self.config.thresholds = Thresholds { raw };
                self.send_on_delta.thresholds = self.config.thresholds;
            }
            CellCommand::EnableMask(mask) => {
                for c in mask.iter() {
                    if !self.config.enabled.contains(c) {
                        self.send_on_delta.last_sent[c.index()] = None;
                    }
                }
                self.config.enabled = mask;
                self.send_on_delta.enabled = mask;
            }
            CellCommand::SampleRate(_) | CellCommand::TimeSync { .. } => {}
        }
    }

    /// The cell's configuration.
    pub fn config(&self) -> &CellConfig {
        &self.config
    }

    /// The Algorithm 1 state (what the host holds after every event so far).
    pub fn send_on_delta(&self) -> &SendOnDelta {
        &self.send_on_delta
    }

    /// Sequence number the next event packet will carry.
    pub fn next_sequence(&self) -> u16 {
        self.next_sequence
    }

    /// One sample in physical units: quantised, then sent as [`Cell::sample_raw`] does.
    pub fn sample_units(&mut self, values_units: &[f64; Channel::COUNT]) -> SamplePackets {
        let mut raw = [0; Channel::COUNT];
        for (i, c) in Channel::ALL.into_iter().enumerate() {
            raw[i] = quantise(c, values_units[i]);
        }
        self.send(&raw)
    }

    /// One sample of raw values (saturated to the sensor ranges first): a data packet in data
    /// mode; zero, one or two event packets in event mode.
    pub fn sample_raw(&mut self, raw: &[i32; Channel::COUNT]) -> SamplePackets {
        let mut clamped = [0; Channel::COUNT];
        for (i, c) in Channel::ALL.into_iter().enumerate() {
            let r = sensor_range_raw(c);
            clamped[i] = raw[i].clamp(*r.start(), *r.end());
        }
        self.send(&clamped)
    }

    /// Sends a sample already inside the sensor ranges.
    fn send(&mut self, raw: &[i32; Channel::COUNT]) -> SamplePackets {
        let id = self.config.cell_id;
        let mut out = SamplePackets::default();
        let every = u64::from(self.config.refresh_every_samples);
        let refresh = every > 0 && self.samples > 0 && self.samples.is_multiple_of(every);
        self.samples += 1;
        let mode = match self.config.mode {
            Mode::Event if refresh => {
                self.send_on_delta.refresh(raw);
                Mode::Data
            }
            mode => mode,
        };
        match mode {
            Mode::Data => {
                let data = DataRepr {
                    cell_id: id,
                    accel: [0, 1, 2].map(|i| raw[i] as i16),
                    force: [3, 4, 5].map(|i| raw[i] as u16),
                    proximity: raw[Channel::Proximity.index()] as u16,
                    temperature: [7, 8].map(|i| raw[i] as u8),
                };
                out.push(data.to_bytes());
                out.fired = ChannelMask::ALL;
            }
            Mode::Event => {
                let fired = self.send_on_delta.step(raw);
                if fired.is_empty() {
                    return out;
                }
                out.fired = fired.mask();
                let mut events = [(Channel::AccelX, 0); Channel::COUNT];
                for (slot, event) in fired.events().enumerate() {
                    events[slot] = event;
                }
                // Sensor ranges lie inside the event words and `events` is in channel order
                // with one to nine entries: the split cannot fail.
                let (first, second) =
                    EventRepr::split(id, self.next_sequence, &events[..fired.len()])
                        .expect("events of one sample form valid packets");
                out.push(first.to_bytes());
                self.next_sequence = self.next_sequence.wrapping_add(1);
                if let Some(second) = second {
                    out.push(second.to_bytes());
                    self.next_sequence = self.next_sequence.wrapping_add(1);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::{CellRepr, DataRepr};

    /// A resting sample well inside every sensor range.
    const BASE: [i32; Channel::COUNT] = [10, -20, 256, 100, 200, 300, 5_000, 60, 40];

    fn event_cell(enabled: ChannelMask) -> Cell {
        Cell::new(CellConfig {
            cell_id: 42,
            mode: Mode::Event,
            thresholds: Thresholds::table_i(),
            enabled,
            refresh_every_samples: 0,
        })
    }

    fn events(packets: &SamplePackets) -> Vec<EventRepr> {
        packets
            .as_slice()
            .iter()
            .map(|b| EventRepr::parse(b).expect("a valid event packet"))
            .collect()
    }

    fn with(channel: Channel, raw: i32) -> [i32; Channel::COUNT] {
        let mut s = BASE;
        s[channel.index()] = raw;
        s
    }

    #[test]
    fn first_sample_sends_every_enabled_channel() {
        let mut cell = event_cell(ChannelMask::ALL);
        let p = events(&cell.sample_raw(&BASE));
        assert_eq!(p.len(), 2);
        let sent: Vec<_> = p.iter().flat_map(|e| e.events()).collect();
        assert_eq!(sent, Channel::ALL.map(|c| (c, BASE[c.index()])).to_vec());
        assert!(cell.sample_raw(&BASE).as_slice().is_empty());
    }

    #[test]
    fn each_threshold_is_strict_on_both_sides() {
        for c in Channel::ALL {
            let t = i32::from(c.table_i_threshold_raw());
            let b = BASE[c.index()];
            let mut cell = event_cell(ChannelMask::ALL);
            cell.sample_raw(&BASE);
            // Exactly the threshold away, up or down: no event.
            for v in [b + t, b - t] {
                let out = cell.sample_raw(&with(c, v));
                assert!(out.as_slice().is_empty(), "{c}: {v} fired at threshold {t}");
                assert_eq!(cell.send_on_delta().last_sent(c), Some(b));
            }
            // One step more: exactly this channel fires, with its value.
            let up = events(&cell.sample_raw(&with(c, b + t + 1)));
            assert_eq!(up.len(), 1, "{c}");
            assert_eq!(up[0].events().collect::<Vec<_>>(), vec![(c, b + t + 1)]);
            assert_eq!(cell.send_on_delta().last_sent(c), Some(b + t + 1));
            // Downwards from the new last value: threshold holds, threshold + 1 fires.
            let mut s = with(c, b + 1);
            assert!(cell.sample_raw(&s).as_slice().is_empty(), "{c}");
            s[c.index()] = b;
            let down = events(&cell.sample_raw(&s));
            assert_eq!(down[0].events().collect::<Vec<_>>(), vec![(c, b)], "{c}");
        }
    }

    #[test]
    fn temperature_flicker_of_one_step_never_fires() {
        assert_eq!(Channel::Temperature1.table_i_threshold_raw(), 1);
        let mut cell = event_cell(ChannelMask::ALL);
        cell.sample_raw(&BASE);
        for k in 0..100 {
            let s = with(Channel::Temperature1, 60 + (k % 2));
            assert!(cell.sample_raw(&s).as_slice().is_empty(), "sample {k}");
        }
        let p = events(&cell.sample_raw(&with(Channel::Temperature1, 62)));
        assert_eq!(
            p[0].events().collect::<Vec<_>>(),
            vec![(Channel::Temperature1, 62)]
        );
    }

    #[test]
    fn last_sent_moves_only_for_fired_channels() {
        let mut cell = event_cell(ChannelMask::ALL);
        cell.sample_raw(&BASE);
        // accel x creeps by 3 (below its threshold of 5) while force 1 jumps.
        let mut s = BASE;
        s[0] += 3;
        s[3] += 50;
        let p = events(&cell.sample_raw(&s));
        assert_eq!(
            p[0].events().collect::<Vec<_>>(),
            vec![(Channel::Force1, 150)]
        );
        assert_eq!(cell.send_on_delta().last_sent(Channel::AccelX), Some(10));
        // Another 3: 6 from what was sent, so it fires now, although only 3 from the last
        // sample.
        s[0] += 3;
        let p = events(&cell.sample_raw(&s));
        assert_eq!(
            p[0].events().collect::<Vec<_>>(),
            vec![(Channel::AccelX, 16)]
        );
    }

    #[test]
    fn disabled_channels_never_fire() {
        let enabled: ChannelMask = [Channel::AccelZ, Channel::Proximity].into_iter().collect();
        let mut cell = event_cell(enabled);
        let first = events(&cell.sample_raw(&BASE));
        assert_eq!(first.len(), 1);
        assert_eq!(first[0].channels, enabled);
        // Every channel jumps: only the enabled two are sent.
        let jump = BASE.map(|v| v + 100);
        let p = events(&cell.sample_raw(&jump));
        assert_eq!(p[0].channels, enabled);
        assert_eq!(
            p[0].events().collect::<Vec<_>>(),
            vec![(Channel::AccelZ, 356), (Channel::Proximity, 5_100)]
        );
        assert_eq!(cell.send_on_delta().last_sent(Channel::Force1), None);
    }

    #[test]
    fn six_events_fit_one_packet_and_seven_to_nine_split() {
        for fired in 6..=9usize {
            let mut cell = event_cell(ChannelMask::ALL);
            cell.sample_raw(&BASE);
            let seq = cell.next_sequence();
            let mut s = BASE;
            for v in s.iter_mut().take(fired) {
                *v += 10;
            }
            let p = events(&cell.sample_raw(&s));
            let expected: Vec<_> = Channel::ALL[..fired]
                .iter()
                .map(|&c| (c, BASE[c.index()] + 10))
                .collect();
            if fired == 6 {
                assert_eq!(p.len(), 1);
            } else {
                assert_eq!(p.len(), 2, "{fired} events");
                assert_eq!(p[0].channels.len(), 6);
                assert!(!p[0].second_part);
                assert!(p[1].second_part);
                assert_eq!(p[1].channels.len(), fired - 6);
                assert_eq!(p[1].sequence, seq.wrapping_add(1));
            }
            assert_eq!(p[0].sequence, seq);
            let all: Vec<_> = p.iter().flat_map(|e| e.events()).collect();
            assert_eq!(all, expected, "{fired} events");
            assert_eq!(cell.next_sequence(), seq.wrapping_add(p.len() as u16));
        }
    }

    #[test]
    fn sequence_numbers_count_event_packets_and_wrap() {
        let mut cell = event_cell(ChannelMask::ALL);
        assert_eq!(cell.sample_raw(&BASE).as_slice().len(), 2); // sequences 0 and 1
        let mut expected = 2u16;
        let mut high = false;
        for k in 0..90_000u32 {
            // Proximity jumps by 100 at four samples of five: one packet each.
            let quiet = k % 5 == 4;
            if !quiet {
                high = !high;
            }
            let prox = if high { 5_100 } else { 5_000 };
            let p = events(&cell.sample_raw(&with(Channel::Proximity, prox)));
            if quiet {
                assert!(p.is_empty(), "sample {k}");
                continue;
            }
            assert_eq!(p.len(), 1);
            assert_eq!(p[0].sequence, expected, "sample {k}");
            expected = expected.wrapping_add(1);
        }
        // 2 + 72,000 packets: the counter wrapped once, past 65,535 to 0.
        assert_eq!(cell.next_sequence(), 6_466);
        assert_eq!(cell.next_sequence(), expected);
    }

    #[test]
    fn data_mode_sends_every_sample_saturated_to_the_sensor_ranges() {
        let mut cell = Cell::new(CellConfig {
            cell_id: 7,
            mode: Mode::Data,
            thresholds: Thresholds::table_i(),
            enabled: ChannelMask::ALL,
            refresh_every_samples: 0,
        });
        for _ in 0..3 {
            let out = cell.sample_raw(&BASE);
            assert_eq!(out.as_slice().len(), 1);
            let d = DataRepr::parse(&out.as_slice()[0]).unwrap();
            assert_eq!((d.cell_id, d.raw_values()), (7, BASE));
        }
        let wild = [9_999, -9_999, 0, -5, 2_000, 1_023, 70_000, 300, -1];
        let out = cell.sample_raw(&wild);
        match CellRepr::parse(&out.as_slice()[0], &Default::default()).unwrap() {
            CellRepr::Data(d) => {
                assert_eq!(
                    d.raw_values(),
                    [511, -512, 0, 0, 1_023, 1_023, 65_535, 255, 0]
                )
            }
            other => panic!("expected a data packet, got {other:?}"),
        }
    }

    #[test]
    fn a_refresh_sends_every_channel_in_one_data_packet_every_n_samples() {
        let mut cell = Cell::new(CellConfig {
            cell_id: 9,
            mode: Mode::Event,
            thresholds: Thresholds::table_i(),
            enabled: ChannelMask::ALL,
            refresh_every_samples: 4,
        });
        // Sample 0: the first sample, all nine channels as events in two packets.
        assert_eq!(events(&cell.sample_raw(&BASE)).len(), 2);
        let mut s = BASE;
        for k in 1..=12u32 {
            // accel x creeps by 2 a sample: below its threshold of 5 until a refresh or
            // the third step.
            s[0] += 2;
            let out = cell.sample_raw(&s);
            if k % 4 == 0 {
                assert_eq!(out.as_slice().len(), 1, "sample {k}");
                let d = DataRepr::parse(&out.as_slice()[0]).unwrap();
                assert_eq!(d.raw_values(), s, "sample {k}");
                assert_eq!(out.fired(), ChannelMask::ALL);
                for c in Channel::ALL {
                    assert_eq!(cell.send_on_delta().last_sent(c), Some(s[c.index()]));
                }
            } else {
                // Between refreshes Algorithm 1 runs from the refreshed values: accel x
                // fires at 6 from what was sent (k = 3, 7, 11).
                let fired = !out.as_slice().is_empty();
                assert_eq!(fired, k % 4 == 3, "sample {k}");
            }
        }
    }

    #[test]
    fn quantisation_rounds_to_the_nearest_step_and_saturates() {
        assert_eq!(quantise(Channel::AccelX, 0.02), 5); // 5.12 steps
        assert_eq!(quantise(Channel::AccelX, -0.0215), -6); // -5.504 steps
        assert_eq!(quantise(Channel::AccelZ, 3.0), 511);
        assert_eq!(quantise(Channel::Force1, -0.1), 0);
        assert_eq!(quantise(Channel::Temperature1, 30.24), 60);
        assert_eq!(quantise(Channel::Temperature1, 30.26), 61);
        assert_eq!(quantise(Channel::Proximity, f64::NAN), 0);
        assert_eq!(quantise(Channel::Proximity, f64::INFINITY), 65_535);
        assert_eq!(full_range_units(Channel::AccelY), 4.0);
        assert_eq!(full_range_units(Channel::Temperature2), 128.0);
    }

    #[test]
    fn commands_switch_mode_thresholds_and_channels() {
        use skinbox_protocol::cell_command::ModalityThresholds;
        let mut cell = Cell::new(CellConfig {
            cell_id: 3,
            mode: Mode::Data,
            thresholds: Thresholds::table_i(),
            enabled: ChannelMask::ALL,
            refresh_every_samples: 0,
        });
        assert_eq!(cell.sample_raw(&BASE).as_slice()[0][0], 0xA1);
        // To event mode: the next sample sends all nine channels, as at start-up.
        cell.apply(&CellCommand::Mode(CellMode::Event));
        let p = events(&cell.sample_raw(&BASE));
        assert_eq!(p.iter().map(|e| e.channels.len()).sum::<usize>(), 9);
        assert!(cell.sample_raw(&BASE).as_slice().is_empty());
        // Force threshold 1 -> 60 steps: a jump of 50 no longer fires.
        cell.apply(&CellCommand::Thresholds(ModalityThresholds {
            raw: [5, 60, 6, 1],
        }));
        assert!(cell
            .sample_raw(&with(Channel::Force1, 150))
            .as_slice()
            .is_empty());
        assert_eq!(
            events(&cell.sample_raw(&with(Channel::Force1, 161)))[0]
                .events()
                .collect::<Vec<_>>(),
            vec![(Channel::Force1, 161)]
        );
        // Only proximity enabled: accel jumps are not sent.
        let prox: ChannelMask = [Channel::Proximity].into_iter().collect();
        cell.apply(&CellCommand::EnableMask(prox));
        let mut s = with(Channel::Force1, 161);
        s[0] += 100;
        assert!(cell.sample_raw(&s).as_slice().is_empty());
        // Back to data mode: every sample again.
        cell.apply(&CellCommand::Mode(CellMode::Data));
        let d = DataRepr::parse(&cell.sample_raw(&s).as_slice()[0]).unwrap();
        assert_eq!(d.raw_values(), s);
    }

    #[test]
    fn thresholds_from_units_match_table_i() {
        assert_eq!(
            Thresholds::from_units(0.02, 0.001, 0.0001, 0.5),
            Thresholds::table_i()
        );
        assert_eq!(Thresholds::table_i().raw, [5, 5, 5, 1, 1, 1, 6, 1, 1]);
    }
}
