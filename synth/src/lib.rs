//! Synthesis flow of the skinbox interface box for an ECP5 board.
//!
//! [`toolchain`] installs YoWASP's yosys and nextpnr-ecp5 into a venv; [`flow`] writes the
//! box with its board top (`skinbox_gateware::board`), runs `synth_ecp5`, `nextpnr-ecp5`
//! with the board's constraints and `ecppack`, and returns a [`flow::SynthReport`] built
//! from the tools' JSON reports ([`report`]).

pub mod blocks;
pub mod flow;
pub mod netlist_sim;
pub mod report;
pub mod toolchain;

use std::path::PathBuf;

pub use flow::{
    merge, read_seed_shards, run, run_shard, Event, FlowOptions, Placer, SeedResult, SeedShard,
    Stage, SynthReport,
};
pub use toolchain::Toolchain;

/// Why the flow stopped.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The box or board top cannot be built with these parameters.
    #[error(transparent)]
    Config(#[from] skinbox_gateware::interface_box::ConfigError),
    /// No Python to create the venv with.
    #[error(
        "cannot run {python}: the synthesis tools install into a Python venv; install Python \
         with '{}' (scripts/setup.sh does) and run again",
        toolchain::VENV_APT_HINT
    )]
    NoPython {
        /// The interpreter tried.
        python: String,
    },
    /// `python3 -m venv` failed, usually for want of Debian's python3-venv.
    #[error(
        "cannot create a Python venv at {}: {}\ninstall Python's venv module with '{}' \
         (scripts/setup.sh does) and run again",
        venv.display(),
        output.trim(),
        toolchain::VENV_APT_HINT
    )]
    Venv {
        /// Where the venv was to be.
        venv: PathBuf,
        /// What `python3 -m venv` said.
        output: String,
    },
    /// A tool exited with an error.
    #[error("{tool} failed ({status}); its output is in {}; it ended with:\n{tail}", log.display())]
    Tool {
        /// Which tool.
        tool: String,
        /// Its exit status.
        status: String,
        /// Its whole output.
        log: PathBuf,
        /// Its last lines.
        tail: String,
    },
    /// A file could not be read or written, or a process not started.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The error.
        source: std::io::Error,
    },
    /// The design needs more of a resource than the device has.
    #[error(
        "the {ports}-port box does not fit the {part}: {used} {resource} of {available} \
         ({:.0} %)",
        100.0 * *used as f64 / *available as f64
    )]
    DoesNotFit {
        /// UART ports of the box.
        ports: usize,
        /// The FPGA.
        part: String,
        /// nextpnr's name of the resource (`TRELLIS_COMB` for LUT4 positions).
        resource: String,
        /// Needed.
        used: u64,
        /// On the device.
        available: u64,
    },
    /// Shards of a seed sweep that do not make one complete sweep, or an empty shard.
    #[error("{0}")]
    Merge(String),
    /// A tool's report did not parse.
    #[error(transparent)]
    Report(#[from] report::ReportError),
}

impl SynthError {
    pub(crate) fn io(what: impl Into<String>, source: std::io::Error) -> SynthError {
        SynthError::Io {
            what: what.into(),
            source,
        }
    }
}
