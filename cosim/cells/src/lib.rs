//! Skin cell models, the bus model and calibrated scenes for the skinbox co-simulation.
//!
//! Read in the order a packet is made:
//! - [`signal`]: the true physical signals of a scene and the sensor noise;
//! - [`cell`]: quantisation, data mode and event mode (Algorithm 1, send-on-delta);
//! - [`bus`]: hop latency and the root FIFO feeding the 4 Mbit/s UART; [`BusPacket`] is
//!   what the co-simulation drives onto a box pin;
//! - [`scene`]: scene files (`cosim/scenes/*.toml`) and [`Scene::generate`], which gives
//!   every bus's packet stream, the rates and the reconstruction error;
//! - [`calibration`]: the scenes against the papers' Fig. 8 table;
//! - [`time_sync`]: cells that sample on the box's time grid (a time-sync command).
//!
//! What the co-simulation drives onto the box pins:
//!
//! ```
//! use skinbox_cells::{scenes_dir, GenerateOptions, Scene};
//!
//! let mut scene = Scene::load(&scenes_dir().join("force_test_stand.toml")).unwrap();
//! scene.config.scene.duration_s = 2.0;
//! scene.check().unwrap();
//! let generated = scene.generate(&GenerateOptions::default());
//! for bus in &generated.buses {
//!     for p in &bus.packets {
//!         // Bit k of the packet (k = 0: the first start bit) starts at this time, in ps.
//!         let bit_ps = |k: u64| p.pin_edge_ps + k * u64::from(p.bit_period_ps);
//!         assert!(bit_ps(0) / 1000 >= p.sample_time_ns);
//!         assert_eq!(p.bytes.len(), 20);
//!     }
//!     assert_eq!(bus.stats.dropped, 0);
//! }
//! ```

#![warn(missing_docs)]

pub mod bus;
pub mod calibration;
pub mod cell;
pub mod config;
pub mod oscillator;
pub mod rng;
pub mod scene;
pub mod signal;
pub mod time_sync;

pub use bus::{BusPacket, BusStats, RootFifo};
pub use cell::{Cell, CellConfig, Mode, SendOnDelta, Thresholds};
pub use oscillator::OscillatorNoise;
pub use scene::{
    BusStream, CellClock, CellCommandCounts, CellTruth, ClockWander, GenerateOptions, Generated,
    Scene, SceneError, SceneStats,
};
pub use time_sync::{RateServo, TimeSync};

/// Directory of the scene files shipped with the project.
pub fn scenes_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}
