//! The box's UART receive pins as the models take them: level changes at the clock edges
//! that first sample them.

/// A pin level change, as the clock edge that first samples it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Transition {
    /// The first rising edge that samples the new level.
    pub edge: u64,
    /// The new level.
    pub level: bool,
}
