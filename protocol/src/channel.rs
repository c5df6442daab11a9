//! The nine sensor channels of a skin cell, their raw units and conversions.
//!
//! Raw steps come from the values the original skin driver reports (docs/design.md section 2):
//! acceleration 1/256 g (10-bit signed, +-2 g), force 1/1024 of the normalised force,
//! proximity 1/65536 (16-bit count), temperature 0.5 C from 0 C.

use core::fmt;

/// One of the nine sensor channels; the discriminant is its bit in an event mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Channel {
    AccelX = 0,
    AccelY = 1,
    AccelZ = 2,
    Force1 = 3,
    Force2 = 4,
    Force3 = 5,
    Proximity = 6,
    Temperature1 = 7,
    Temperature2 = 8,
}

/// The four sensing modalities, as the papers report event rates per modality.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Modality {
    Acceleration,
    Force,
    Proximity,
    Temperature,
}

impl Modality {
    /// All modalities, in channel order.
    pub const ALL: [Modality; 4] = [
        Modality::Acceleration,
        Modality::Force,
        Modality::Proximity,
        Modality::Temperature,
    ];

    /// Short lowercase name.
    pub fn name(self) -> &'static str {
        match self {
            Modality::Acceleration => "acceleration",
            Modality::Force => "force",
            Modality::Proximity => "proximity",
            Modality::Temperature => "temperature",
        }
    }
}

impl Channel {
    /// Number of channels of a cell.
    pub const COUNT: usize = 9;

    /// All channels in mask-bit order.
    pub const ALL: [Channel; Channel::COUNT] = [
        Channel::AccelX,
        Channel::AccelY,
        Channel::AccelZ,
        Channel::Force1,
        Channel::Force2,
        Channel::Force3,
        Channel::Proximity,
        Channel::Temperature1,
        Channel::Temperature2,
    ];

    /// Position in mask-bit order (0..9).
    #[inline]
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The channel at mask bit `index`, if any.
    pub fn from_index(index: usize) -> Option<Channel> {
        Channel::ALL.get(index).copied()
    }

    /// Lowercase identifier, e.g. `accel_x`.
    pub fn name(self) -> &'static str {
        match self {
            Channel::AccelX => "accel_x",
            Channel::AccelY => "accel_y",
            Channel::AccelZ => "accel_z",
            Channel::Force1 => "force_1",
            Channel::Force2 => "force_2",
            Channel::Force3 => "force_3",
            Channel::Proximity => "proximity",
            Channel::Temperature1 => "temperature_1",
            Channel::Temperature2 => "temperature_2",
        }
    }

    /// The modality this channel measures.
    #[inline]
    pub fn modality(self) -> Modality {
        match self {
            Channel::AccelX | Channel::AccelY | Channel::AccelZ => Modality::Acceleration,
            Channel::Force1 | Channel::Force2 | Channel::Force3 => Modality::Force,
            Channel::Proximity => Modality::Proximity,
            Channel::Temperature1 | Channel::Temperature2 => Modality::Temperature,
        }
    }

    /// Physical unit of [`Channel::to_units`]: g, normalised force, normalised proximity, C.
    pub fn unit(self) -> &'static str {
        match self.modality() {
            Modality::Acceleration => "g",
            Modality::Force => "",
            Modality::Proximity => "",
            Modality::Temperature => "C",
        }
    }

    /// Size of one raw step in physical units.
    pub fn units_per_lsb(self) -> f64 {
        match self.modality() {
            Modality::Acceleration => 1.0 / 256.0,
            Modality::Force => 1.0 / 1024.0,
            Modality::Proximity => 1.0 / 65536.0,
            Modality::Temperature => 0.5,
        }
    }

    /// Raw value to physical units.
    pub fn to_units(self, raw: i32) -> f64 {
        f64::from(raw) * self.units_per_lsb()
    }

    /// Range of raw values the channel's 16-bit event word may carry: acceleration is
    /// 10-bit signed (-512..=511, sign-extended in an i16 word), the others u16.
    #[inline]
    pub fn word_range(self) -> core::ops::RangeInclusive<i32> {
        match self.modality() {
            Modality::Acceleration => ACCEL_MIN..=ACCEL_MAX,
            _ => 0..=i32::from(u16::MAX),
        }
    }

    /// Range of raw values the channel's data-packet field holds (temperatures are u8 there).
    #[inline]
    pub fn data_range(self) -> core::ops::RangeInclusive<i32> {
        match self.modality() {
            Modality::Temperature => 0..=i32::from(u8::MAX),
            _ => self.word_range(),
        }
    }

    /// Decodes a 16-bit event word to a raw value (sign-extends acceleration).
    #[inline]
    pub fn decode_word(self, word: u16) -> i32 {
        match self.modality() {
            Modality::Acceleration => i32::from(word as i16),
            _ => i32::from(word),
        }
    }

    /// Encodes a raw value as a 16-bit event word, or `None` when it does not fit.
    pub fn encode_word(self, raw: i32) -> Option<u16> {
        if self.word_range().contains(&raw) {
            Some(raw as u16)
        } else {
            None
        }
    }

    /// Send-on-delta threshold of the papers' Table I (host units: 0.02 g, 0.001, 0.0001,
    /// 0.5 C) in whole raw steps. The comparison is strict (`>`), so a threshold of 0.02 g
    /// = 5.12 steps fires from 6 steps on.
    pub fn table_i_threshold_raw(self) -> u16 {
        let host = match self.modality() {
            Modality::Acceleration => 0.02,
            Modality::Force => 0.001,
            Modality::Proximity => 0.0001,
            Modality::Temperature => 0.5,
        };
        (host / self.units_per_lsb() + 1e-9).floor() as u16
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Smallest raw acceleration: -2 g in 1/256 g (10-bit signed).
pub const ACCEL_MIN: i32 = -512;
/// Largest raw acceleration: 2 g - 1/256 g (10-bit signed).
pub const ACCEL_MAX: i32 = 511;

/// A set of channels, as the 9 low bits of an event packet's mask field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
pub struct ChannelMask(u16);

impl ChannelMask {
    /// Bits that name channels.
    pub const CHANNEL_BITS: u16 = (1 << Channel::COUNT) - 1;
    /// No channel.
    pub const EMPTY: ChannelMask = ChannelMask(0);
    /// Every channel.
    pub const ALL: ChannelMask = ChannelMask(Self::CHANNEL_BITS);

    /// The mask of these bits, or `None` when a bit above channel 8 is set.
    #[inline]
    pub fn from_bits(bits: u16) -> Option<ChannelMask> {
        if bits & !Self::CHANNEL_BITS == 0 {
            Some(ChannelMask(bits))
        } else {
            None
        }
    }

    /// The 9-bit value.
    pub fn bits(self) -> u16 {
        self.0
    }

    /// Whether `channel` is in the set.
    pub fn contains(self, channel: Channel) -> bool {
        self.0 & (1 << channel.index()) != 0
    }

    /// Adds `channel`.
    pub fn insert(&mut self, channel: Channel) {
        self.0 |= 1 << channel.index();
    }

    /// Number of channels in the set.
    pub fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether the set is empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The channels in mask-bit order.
    pub fn iter(self) -> impl Iterator<Item = Channel> {
        Channel::ALL.into_iter().filter(move |c| self.contains(*c))
    }
}

impl FromIterator<Channel> for ChannelMask {
    fn from_iter<I: IntoIterator<Item = Channel>>(iter: I) -> Self {
        let mut mask = ChannelMask::EMPTY;
        for c in iter {
            mask.insert(c);
        }
        mask
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_i_thresholds_in_raw_steps() {
        // 0.02 g / (1/256 g) = 5.12, 0.001 / (1/1024) = 1.024, 0.0001 / (1/65536) = 6.55,
        // 0.5 C / 0.5 C = 1.
        assert_eq!(Channel::AccelY.table_i_threshold_raw(), 5);
        assert_eq!(Channel::Force2.table_i_threshold_raw(), 1);
        assert_eq!(Channel::Proximity.table_i_threshold_raw(), 6);
        assert_eq!(Channel::Temperature1.table_i_threshold_raw(), 1);
    }

    #[test]
    fn units() {
        assert_eq!(Channel::AccelZ.to_units(256), 1.0);
        assert_eq!(Channel::AccelX.to_units(-512), -2.0);
        assert_eq!(Channel::Force1.to_units(1024), 1.0);
        assert_eq!(Channel::Proximity.to_units(32768), 0.5);
        assert_eq!(Channel::Temperature2.to_units(61), 30.5);
    }

    #[test]
    fn words_sign_extend_acceleration_only() {
        assert_eq!(Channel::AccelX.decode_word(0xFFFF), -1);
        assert_eq!(Channel::Force1.decode_word(0xFFFF), 65535);
        assert_eq!(Channel::AccelX.encode_word(-1), Some(0xFFFF));
        assert_eq!(Channel::AccelX.encode_word(40000), None);
        assert_eq!(Channel::AccelX.encode_word(511), Some(0x01FF));
        assert_eq!(Channel::AccelX.encode_word(512), None);
        assert_eq!(Channel::AccelX.encode_word(-512), Some(0xFE00));
        assert_eq!(Channel::AccelX.encode_word(-513), None);
        assert_eq!(Channel::Proximity.encode_word(-1), None);
    }

    #[test]
    fn mask_iterates_in_bit_order() {
        let m: ChannelMask = [Channel::Temperature2, Channel::AccelX, Channel::Force2]
            .into_iter()
            .collect();
        assert_eq!(m.bits(), 0b1_0001_0001);
        assert_eq!(
            m.iter().collect::<Vec<_>>(),
            vec![Channel::AccelX, Channel::Force2, Channel::Temperature2]
        );
        assert_eq!(ChannelMask::from_bits(0x200), None);
    }
}
