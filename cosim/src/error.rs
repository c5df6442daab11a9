//! Why a co-simulation could not run: the one error type of the crate, below every module
//! that returns it.

use skinbox_gateware::interface_box::ConfigError;
use std::path::PathBuf;

/// Why a model could not be built or loaded, or a run could not be checked.
#[derive(Debug, thiserror::Error)]
pub enum CosimError {
    /// The box parameters are impossible.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Verilator is not installed.
    #[error("verilator not found ({0}): install it with 'apt-get install -y verilator' (scripts/test and scripts/run do)")]
    NoVerilator(std::io::Error),
    /// Verilator, the C++ compiler or the linker failed.
    #[error("{step} failed:\n{output}")]
    Tool { step: &'static str, output: String },
    /// A frame failed the independent checks, or a predicted frame could not be encoded.
    #[error("{step}: {source}")]
    Frame {
        step: &'static str,
        source: skinbox_frame_check::FrameError,
    },
    /// The host frames of a spec cannot be driven as given.
    #[error("host frames: {0}")]
    HostFrames(String),
    /// The box sent something a box of its configuration cannot send.
    #[error("the box sent {0}")]
    BoxOutput(String),
    /// A frame's UDP payload is not a box datagram.
    #[error("parsing a datagram: {0}")]
    Datagram(#[from] skinbox_protocol::Error),
    /// Writing the pcap file failed.
    #[error("writing the pcap: {0}")]
    Pcap(String),
    /// A scene could not be loaded or generated.
    #[error(transparent)]
    Scene(#[from] skinbox_cells::scene::SceneError),
    /// Reading or writing the cache.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A scene has more or fewer buses than a box has ports.
    #[error("the scene has {0} buses; the box has 1 to 64 ports")]
    Ports(usize),
    /// A closed-loop run's cells could not follow the box's downlink.
    #[error("closed loop: {0}")]
    ClosedLoop(String),
    /// The shared library could not be loaded.
    #[error("loading {path}: {message}")]
    Load { path: PathBuf, message: String },
}
