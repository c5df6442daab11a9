//! GMII bytes to Ethernet frames; [`check`] checks them with independent code.

use crate::GmiiByte;

/// One frame as it left the box.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Clock cycle of the first preamble byte.
    pub first_cycle: u64,
    /// Preamble to FCS.
    pub bytes: Vec<u8>,
}

/// Splits GMII bytes into frames: a frame ends where `tx_en` fell (cycles not
/// consecutive). Also returns the shortest gap between frames, in clocks.
pub fn assemble(bytes: &[GmiiByte]) -> (Vec<Frame>, Option<u64>) {
    let mut frames: Vec<Frame> = vec![];
    let mut min_gap: Option<u64> = None;
    let mut previous: Option<u64> = None;
    for b in bytes {
        match previous {
            Some(p) if b.cycle == p + 1 => {}
            _ => {
                if let Some(p) = previous {
                    let gap = b.cycle - p - 1;
                    min_gap = Some(min_gap.map_or(gap, |g| g.min(gap)));
                }
                frames.push(Frame {
                    first_cycle: b.cycle,
                    bytes: vec![],
                });
            }
        }
        frames
            .last_mut()
            .expect("a frame was started")
            .bytes
            .push(b.data);
        previous = Some(b.cycle);
    }
    (frames, min_gap)
}

/// Shortest gap between consecutive frames, in clocks.
pub fn min_gap(frames: &[Frame]) -> Option<u64> {
    frames
        .windows(2)
        .map(|w| w[1].first_cycle - (w[0].first_cycle + w[0].bytes.len() as u64))
        .min()
}

pub use skinbox_frame_check::{check, FrameError};
