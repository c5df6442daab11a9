//! Scenes: TOML files naming the cells, buses, mode, thresholds, duration, seed and stimulus,
//! and the generation of each bus's packet stream from them.
//!
//! A scene file has a `[scene]` table and optional tables `[bus]`, `[thresholds]`,
//! `[noise]`, `[temperature]`, `[motion]`, `[hammer]`, `[stroke]`, `[crosstalk]` and
//! `[force_stand]` (see `cosim/scenes/*.toml` and `docs/scenes.md`). Unknown keys are errors;
//! every error names the file, the line and what is wrong.
//!
//! `[[commands]]` entries are cell commands the box sends down a bus at a time
//! ([`CommandConfig`]): each leaves the box's UART at its time (after the previous command
//! on that bus), is complete in the root cell 50 us later and one hop latency later in each
//! next cell ([`crate::bus::downlink_arrival_ns`]); a cell takes it at its first sample at or
//! after that, applies it when it is addressed to it or to every cell, and ignores and
//! counts it when it is malformed ([`CellCommandCounts`]). A rate change sets the cell's
//! period from that sample on, with its own clock drift; cells on the box's time grid
//! ([`GenerateOptions::time_sync`]) keep the grid's rate.

use crate::bus::DOWNLINK_PACKET_NS;
use crate::bus::{bit_period_ps, downlink_arrival_ns, BusPacket, BusStats, RootFifo};
use crate::cell::{full_range_units, Cell, CellConfig, Mode, Thresholds};
pub use crate::config::{
    BusConfig, CommandConfig, CommandThresholds, CrosstalkConfig, ForceStandConfig, HammerConfig,
    MotionConfig, NoiseConfig, SceneConfig, SceneTable, StrokeConfig, TemperatureConfig,
    ThresholdConfig, TimeSyncConfig,
};
pub use crate::oscillator::ClockWander;
use crate::rng::Rng;
use crate::signal::SignalModel;
use crate::time_sync::{SyncedClock, TimeSync};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::cell_command::{
    CellCommand, CellCommandRepr, CellMode, ModalityThresholds, SampleRate, ALL_CELLS,
};
use skinbox_protocol::{CellFraming, CellRepr, Channel, ChannelMask, Modality};
use std::cmp::Reverse;
use std::fmt;
use std::path::Path;

/// A scene file that could not be used: which file, which line, what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct SceneError {
    /// File name as given.
    pub file: String,
    /// 1-based line, when the problem has one.
    pub line: Option<usize>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.file, line, self.message),
            None => write!(f, "{}: {}", self.file, self.message),
        }
    }
}

/// A checked scene, ready to generate.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene's settings; change them (e.g. `scene.cells`) and call [`Scene::check`].
    pub config: SceneConfig,
    file: String,
}

/// The line of `key` in `[table]` of `text`, if written there.
fn line_of(text: &str, table: &str, key: &str) -> Option<usize> {
    let mut current = String::new();
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.starts_with('[') {
            current = l.trim_matches(|c| c == '[' || c == ']').trim().to_string();
            if key.is_empty() && current == table {
                return Some(i + 1);
            }
            continue;
        }
        if current == table && !key.is_empty() {
            if let Some(rest) = l.strip_prefix(key) {
                if rest.trim_start().starts_with('=') {
                    return Some(i + 1);
                }
            }
        }
    }
    None
}

/// The line of `key` in the `n`th `[[commands]]` entry of `text` (or of the entry's header).
fn line_of_command(text: &str, n: usize, key: &str) -> Option<usize> {
    let mut entry = None;
    let mut header = None;
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.starts_with('[') {
            entry = if l.replace(' ', "") == "[[commands]]" {
                Some(entry.map_or(0, |e: usize| e + 1))
            } else {
                entry.map(|e| e + 1_000_000)
            };
            if entry == Some(n) {
                header = Some(i + 1);
            }
            continue;
        }
        if entry == Some(n) {
            if let Some(rest) = l.strip_prefix(key) {
                if rest.trim_start().starts_with('=') {
                    return Some(i + 1);
                }
            }
        }
    }
    header
}

/// The cell command packets one bus's root receives: (scene time the first start bit
/// leaves the box, ns; the bytes), in order.
pub type BusDownlink = Vec<(u64, [u8; PACKET_LEN])>;

/// What a `[[commands]]` entry sends: a command, or raw bytes.
#[derive(Debug, Clone, Copy)]
enum Downlink {
    Command(CellCommandRepr),
    Raw([u8; PACKET_LEN]),
}

/// What the cells of a run did with the cell command packets that reached them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CellCommandCounts {
    /// Packets taken at a sample boundary (every packet passes every cell of its bus).
    pub received: u64,
    /// Well-formed commands addressed to the cell or to every cell, applied.
    pub applied: u64,
    /// Malformed packets or unknown commands, ignored.
    pub malformed: u64,
}

/// One problem found by [`Scene::check`]: table, key, message.
type Problem = (&'static str, &'static str, String);

fn positive(table: &'static str, key: &'static str, v: f64, out: &mut Vec<Problem>) {
    if !(v.is_finite() && v > 0.0) {
        out.push((
            table,
            key,
            format!("`{key}` must be a number > 0, found {v}"),
        ));
    }
}

fn non_negative(table: &'static str, key: &'static str, v: f64, out: &mut Vec<Problem>) {
    if !(v.is_finite() && v >= 0.0) {
        out.push((
            table,
            key,
            format!("`{key}` must be a number >= 0, found {v}"),
        ));
    }
}

fn region(table: &'static str, r: [f64; 2], out: &mut Vec<Problem>) {
    if !(r[0].is_finite() && r[1].is_finite() && 0.0 <= r[0] && r[0] <= r[1] && r[1] <= 1.0) {
        out.push((
            table,
            "region",
            format!(
                "`region` must be [from, to] with 0 <= from <= to <= 1, found [{}, {}]",
                r[0], r[1]
            ),
        ));
    }
}

impl Scene {
    /// The scene `name_or_path`: a scene file, or a built-in scene's name (in
    /// [`crate::scenes_dir`]); `None`: stroking_upper_arm.
    pub fn find(name_or_path: Option<&str>) -> Result<Scene, SceneError> {
        let dir = crate::scenes_dir();
        let name = name_or_path.unwrap_or("stroking_upper_arm");
        let path = Path::new(name);
        if path.is_file() {
            return Scene::load(path);
        }
        let builtin = dir.join(format!("{name}.toml"));
        if !name.contains(['/', '.']) && builtin.is_file() {
            return Scene::load(&builtin);
        }
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .map(|entries| {
                entries
                    .filter_map(|e| e.ok())
                    .filter_map(|e| {
                        let p = e.path();
                        (p.extension()? == "toml")
                            .then(|| p.file_stem()?.to_str().map(str::to_string))?
                    })
                    .collect()
            })
            .unwrap_or_default();
        names.sort();
        Err(SceneError {
            file: name.to_string(),
            line: None,
            message: format!(
                "no scene file and no built-in scene of that name (built in: {})",
                names.join(", ")
            ),
        })
    }

    /// Reads and checks a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            file: file.clone(),
            line: None,
            message: format!("cannot read: {e}"),
        })?;
        Scene::parse(&text, &file)
    }

    /// Parses and checks scene text; `file` names it in errors and gives the default name.
    pub fn parse(text: &str, file: &str) -> Result<Scene, SceneError> {
        let mut config: SceneConfig = toml::from_str(text).map_err(|e| SceneError {
            file: file.to_string(),
            line: e.span().map(|s| {
                let before = text.get(..s.start).unwrap_or(text);
                before.matches('\n').count() + 1
            }),
            message: e.message().trim().to_string(),
        })?;
        if config.scene.name.is_empty() {
            config.scene.name = Path::new(file)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
        }
        let scene = Scene {
            config,
            file: file.to_string(),
        };
        if let Some((table, key, message)) = scene.problems().into_iter().next() {
            return Err(SceneError {
                file: file.to_string(),
                line: line_of(text, table, key).or_else(|| line_of(text, table, "")),
                message: format!("[{table}] {message}"),
            });
        }
        if let Some((n, key, message)) = scene.command_problems().into_iter().next() {
            return Err(SceneError {
                file: file.to_string(),
                line: line_of_command(text, n, key),
                message: format!("[[commands]] #{}: {message}", n + 1),
            });
        }
        Ok(scene)
    }

    /// Checks the settings after a change: the first problem, without a line.
    pub fn check(&self) -> Result<(), SceneError> {
        if let Some((table, _, message)) = self.problems().into_iter().next() {
            return Err(SceneError {
                file: self.file.clone(),
                line: None,
                message: format!("[{table}] {message}"),
            });
        }
        match self.command_problems().into_iter().next() {
            None => Ok(()),
            Some((n, _, message)) => Err(SceneError {
                file: self.file.clone(),
                line: None,
                message: format!("[[commands]] #{}: {message}", n + 1),
            }),
        }
    }

    /// What a `[[commands]]` entry sends, or the key that is wrong and why.
    fn downlink_of(c: &CommandConfig) -> Result<Downlink, (&'static str, String)> {
        let given = [
            c.mode.is_some(),
            c.rate_hz.is_some(),
            c.thresholds.is_some(),
            c.enabled.is_some(),
            c.time_sync.is_some(),
            c.raw.is_some(),
        ]
        .into_iter()
        .filter(|g| *g)
        .count();
        if given != 1 {
            return Err((
                "time_s",
                format!(
                    "a command has exactly one of `mode`, `rate_hz`, `thresholds`, `enabled`, \
                     `time_sync`, `raw`; found {given}"
                ),
            ));
        }
        let command = if let Some(m) = c.mode {
            CellCommand::Mode(match m {
                Mode::Data => CellMode::Data,
                Mode::Event => CellMode::Event,
            })
        } else if let Some(hz) = c.rate_hz {
            CellCommand::SampleRate(SampleRate::from_hz(hz).ok_or((
                "rate_hz",
                format!("`rate_hz` must be 62.5, 125, 250, 500 or 1000, found {hz}"),
            ))?)
        } else if let Some(t) = &c.thresholds {
            CellCommand::Thresholds(
                ModalityThresholds::from_units([t.accel_g, t.force, t.proximity, t.temperature_c])
                    .ok_or((
                        "thresholds",
                        "`thresholds` must each be >= 0 and at most 65535 raw steps".to_string(),
                    ))?,
            )
        } else if let Some(names) = &c.enabled {
            let mut mask = ChannelMask::EMPTY;
            for name in names {
                let channel = Channel::ALL
                    .into_iter()
                    .find(|ch| ch.name() == name)
                    .ok_or((
                        "enabled",
                        format!(
                            "unknown channel `{name}` in `enabled`; channels are {}",
                            Channel::ALL.map(|c| c.name()).join(", ")
                        ),
                    ))?;
                mask.insert(channel);
            }
            CellCommand::EnableMask(mask)
        } else if let Some(sync) = c.time_sync {
            if !sync {
                return Err(("time_sync", "`time_sync` must be true".to_string()));
            }
            // The tick is the one at which the packet leaves the box (set in generate).
            CellCommand::TimeSync { box_tick: 0 }
        } else {
            let hex = c.raw.as_deref().unwrap_or_default();
            let bad = || {
                (
                    "raw",
                    format!("`raw` must be 40 hex digits (20 bytes), found \"{hex}\""),
                )
            };
            if hex.len() != 2 * PACKET_LEN || !hex.is_ascii() {
                return Err(bad());
            }
            let mut bytes = [0u8; PACKET_LEN];
            for (i, b) in bytes.iter_mut().enumerate() {
                *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).map_err(|_| bad())?;
            }
            return Ok(Downlink::Raw(bytes));
        };
        Ok(Downlink::Command(CellCommandRepr {
            cell_id: c.cell.unwrap_or(ALL_CELLS),
            command,
        }))
    }

    fn command_problems(&self) -> Vec<(usize, &'static str, String)> {
        let s = &self.config.scene;
        let buses = self.bus_cells();
        let mut p = Vec::new();
        for (n, c) in self.config.commands.iter().enumerate() {
            if !(c.time_s.is_finite() && c.time_s >= 0.0 && c.time_s < s.duration_s) {
                p.push((
                    n,
                    "time_s",
                    format!(
                        "`time_s` must be in 0..{} (the scene's duration), found {}",
                        s.duration_s, c.time_s
                    ),
                ));
            }
            if let Some(port) = c.port.filter(|&port| port >= s.buses) {
                p.push((
                    n,
                    "port",
                    format!("`port` {port}: the scene has buses 0..{}", s.buses),
                ));
            }
            if let Some(id) = c.cell {
                let index = usize::from(id).wrapping_sub(1);
                if id == 0 || usize::from(id) > s.cells {
                    p.push((
                        n,
                        "cell",
                        format!("`cell` {id}: the scene has cells 1..={}", s.cells),
                    ));
                } else if let Some(port) = c.port.filter(|&port| port < s.buses) {
                    if !buses[port].contains(&index) {
                        p.push((
                            n,
                            "cell",
                            format!(
                                "`cell` {id} is not on bus {port} (cells {}..={})",
                                buses[port].start + 1,
                                buses[port].end
                            ),
                        ));
                    }
                }
            }
            if let Err((key, message)) = Self::downlink_of(c) {
                p.push((n, key, message));
            }
        }
        p
    }

    /// Every command the box sends, in time order: the `[[commands]]` entries and the
    /// `[time_sync]` table's sync commands (scene time, ns; the port, `None` for every
    /// port; what it sends).
    fn scheduled(&self) -> Vec<(u64, Option<usize>, Downlink)> {
        let mut out: Vec<_> = self
            .config
            .commands
            .iter()
            .filter_map(|c| {
                Some((
                    (c.time_s * 1e9).round() as u64,
                    c.port,
                    Self::downlink_of(c).ok()?,
                ))
            })
            .collect();
        if let Some(t) = &self.config.time_sync {
            let sync = Downlink::Command(CellCommandRepr {
                cell_id: ALL_CELLS,
                command: CellCommand::TimeSync { box_tick: 0 },
            });
            let mut k = 0;
            loop {
                let time_s = t.start_s + k as f64 * t.interval_s;
                if time_s >= self.config.scene.duration_s || time_s.is_nan() || t.interval_s <= 0.0
                {
                    break;
                }
                out.push(((time_s * 1e9).round() as u64, None, sync));
                k += 1;
            }
        }
        out.sort_by_key(|e| e.0);
        out
    }

    /// The commands as the host sends them, in time order: (scene time, ns; the port,
    /// `None` for every port; the packet, a time sync's tick 0; whether it is a time sync,
    /// whose tick the sender fills in).
    pub fn command_packets(&self) -> Vec<(u64, Option<usize>, [u8; PACKET_LEN], bool)> {
        self.scheduled()
            .into_iter()
            .map(|(time_ns, port, downlink)| match downlink {
                Downlink::Raw(bytes) => (time_ns, port, bytes, false),
                Downlink::Command(repr) => (
                    time_ns,
                    port,
                    repr.to_bytes(),
                    matches!(repr.command, CellCommand::TimeSync { .. }),
                ),
            })
            .collect()
    }

    /// The cell command packets of bus `bus`: (time the first start bit leaves the box, ns;
    /// the bytes), in sending order, one after the other on the box's UART: given by
    /// `options` (a box's downlink), or each at its time (a time sync carrying the tick it
    /// leaves at, box time being scene time).
    fn downlink(&self, bus: usize, options: &GenerateOptions) -> BusDownlink {
        if let Some(given) = &options.downlink {
            return given.get(bus).cloned().unwrap_or_default();
        }
        let mut line_free_ns = 0;
        self.scheduled()
            .into_iter()
            .filter(|c| c.1.is_none_or(|p| p == bus))
            .map(|(time_ns, _, downlink)| {
                let leave_ns = time_ns.max(line_free_ns);
                line_free_ns = leave_ns + DOWNLINK_PACKET_NS;
                let bytes = match downlink {
                    Downlink::Raw(bytes) => bytes,
                    Downlink::Command(mut repr) => {
                        if let CellCommand::TimeSync { box_tick } = &mut repr.command {
                            *box_tick = leave_ns / skinbox_protocol::TICK_NS;
                        }
                        repr.to_bytes()
                    }
                };
                (leave_ns, bytes)
            })
            .collect()
    }

    /// The scene's name.
    pub fn name(&self) -> &str {
        &self.config.scene.name
    }

    fn problems(&self) -> Vec<Problem> {
        let mut p = Vec::new();
        self.scene_problems(&mut p);
        self.bus_and_channel_problems(&mut p);
        self.signal_problems(&mut p);
        p
    }

    /// The problems of `[time_sync]` and `[scene]`.
    fn scene_problems(&self, p: &mut Vec<Problem>) {
        let c = &self.config;
        let s = &c.scene;
        if let Some(t) = &c.time_sync {
            if !(t.interval_s.is_finite() && t.interval_s >= 0.001) {
                p.push((
                    "time_sync",
                    "interval_s",
                    format!(
                        "`interval_s` must be at least 0.001 s, found {}",
                        t.interval_s
                    ),
                ));
            }
            if !(t.start_s.is_finite() && t.start_s >= 0.0) {
                p.push((
                    "time_sync",
                    "start_s",
                    format!("`start_s` must be 0 or more, found {}", t.start_s),
                ));
            }
        }
        positive("scene", "duration_s", s.duration_s, p);
        if s.duration_s > 3_600.0 {
            p.push((
                "scene",
                "duration_s",
                format!("`duration_s` must be at most 3600, found {}", s.duration_s),
            ));
        }
        non_negative("scene", "warmup_s", s.warmup_s, p);
        if s.warmup_s >= s.duration_s {
            p.push((
                "scene",
                "warmup_s",
                format!(
                    "`warmup_s` ({}) must be shorter than `duration_s` ({})",
                    s.warmup_s, s.duration_s
                ),
            ));
        }
        positive("scene", "sample_rate_hz", s.sample_rate_hz, p);
        if s.sample_rate_hz > 10_000.0 {
            p.push((
                "scene",
                "sample_rate_hz",
                format!(
                    "`sample_rate_hz` must be at most 10000, found {}",
                    s.sample_rate_hz
                ),
            ));
        }
        if s.cells == 0 || s.cells > 16_382 {
            p.push((
                "scene",
                "cells",
                format!(
                    "`cells` must be 1..=16382 (cell ids 1..=cells), found {}",
                    s.cells
                ),
            ));
        }
        if s.buses == 0 {
            p.push(("scene", "buses", "`buses` must be at least 1".to_string()));
        } else if s.cells.div_ceil(s.buses) > c.bus.max_cells {
            p.push((
                "scene",
                "buses",
                format!(
                    "{} cells on {} buses put {} cells on a bus; at most {} (`[bus] max_cells`)",
                    s.cells,
                    s.buses,
                    s.cells.div_ceil(s.buses),
                    c.bus.max_cells
                ),
            ));
        }
        if s.columns == 0 {
            p.push((
                "scene",
                "columns",
                "`columns` must be at least 1".to_string(),
            ));
        }
        positive("scene", "cell_pitch_m", s.cell_pitch_m, p);
    }

    /// The problems of `[bus]`, `[thresholds]`, `[noise]` and `[temperature]`.
    fn bus_and_channel_problems(&self, p: &mut Vec<Problem>) {
        let c = &self.config;
        if c.bus.fifo_packets == 0 {
            p.push((
                "bus",
                "fifo_packets",
                "`fifo_packets` must be at least 1".into(),
            ));
        }
        let b = &c.bus;
        if !(b.uart_error_ppm.is_finite() && (0.0..=100_000.0).contains(&b.uart_error_ppm)) {
            p.push((
                "bus",
                "uart_error_ppm",
                format!(
                    "`uart_error_ppm` must be 0..=100000, found {}",
                    b.uart_error_ppm
                ),
            ));
        }
        if !(b.clock_drift_ppm.is_finite() && (0.0..=10_000.0).contains(&b.clock_drift_ppm)) {
            p.push((
                "bus",
                "clock_drift_ppm",
                format!(
                    "`clock_drift_ppm` must be 0..=10000, found {}",
                    b.clock_drift_ppm
                ),
            ));
        }
        let t = &c.thresholds;
        non_negative("thresholds", "accel_g", t.accel_g, p);
        non_negative("thresholds", "force", t.force, p);
        non_negative("thresholds", "proximity", t.proximity, p);
        non_negative("thresholds", "temperature_c", t.temperature_c, p);
        non_negative("thresholds", "refresh_s", t.refresh_s, p);
        for name in &t.enabled {
            if !Channel::ALL.iter().any(|ch| ch.name() == name) {
                p.push((
                    "thresholds",
                    "enabled",
                    format!(
                        "unknown channel `{name}` in `enabled`; channels are {}",
                        Channel::ALL.map(|c| c.name()).join(", ")
                    ),
                ));
            }
        }
        let n = &c.noise;
        non_negative("noise", "accel_g", n.accel_g, p);
        non_negative("noise", "force", n.force, p);
        non_negative("noise", "proximity", n.proximity, p);
        non_negative("noise", "temperature_c", n.temperature_c, p);
        if let Some(t) = &c.temperature {
            non_negative("temperature", "drift_c", t.drift_c, p);
            positive("temperature", "drift_period_s", t.drift_period_s, p);
        }
    }

    /// The problems of the signal sections: motion, hammer, stroke, crosstalk, force stand.
    fn signal_problems(&self, p: &mut Vec<Problem>) {
        let c = &self.config;
        if let Some(m) = &c.motion {
            region("motion", m.region, p);
            non_negative("motion", "accel_g", m.accel_g, p);
            positive("motion", "move_s", m.move_s, p);
            non_negative("motion", "rest_s", m.rest_s, p);
            non_negative("motion", "vibration_g", m.vibration_g, p);
        }
        if let Some(h) = &c.hammer {
            non_negative("hammer", "blows_per_s", h.blows_per_s, p);
            non_negative("hammer", "peak_g", h.peak_g, p);
            positive("hammer", "decay_s", h.decay_s, p);
            non_negative("hammer", "attenuation_per_m", h.attenuation_per_m, p);
            non_negative("hammer", "proximity", h.proximity, p);
            non_negative("hammer", "force", h.force, p);
            if !(h.ring_hz[0] > 0.0 && h.ring_hz[0] <= h.ring_hz[1] && h.ring_hz[1].is_finite()) {
                p.push((
                    "hammer",
                    "ring_hz",
                    format!(
                        "`ring_hz` must be [low, high] with 0 < low <= high, found [{}, {}]",
                        h.ring_hz[0], h.ring_hz[1]
                    ),
                ));
            }
        }
        if let Some(st) = &c.stroke {
            region("stroke", st.region, p);
            if st.hands == 0 || st.hands > 16 {
                p.push((
                    "stroke",
                    "hands",
                    format!("`hands` must be 1..=16, found {}", st.hands),
                ));
            }
            if !(0.001..=1.0).contains(&st.speed_m_per_s) {
                p.push((
                    "stroke",
                    "speed_m_per_s",
                    format!(
                        "`speed_m_per_s` must be 0.001..=1, found {}",
                        st.speed_m_per_s
                    ),
                ));
            }
            positive("stroke", "return_speed_factor", st.return_speed_factor, p);
            positive("stroke", "lower_s", st.lower_s, p);
            non_negative("stroke", "lift_height_m", st.lift_height_m, p);
            positive("stroke", "hand_radius_m", st.hand_radius_m, p);
            non_negative("stroke", "force", st.force, p);
            non_negative("stroke", "proximity", st.proximity, p);
            positive("stroke", "proximity_range_m", st.proximity_range_m, p);
            non_negative("stroke", "vibration_g", st.vibration_g, p);
            non_negative("stroke", "pause_s", st.pause_s, p);
            non_negative("stroke", "pressure_hz", st.pressure_hz, p);
        }
        if let Some(x) = &c.crosstalk {
            non_negative("crosstalk", "force_per_g", x.force_per_g, p);
            non_negative("crosstalk", "proximity_per_g", x.proximity_per_g, p);
        }
        if let Some(f) = &c.force_stand {
            region("force_stand", f.region, p);
            non_negative("force_stand", "amplitude_n", f.amplitude_n, p);
            positive("force_stand", "frequency_hz", f.frequency_hz, p);
            non_negative("force_stand", "force_per_n", f.force_per_n, p);
            non_negative("force_stand", "proximity", f.proximity, p);
        }
    }

    /// The send-on-delta thresholds in raw units.
    pub fn thresholds(&self) -> Thresholds {
        let t = &self.config.thresholds;
        Thresholds::from_units(t.accel_g, t.force, t.proximity, t.temperature_c)
    }

    /// The channels enabled for events.
    pub fn enabled(&self) -> ChannelMask {
        let names = &self.config.thresholds.enabled;
        Channel::ALL
            .into_iter()
            .filter(|c| names.iter().any(|n| n == c.name()))
            .collect()
    }

    /// The clock of the cell at `index` (0-based), drawn from the scene seed.
    pub fn cell_clock(&self, index: usize) -> CellClock {
        let c = &self.config;
        let mut rng = Rng::for_stream(c.scene.seed ^ 0xC10C, index as u64);
        let drift_ppm = rng.range(-c.bus.clock_drift_ppm, c.bus.clock_drift_ppm);
        let uart_error_ppm = rng.range(-c.bus.uart_error_ppm, c.bus.uart_error_ppm);
        CellClock {
            phase_s: rng.range(0.0, 1.0 / c.scene.sample_rate_hz),
            drift_ppm,
            uart_error_ppm,
        }
    }

    /// The bus of each cell position: cells `0..cells` are dealt to buses in contiguous runs
    /// of at most `ceil(cells / buses)`, the first of each run being its root.
    pub fn bus_cells(&self) -> Vec<std::ops::Range<usize>> {
        let s = &self.config.scene;
        let per_bus = s.cells.div_ceil(s.buses.max(1)).max(1);
        (0..s.buses)
            .map(|b| (b * per_bus).min(s.cells)..((b + 1) * per_bus).min(s.cells))
            .collect()
    }

    /// Generates the scene: every bus's packet stream in pin order, with statistics.
    pub fn generate(&self, options: &GenerateOptions) -> Generated {
        let c = &self.config;
        let s = &c.scene;
        let model = SignalModel::new(c);
        let thresholds = self.thresholds();
        let enabled = self.enabled();
        let period_s = 1.0 / s.sample_rate_hz;
        let refresh_every_samples = (c.thresholds.refresh_s * s.sample_rate_hz)
            .round()
            .min(f64::from(u32::MAX)) as u32;
        let mut stats = SceneStats::new(s.duration_s - s.warmup_s, s.cells);
        let mut truth = Vec::new();
        let mut buses = Vec::new();
        // Reused from bus to bus: fresh memory for a million packets costs page faults.
        let mut pending: Vec<Pending> = Vec::new();
        let mut ready_ps: Vec<u64> = Vec::new();
        let mut run_ends: Vec<usize> = Vec::new();
        for (bus_index, cells) in self.bus_cells().into_iter().enumerate() {
            pending.clear();
            ready_ps.clear();
            run_ends.clear();
            let mut root_error_ppm = 0.0;
            let mut cell_uart_error_ppm = Vec::with_capacity(cells.len());
            let downlink = self.downlink(bus_index, options);
            let commands: Vec<Option<CellCommandRepr>> = downlink
                .iter()
                .map(|(_, bytes)| CellCommandRepr::parse(bytes).ok())
                .collect();
            // the time syncs on this bus as the cells' clocks take them: (scene time the
            // packet is complete at the root, [`DOWNLINK_PACKET_NS`] after its first start
            // bit left the box, s; the box time it carries, that of its first start bit,
            // plus the packet's duration, which a cell knows from the baud rate, s), so a
            // sync acts no earlier than any other command (the closed loop checks that)
            let packet_s = DOWNLINK_PACKET_NS as f64 * 1e-9;
            let sync_schedule: Vec<(f64, f64)> = downlink
                .iter()
                .zip(&commands)
                .filter_map(|((leave_ns, _), c)| match c.as_ref()?.command {
                    CellCommand::TimeSync { box_tick } => Some((
                        *leave_ns as f64 * 1e-9 + packet_s,
                        // (a tick before the box's first counts back from 2^64)
                        (box_tick as i64 * skinbox_protocol::TICK_NS as i64) as f64 * 1e-9
                            + packet_s,
                    )),
                    _ => None,
                })
                .collect();
            let mut cell_commands = Vec::with_capacity(cells.len());
            for (position, index) in cells.clone().enumerate() {
                let clock = self.cell_clock(index);
                if position == 0 {
                    root_error_ppm = clock.uart_error_ppm;
                }
                cell_uart_error_ppm.push(clock.uart_error_ppm);
                let ctx = BusContext {
                    model: &model,
                    thresholds,
                    enabled,
                    period_s,
                    refresh_every_samples,
                    options,
                    downlink: &downlink,
                    commands: &commands,
                    sync_schedule: &sync_schedule,
                };
                let mut out = BusOutput {
                    stats: &mut stats,
                    truth: &mut truth,
                    pending: &mut pending,
                    ready_ps: &mut ready_ps,
                };
                let counts = self.generate_cell(&ctx, &mut out, position, index, clock);
                stats.commands.received += counts.received;
                stats.commands.applied += counts.applied;
                stats.commands.malformed += counts.malformed;
                cell_commands.push(counts);
                run_ends.push(pending.len());
            }
            let bit_period = bit_period_ps(root_error_ppm);
            let mut fifo = RootFifo::new(c.bus.fifo_packets, bit_period);
            let mut dropped_per_cell = vec![0u64; cells.len()];
            let mut dropped_sample_time_ns = vec![];
            let packets = to_pin(
                &mut fifo,
                &pending,
                &ready_ps,
                &run_ends,
                &mut dropped_per_cell,
                &mut dropped_sample_time_ns,
            );
            if options.keep_packets {
                stats.offered += pending.len() as u64;
            }
            buses.push(BusStream {
                bus: bus_index,
                cell_ids: cells.map(|i| (i + 1) as u16).collect(),
                root_uart_error_ppm: root_error_ppm,
                cell_uart_error_ppm,
                packets,
                stats: fifo.stats().clone(),
                dropped_per_cell,
                dropped_sample_time_ns,
                downlink,
                cell_commands,
            });
        }
        Generated {
            buses,
            stats,
            truth,
        }
    }

    /// One cell's samples and packets over the scene, obeying the bus's downlink; returns
    /// what it did with the commands it heard.
    fn generate_cell(
        &self,
        ctx: &BusContext,
        out: &mut BusOutput,
        position: usize,
        index: usize,
        clock: CellClock,
    ) -> CellCommandCounts {
        let c = &self.config;
        let s = &c.scene;
        let cell_id = (index + 1) as u16;
        let mut counts = CellCommandCounts::default();
        let mut next_command = 0;
        let mut cell = Cell::new(CellConfig {
            cell_id,
            mode: s.mode,
            thresholds: ctx.thresholds,
            enabled: ctx.enabled,
            refresh_every_samples: ctx.refresh_every_samples,
        });
        let mut signal = ctx.model.cell(index);
        let keep_truth = ctx.options.truth_cells.contains(&cell_id);
        let mut trace = CellTruth {
            cell_id,
            sample_time_ns: Vec::new(),
            truth: Vec::new(),
        };
        // What a host holds of this cell (Algorithm 2): the values of every packet
        // that was not lost on the way, read back from the packet bytes.
        let mut held = [None; Channel::COUNT];
        let mut loss_rng = Rng::for_stream(s.seed ^ 0x1055, index as u64);
        let delay_ns = c.bus.processing_ns + position as u64 * c.bus.hop_latency_ns;
        let (mut synced, wander, mut free_until_s) =
            self.cell_timebase(ctx, position, index, &clock);
        let mut free = FreeClock {
            drift_ppm: clock.drift_ppm,
            nominal_period_s: ctx.period_s,
            period_s: ctx.period_s / (1.0 + clock.drift_ppm * 1e-6),
            segment_start_s: clock.phase_s,
            segment_k: 0,
            wander,
        };
        let mut synced_k = 0;
        let mut k = 0u64;
        loop {
            let t_s = if let (Some(clock), None) = (&mut synced, free_until_s) {
                clock.sample_time_s(k - synced_k)
            } else {
                let t = free.sample_time_s(k);
                match (&mut synced, free_until_s) {
                    (Some(clock), Some(until)) if t >= until => {
                        free_until_s = None;
                        synced_k = k;
                        clock.sample_time_s(0)
                    }
                    _ => t,
                }
            };
            if t_s >= s.duration_s {
                break;
            }
            // Commands complete in this cell by now, at this sample boundary.
            let t_ns = (t_s * 1e9).round() as u64;
            while let Some(&(leave_ns, _)) = ctx.downlink.get(next_command) {
                if downlink_arrival_ns(leave_ns, position, c.bus.hop_latency_ns) > t_ns {
                    break;
                }
                counts.received += 1;
                match &ctx.commands[next_command] {
                    None => counts.malformed += 1,
                    Some(repr) if repr.addresses(cell_id) => {
                        counts.applied += 1;
                        cell.apply(&repr.command);
                        if let CellCommand::SampleRate(rate) = repr.command {
                            free.set_rate(rate.hz(), t_s, k);
                            match (&mut synced, free_until_s) {
                                (Some(clock), None) => clock.set_rate(rate.hz(), k - synced_k),
                                (Some(clock), Some(_)) => {
                                    clock.set_rate_before_first_sync(rate.hz())
                                }
                                (None, _) => {}
                            }
                        }
                    }
                    Some(_) => {}
                }
                next_command += 1;
            }
            k += 1;
            let (value, noise) = ctx.model.sample(&mut signal, t_s);
            let mut measured = value;
            for (m, n) in measured.iter_mut().zip(noise) {
                *m += n;
            }
            let packets = cell.sample_units(&measured);
            let sample_time_ns = (t_s * 1e9).round() as u64;
            if keep_truth {
                trace.sample_time_ns.push(sample_time_ns);
                trace.truth.push(value);
            }
            let mut lost = 0;
            for bytes in packets.as_slice() {
                if ctx.options.packet_loss > 0.0 && loss_rng.uniform() < ctx.options.packet_loss {
                    lost += 1;
                } else {
                    hold(&mut held, bytes);
                }
            }
            if t_s >= s.warmup_s {
                out.stats.record(&packets, lost, &value, &held);
            }
            if ctx.options.keep_packets {
                for bytes in packets.as_slice() {
                    out.ready_ps.push((sample_time_ns + delay_ns) * 1000);
                    out.pending.push(Pending {
                        cell_id,
                        bytes: *bytes,
                        sample_time_ns,
                    });
                }
            } else {
                out.stats.offered += packets.as_slice().len() as u64;
            }
        }
        if keep_truth {
            out.truth.push(trace);
        }
        counts
    }

    /// A cell's time base: the synced clock it samples on (method c of docs/time.md), its
    /// wandering free-running clock, and until when it runs free before its first sync.
    fn cell_timebase(
        &self,
        ctx: &BusContext,
        position: usize,
        index: usize,
        clock: &CellClock,
    ) -> (Option<SyncedClock>, Option<Wandering>, Option<f64>) {
        let c = &self.config;
        let s = &c.scene;
        let phase_s = clock.phase_s;
        // Method c of docs/time.md: the cell samples on the box's grid instead: every
        // `options.time_sync` interval, or as the sync commands on its bus say.
        let mut synced = match &ctx.options.time_sync {
            Some(sync) => Some(SyncedClock::new(
                sync,
                &c.bus,
                position,
                clock.drift_ppm,
                s.sample_rate_hz,
                s.seed,
                index as u64,
            )),
            None if !ctx.sync_schedule.is_empty() => SyncedClock::scheduled(
                &TimeSync {
                    // the cells' firmware runs the rate servo unless the scene says not
                    rate: c.time_sync.as_ref().is_none_or(|t| t.rate),
                    ..TimeSync::every(0.0, &c.bus)
                },
                &c.bus,
                position,
                (clock.drift_ppm, s.sample_rate_hz),
                (s.seed, index as u64),
                ctx.sync_schedule.to_vec(),
            ),
            None => None,
        };
        // A wandering clock (its drift changing over time) is stepped sample by
        // sample; a steady one in closed form.
        let wander = ctx.options.clock_wander.map(|w| {
            let mut rng = Rng::for_stream(s.seed ^ 0x3A4D, index as u64);
            (w, rng.range(0.0, std::f64::consts::TAU), phase_s)
        });
        if let Some((w, angle, _)) = wander {
            synced = synced.map(|clock| clock.with_wander(w, angle));
        }
        if let Some(o) = &c.oscillator {
            let noise = o.noise();
            synced = synced.map(|clock| clock.with_noise(noise, s.seed, index as u64));
        }
        // A cell obeying the box's sync commands runs free until the first one
        // reaches it (then its sample `synced_k` is the grid's first).
        let free_until_s = match ctx.options.time_sync {
            None => synced.as_ref().map(|clock| clock.first_sync_arrival_s()),
            Some(_) => None,
        };
        (synced, wander, free_until_s)
    }
}

/// Takes the values of one packet into a host's held state, as the event-to-data converter
/// (Algorithm 2) does: every channel of a data packet, the fired channels of an event packet.
fn hold(held: &mut [Option<i32>; Channel::COUNT], bytes: &[u8; PACKET_LEN]) {
    match CellRepr::parse(bytes, &CellFraming::DEFAULT) {
        Ok(CellRepr::Data(d)) => {
            for (h, v) in held.iter_mut().zip(d.raw_values()) {
                *h = Some(v);
            }
        }
        Ok(CellRepr::Event(e)) => {
            for (channel, raw) in e.events() {
                held[channel.index()] = Some(raw);
            }
        }
        // The cells make only valid packets (their tests parse every one).
        Err(e) => unreachable!("a cell made an invalid packet: {e}"),
    }
}

/// Offers a bus's packets to its root FIFO in arrival order and returns those that reach the
/// pin. `pending` holds the cells' runs one after the other, each in time order and ending at
/// `run_ends[position]`; `ready_ps[i]` is the arrival of `pending[i]` at the root. The runs
/// are merged; ties go to the lower index, i.e. the cell nearer the root, then sending
/// order. Arrival times sit in their own array so the merge reads little memory.
fn to_pin(
    fifo: &mut RootFifo,
    pending: &[Pending],
    ready_ps: &[u64],
    run_ends: &[usize],
    dropped_per_cell: &mut [u64],
    dropped_sample_time_ns: &mut Vec<u64>,
) -> Vec<BusPacket> {
    let mut packets = Vec::with_capacity(pending.len());
    let mut heap = std::collections::BinaryHeap::with_capacity(run_ends.len());
    let mut run_start = 0;
    for (run, &end) in run_ends.iter().enumerate() {
        if run_start < end {
            heap.push(Reverse((ready_ps[run_start], run_start, run)));
        }
        run_start = end;
    }
    while let Some(Reverse((ready, i, run))) = heap.pop() {
        if i + 1 < run_ends[run] {
            heap.push(Reverse((ready_ps[i + 1], i + 1, run)));
        }
        let p = &pending[i];
        match fifo.offer(ready) {
            Some(pin_edge_ps) => packets.push(BusPacket {
                cell_id: p.cell_id,
                bytes: p.bytes,
                sample_time_ns: p.sample_time_ns,
                pin_edge_ps,
                bit_period_ps: fifo.bit_period_ps(),
            }),
            None => {
                dropped_per_cell[run] += 1;
                dropped_sample_time_ns.push(p.sample_time_ns);
            }
        }
    }
    packets
}

/// A cell's clock: when it samples and how fast its UART runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellClock {
    /// Time of the first sample, s (uniform in one sample period).
    pub phase_s: f64,
    /// Sample-rate error, ppm (uniform in +-`clock_drift_ppm`; positive is fast).
    pub drift_ppm: f64,
    /// UART clock error, ppm (uniform in +-`uart_error_ppm`; positive is fast).
    pub uart_error_ppm: f64,
}

/// A wandering clock's wander, its phase angle and its next sample time, s.
type Wandering = (ClockWander, f64, f64);

/// A cell's free-running sample clock: in closed form from its last rate change on, or
/// stepped sample by sample while its drift wanders.
struct FreeClock {
    drift_ppm: f64,
    nominal_period_s: f64,
    period_s: f64,
    segment_start_s: f64,
    segment_k: u64,
    wander: Option<Wandering>,
}

impl FreeClock {
    /// The time of sample `k`, s (asked for k = 0, 1, 2, ... in turn).
    fn sample_time_s(&mut self, k: u64) -> f64 {
        match &mut self.wander {
            Some((w, angle, next_s)) => {
                let t = *next_s;
                *next_s +=
                    self.nominal_period_s / (1.0 + w.drift_ppm(self.drift_ppm, *angle, t) * 1e-6);
                t
            }
            None => self.segment_start_s + (k - self.segment_k) as f64 * self.period_s,
        }
    }

    /// A new sample rate from sample `k`, at `t_s`, on.
    fn set_rate(&mut self, hz: f64, t_s: f64, k: u64) {
        self.nominal_period_s = 1.0 / hz;
        self.period_s = self.nominal_period_s / (1.0 + self.drift_ppm * 1e-6);
        (self.segment_start_s, self.segment_k) = (t_s, k);
        if let Some((w, angle, next_s)) = &mut self.wander {
            *next_s = t_s
                + self.nominal_period_s / (1.0 + w.drift_ppm(self.drift_ppm, *angle, t_s) * 1e-6);
        }
    }
}

/// What generating one bus's cells shares.
struct BusContext<'a> {
    model: &'a SignalModel,
    thresholds: Thresholds,
    enabled: ChannelMask,
    period_s: f64,
    refresh_every_samples: u32,
    options: &'a GenerateOptions,
    downlink: &'a BusDownlink,
    commands: &'a [Option<CellCommandRepr>],
    sync_schedule: &'a [(f64, f64)],
}

/// Where one bus's cells put what they generate.
struct BusOutput<'a> {
    stats: &'a mut SceneStats,
    truth: &'a mut Vec<CellTruth>,
    pending: &'a mut Vec<Pending>,
    ready_ps: &'a mut Vec<u64>,
}

struct Pending {
    cell_id: u16,
    bytes: [u8; PACKET_LEN],
    sample_time_ns: u64,
}

/// What [`Scene::generate`] keeps.
#[derive(Debug, Clone)]
pub struct GenerateOptions {
    /// Run the buses and keep every packet. Off: only count (for rate studies); the bus
    /// streams then hold no packets and zero counters.
    pub keep_packets: bool,
    /// Cells (by id) whose true signals are kept sample by sample.
    pub truth_cells: Vec<u16>,
    /// Probability that a packet is lost between its cell and the host (independent per
    /// packet, seeded by the scene seed), for the reconstruction error only: the buses
    /// still carry every packet.
    pub packet_loss: f64,
    /// Cells sample on the box's time grid, set by a time-sync command
    /// ([`crate::time_sync`]); `None`: each on its own free-running clock.
    pub time_sync: Option<TimeSync>,
    /// The free-running clocks' drift wanders (temperature) around each cell's own;
    /// `None`: steady.
    pub clock_wander: Option<ClockWander>,
    /// The cell command packets each bus's root receives from the box, as a box's downlink
    /// sends them: per bus, (scene time the first start bit leaves the box, ns; the bytes).
    /// `None`: each `[[commands]]` entry leaves at its own time.
    pub downlink: Option<Vec<BusDownlink>>,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        GenerateOptions {
            keep_packets: true,
            truth_cells: Vec::new(),
            packet_loss: 0.0,
            time_sync: None,
            clock_wander: None,
            downlink: None,
        }
    }
}

/// One bus's packet stream as the box pin sees it.
#[derive(Debug, Clone)]
pub struct BusStream {
    /// Bus index (the box port it is wired to).
    pub bus: usize,
    /// Cell ids along the chain, root first.
    pub cell_ids: Vec<u16>,
    /// UART clock error of the root cell, which drives the pin, ppm.
    pub root_uart_error_ppm: f64,
    /// UART clock error of every cell, in chain order, ppm (the root's is the pin's).
    pub cell_uart_error_ppm: Vec<f64>,
    /// Packets in pin order (ascending `pin_edge_ps`, back to back at best).
    pub packets: Vec<BusPacket>,
    /// Offered, sent and dropped packets, FIFO peak.
    pub stats: BusStats,
    /// Packets dropped per cell, in chain order.
    pub dropped_per_cell: Vec<u64>,
    /// Sample times of the dropped packets, ns, in order of their arrival at the root (to
    /// tell a warm-up's drops from a measurement window's).
    pub dropped_sample_time_ns: Vec<u64>,
    /// The cell command packets sent down this bus: the time their first start bit left the
    /// box, ns, and their bytes, in sending order.
    pub downlink: Vec<(u64, [u8; PACKET_LEN])>,
    /// What each cell did with them, in chain order.
    pub cell_commands: Vec<CellCommandCounts>,
}

impl BusStream {
    /// Packets dropped at the root whose sample was taken at or after `from_ns`.
    pub fn dropped_from(&self, from_ns: u64) -> u64 {
        self.dropped_sample_time_ns
            .iter()
            .filter(|&&t| t >= from_ns)
            .count() as u64
    }
}

/// The true signals of one cell, sample by sample.
#[derive(Debug, Clone)]
pub struct CellTruth {
    /// The cell.
    pub cell_id: u16,
    /// True sample times, ns.
    pub sample_time_ns: Vec<u64>,
    /// True physical values (host units, no sensor noise, not quantised) per sample.
    pub truth: Vec<[f64; Channel::COUNT]>,
}

/// Result of [`Scene::generate`].
#[derive(Debug, Clone)]
pub struct Generated {
    /// One stream per bus.
    pub buses: Vec<BusStream>,
    /// Rates and reconstruction error over the measurement window.
    pub stats: SceneStats,
    /// True signals of the cells asked for.
    pub truth: Vec<CellTruth>,
}

/// Rates and reconstruction error of a scene over its measurement window (after warm-up),
/// counted at the cells (before any bus drop).
#[derive(Debug, Clone)]
pub struct SceneStats {
    /// Length of the window, s.
    pub window_s: f64,
    /// Cells.
    pub cells: usize,
    /// Samples taken in the window.
    pub samples: u64,
    /// Packets sent in the window.
    pub packets: u64,
    /// Events (values sent) per channel in the window (every channel in data mode).
    pub events: [u64; Channel::COUNT],
    /// Packets the cells produced over the whole run (window and warm-up).
    pub offered: u64,
    /// Packets of the window lost on the way to the host ([`GenerateOptions::packet_loss`]).
    pub packets_lost: u64,
    /// Cell command packets over the whole run, summed over the cells.
    pub commands: CellCommandCounts,
    squared_error: [f64; Channel::COUNT],
}

impl SceneStats {
    fn new(window_s: f64, cells: usize) -> SceneStats {
        SceneStats {
            window_s,
            cells,
            samples: 0,
            packets: 0,
            events: [0; Channel::COUNT],
            offered: 0,
            packets_lost: 0,
            commands: CellCommandCounts::default(),
            squared_error: [0.0; Channel::COUNT],
        }
    }

    fn record(
        &mut self,
        packets: &crate::cell::SamplePackets,
        lost: u64,
        truth: &[f64; Channel::COUNT],
        held: &[Option<i32>; Channel::COUNT],
    ) {
        self.samples += 1;
        self.packets += packets.as_slice().len() as u64;
        self.packets_lost += lost;
        for c in packets.fired().iter() {
            self.events[c.index()] += 1;
        }
        for c in Channel::ALL {
            let i = c.index();
            // A channel the host never received reads 0 there.
            let value = c.to_units(held[i].unwrap_or(0));
            self.squared_error[i] += (value - truth[i]).powi(2);
        }
    }

    /// Events per cell per second of a modality (all its channels together).
    pub fn events_per_cell_s(&self, modality: Modality) -> f64 {
        let n: u64 = Channel::ALL
            .iter()
            .filter(|c| c.modality() == modality)
            .map(|c| self.events[c.index()])
            .sum();
        n as f64 / (self.cells as f64 * self.window_s)
    }

    /// Packets per cell per second (the papers' Fig. 11 axis).
    pub fn packets_per_cell_s(&self) -> f64 {
        self.packets as f64 / (self.cells as f64 * self.window_s)
    }

    /// Packets in percent of data mode (one packet per sample).
    pub fn packet_rate_pct(&self) -> f64 {
        100.0 * self.packets as f64 / self.samples.max(1) as f64
    }

    /// RMS error of the reconstructed channel (the host holds the last value it received)
    /// against the true signal, in percent of the channel's full range.
    pub fn rms_error_pct(&self, channel: Channel) -> f64 {
        let i = channel.index();
        100.0 * (self.squared_error[i] / self.samples.max(1) as f64).sqrt()
            / full_range_units(channel)
    }
}
