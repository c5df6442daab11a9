//! Bad input, counted by reason: what was wrong, how often, and the first few messages.

use serde::Serialize;
use skinbox_protocol::Error;
use std::collections::BTreeMap;

/// How many full messages [`BadInput`] keeps as examples.
pub const MAX_EXAMPLES: usize = 16;

/// Rejected input, counted by reason.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BadInput {
    /// Everything rejected.
    pub total: u64,
    /// Count per reason, e.g. `datagram: bad magic`.
    pub by_reason: BTreeMap<String, u64>,
    /// The first [`MAX_EXAMPLES`] rejections with their full messages.
    pub examples: Vec<String>,
}

impl BadInput {
    /// Counts one rejection with a short `reason` and the full `message`.
    pub fn count(&mut self, reason: &str, message: impl FnOnce() -> String) {
        self.total += 1;
        match self.by_reason.get_mut(reason) {
            Some(n) => *n += 1,
            None => {
                self.by_reason.insert(reason.to_string(), 1);
            }
        }
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(message());
        }
    }

    /// Counts one format error of the protocol crate under `layer` (`datagram`, `record`).
    pub fn count_error(&mut self, layer: &str, error: &Error) {
        let reason = format!("{layer}: {}", error_reason(error));
        self.count(&reason, || format!("{layer}: {error}"));
    }

    /// Count for one reason (0 when never seen).
    pub fn get(&self, reason: &str) -> u64 {
        self.by_reason.get(reason).copied().unwrap_or(0)
    }

    /// Adds another tally into this one.
    pub fn merge(&mut self, other: &BadInput) {
        self.total += other.total;
        for (k, v) in &other.by_reason {
            *self.by_reason.entry(k.clone()).or_insert(0) += v;
        }
        for e in &other.examples {
            if self.examples.len() < MAX_EXAMPLES {
                self.examples.push(e.clone());
            }
        }
    }
}

/// A short, stable name for a format error, used as the counting key.
pub fn error_reason(error: &Error) -> &'static str {
    match error {
        Error::Truncated { .. } => "truncated",
        Error::LengthMismatch { .. } => "length mismatch",
        Error::BadHeader { .. } => "bad cell packet header",
        Error::BadEndOfPacket { .. } => "bad end-of-packet byte",
        Error::BadCellId { .. } => "bad cell id",
        Error::BadEventMask { .. } => "bad event mask",
        Error::BadMagic { .. } => "bad magic",
        Error::UnsupportedVersion { .. } => "unsupported version",
        Error::UnknownKind { .. } => "unknown kind",
        Error::TooManyEntries { .. } => "too many entries",
        Error::BadPort { .. } => "port out of range",
        Error::ValueOutOfRange { .. } => "value out of range",
        Error::BadEvents { .. } => "bad events",
        Error::BadPortCount { .. } => "port count out of range",
        Error::BadFlags { .. } => "undefined flag bits",
        Error::UnusedValueSet { .. } => "unused event value slot not 0",
    }
}
