//! What the tools report, parsed: yosys' cell counts and nextpnr's utilisation, Fmax and
//! critical paths.
//!
//! Inputs are the tools' JSON reports, not their logs:
//! - yosys `tee -q -o FILE stat -json` after `synth_ecp5`: `design.num_cells_by_type` maps a
//!   cell type (`LUT4`, `CCU2C`, `TRELLIS_FF`, `DP16KD`, ...) to its count;
//! - nextpnr-ecp5 `--report FILE`: `utilization` maps a bel type to `{used, available}`,
//!   `fmax` maps a clock net to `{achieved, constraint}` in MHz, and `critical_paths` lists,
//!   per clock pair, the worst path as segments (`clk-to-q`, `routing`, `logic`, `setup`)
//!   with their delay in ns and the cells they run from and to.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A report that does not have the shape the flow expects.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{tool} report: {what}")]
pub struct ReportError {
    /// Which tool wrote the report.
    pub tool: &'static str,
    /// What was wrong with it.
    pub what: String,
}

/// Cell counts after yosys `synth_ecp5`, by cell type.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct YosysStats {
    /// Count of each cell type in the whole (flattened) design.
    pub cells: BTreeMap<String, u64>,
}

impl YosysStats {
    /// Parses the JSON of yosys `stat -json`.
    pub fn parse(json: &str) -> Result<YosysStats, ReportError> {
        #[derive(Deserialize)]
        struct Stat {
            design: Design,
        }
        #[derive(Deserialize)]
        struct Design {
            num_cells_by_type: BTreeMap<String, u64>,
        }
        let stat: Stat = serde_json::from_str(json).map_err(|e| ReportError {
            tool: "yosys",
            what: format!("not the JSON of `stat -json` ({e})"),
        })?;
        Ok(YosysStats {
            cells: stat.design.num_cells_by_type,
        })
    }

    /// Count of `cell_type` cells, 0 when there are none.
    pub fn count(&self, cell_type: &str) -> u64 {
        self.cells.get(cell_type).copied().unwrap_or(0)
    }
}

/// Used and available resources of one kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Use {
    /// Used by the design.
    pub used: u64,
    /// On the device.
    pub available: u64,
}

/// Fmax of one clock.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockFmax {
    /// Highest frequency the placed and routed design runs at, MHz.
    pub achieved: f64,
    /// The constraint, MHz.
    pub constraint: f64,
}

/// One segment of a timing path.
#[derive(Debug, Clone, PartialEq, Deserialize)]
struct Segment {
    #[serde(rename = "type")]
    kind: String,
    delay: f64,
    from: Endpoint,
    to: Endpoint,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
struct Endpoint {
    cell: String,
}

/// The worst path between two clock edges, summarised.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CriticalPath {
    /// Launching clock edge, e.g. `posedge clk125`.
    pub from_clock: String,
    /// Capturing clock edge.
    pub to_clock: String,
    /// Sum of the segment delays (clock-to-out, logic, routing, setup), ns.
    pub delay_ns: f64,
    /// Of which in routing, ns.
    pub routing_ns: f64,
    /// LUTs and carry cells passed through.
    pub logic_levels: usize,
    /// Cell the path starts at.
    pub start_cell: String,
    /// Cell the path ends at.
    pub end_cell: String,
    /// Blocks of the box the path passes, in order, each once per visit: the instance
    /// below the box (`framer`, `arbiter`, `buffers$3`, ...), `board` for the board top.
    pub blocks: Vec<String>,
}

/// nextpnr-ecp5's `--report` JSON.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NextpnrReport {
    /// Resources by bel type (`TRELLIS_COMB`, `TRELLIS_FF`, `DP16KD`, `TRELLIS_IO`, ...).
    pub utilization: BTreeMap<String, Use>,
    /// Fmax by clock net.
    pub fmax: BTreeMap<String, ClockFmax>,
    /// Worst path per clock pair.
    pub critical_paths: Vec<CriticalPath>,
}

impl NextpnrReport {
    /// Parses the JSON of `nextpnr-ecp5 --report`. `box_instance` is the instance name of
    /// the box in the board top, used to name the blocks of critical paths.
    pub fn parse(json: &str, box_instance: &str) -> Result<NextpnrReport, ReportError> {
        #[derive(Deserialize)]
        struct Raw {
            utilization: BTreeMap<String, Use>,
            #[serde(default)]
            fmax: BTreeMap<String, ClockFmax>,
            #[serde(default)]
            critical_paths: Vec<RawPath>,
        }
        #[derive(Deserialize)]
        struct RawPath {
            from: String,
            to: String,
            path: Vec<Segment>,
        }
        let raw: Raw = serde_json::from_str(json).map_err(|e| ReportError {
            tool: "nextpnr",
            what: format!("not the JSON of `--report` ({e})"),
        })?;
        let critical_paths = raw
            .critical_paths
            .into_iter()
            .filter(|p| !p.path.is_empty())
            .map(|p| summarise(p.from, p.to, &p.path, box_instance))
            .collect();
        Ok(NextpnrReport {
            utilization: raw.utilization,
            fmax: raw.fmax,
            critical_paths,
        })
    }

    /// Resources of bel type `kind`; zero of zero when the device has none.
    pub fn usage(&self, kind: &str) -> Use {
        self.utilization.get(kind).copied().unwrap_or_default()
    }

    /// The clock constrained to `target_mhz` (within 0.1 %) and its Fmax, leaving out a
    /// clock whose name contains `except` (another clock of the same frequency, named after
    /// its pin). nextpnr names a clock after the net that its global buffer drives, which
    /// need not be the net the constraint named, so the constraint identifies the domain.
    pub fn clock_at(&self, target_mhz: f64, except: Option<&str>) -> Option<(&str, ClockFmax)> {
        self.fmax
            .iter()
            .filter(|(name, _)| except.is_none_or(|e| !name.contains(e)))
            .find(|(_, f)| (f.constraint - target_mhz).abs() <= target_mhz * 1e-3)
            .map(|(name, f)| (name.as_str(), *f))
    }
}

/// A line of nextpnr's "Device utilisation" table, `Info: \t TRELLIS_COMB:   27625/  24288
/// 113%`, as the resource and its use; `None` for any other line.
pub fn utilisation_line(line: &str) -> Option<(String, Use)> {
    let rest = line.strip_prefix("Info:")?.trim();
    let (name, counts) = rest.split_once(':')?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return None;
    }
    let (used, rest) = counts.split_once('/')?;
    let available = rest.split_whitespace().next()?;
    if !rest.trim_end().ends_with('%') {
        return None;
    }
    Some((
        name.to_string(),
        Use {
            used: used.trim().parse().ok()?,
            available: available.parse().ok()?,
        },
    ))
}

fn summarise(from: String, to: String, path: &[Segment], box_instance: &str) -> CriticalPath {
    let mut blocks: Vec<String> = Vec::new();
    let mut visit = |cell: &str| {
        let Some(block) = block_of(cell, box_instance) else {
            return;
        };
        if blocks.last() != Some(&block) {
            blocks.push(block);
        }
    };
    for segment in path {
        visit(&segment.from.cell);
        visit(&segment.to.cell);
    }
    CriticalPath {
        from_clock: from,
        to_clock: to,
        delay_ns: path.iter().map(|s| s.delay).sum(),
        routing_ns: path
            .iter()
            .filter(|s| s.kind == "routing")
            .map(|s| s.delay)
            .sum(),
        logic_levels: path.iter().filter(|s| s.kind == "logic").count(),
        start_cell: path[0].from.cell.clone(),
        end_cell: path[path.len() - 1].to.cell.clone(),
        blocks,
    }
}

/// `framer` for `interface_box.framer.offset_left.q_TRELLIS_FF_Q`; `board` for a cell of
/// the board top itself; `None` for a cell the tools made up (`$nextpnr_CCU2C_103$...`),
/// which belongs to whatever block its neighbours on the path belong to.
fn block_of(cell: &str, box_instance: &str) -> Option<String> {
    if cell.starts_with('$') {
        return None;
    }
    let prefix = format!("{box_instance}.");
    Some(match cell.strip_prefix(&prefix) {
        Some(rest) => rest.split('.').next().unwrap_or(rest).to_string(),
        None => "board".to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shape of yosys 0.70 `stat -json`, cut down.
    const YOSYS_STAT: &str = r#"{
   "creator": "Yosys 0.70",
   "invocation": "stat -json ",
   "modules": {
      "\\skinbox_colorlight_i5": { "num_cells": 12, "num_cells_by_type": { "LUT4": 7 } }
   },
   "design": {
      "num_wires": 40,
      "num_cells": 12,
      "num_cells_by_type": {
         "CCU2C": 2,
         "DP16KD": 1,
         "LUT4": 7,
         "TRELLIS_FF": 2
      }
   }
}"#;

    /// The shape of nextpnr-ecp5 0.11 `--report`, cut down to one short path.
    const NEXTPNR_REPORT: &str = r#"{
 "critical_paths": [
  {
   "from": "posedge clk125",
   "to": "posedge clk125",
   "path": [
    { "type": "clk-to-q", "delay": 0.5,
      "from": { "cell": "interface_box.framer.state_q", "loc": [3, 4], "port": "CLK" },
      "to": { "cell": "interface_box.framer.state_q", "loc": [3, 4], "port": "Q" } },
    { "type": "routing", "delay": 1.25, "net": "interface_box.framer.state[0]",
      "from": { "cell": "interface_box.framer.state_q", "loc": [3, 4], "port": "Q" },
      "to": { "cell": "interface_box.arbiter.grant_LUT4", "loc": [5, 4], "port": "A" } },
    { "type": "logic", "delay": 0.25,
      "from": { "cell": "interface_box.arbiter.grant_LUT4", "loc": [5, 4], "port": "A" },
      "to": { "cell": "interface_box.arbiter.grant_LUT4", "loc": [5, 4], "port": "F" } },
    { "type": "routing", "delay": 0.5, "net": "n6",
      "from": { "cell": "interface_box.arbiter.grant_LUT4", "loc": [5, 4], "port": "F" },
      "to": { "cell": "$nextpnr_CCU2C_7$CCU2_COMB0", "loc": [6, 4], "port": "A" } },
    { "type": "routing", "delay": 0.5, "net": "n7",
      "from": { "cell": "$nextpnr_CCU2C_7$CCU2_COMB0", "loc": [6, 4], "port": "F" },
      "to": { "cell": "interface_box.buffers$3.ram", "loc": [9, 4], "port": "ADA5" } },
    { "type": "setup", "delay": 0.5,
      "from": { "cell": "interface_box.buffers$3.ram", "loc": [9, 4], "port": "CLKA" },
      "to": { "cell": "interface_box.buffers$3.ram", "loc": [9, 4], "port": "ADA5" } }
   ]
  }
 ],
 "fmax": {
  "$glbnet$clk125": { "achieved": 68.7, "constraint": 125 },
  "$glbnet$eth_rx_clk": { "achieved": 210.5, "constraint": 125 },
  "clk25": { "achieved": 400.0, "constraint": 25 }
 },
 "utilization": {
  "DP16KD": { "available": 56, "used": 5 },
  "TRELLIS_COMB": { "available": 24288, "used": 5581 },
  "TRELLIS_FF": { "available": 24288, "used": 2870 },
  "TRELLIS_IO": { "available": 197, "used": 17 }
 }
}"#;

    #[test]
    fn yosys_cell_counts_come_from_the_whole_design() {
        let stats = YosysStats::parse(YOSYS_STAT).unwrap();
        assert_eq!(stats.count("LUT4"), 7);
        assert_eq!(stats.count("CCU2C"), 2);
        assert_eq!(stats.count("DP16KD"), 1);
        assert_eq!(stats.count("TRELLIS_DPR16X4"), 0);
    }

    #[test]
    fn nextpnr_utilisation_fmax_and_path_parse() {
        let report = NextpnrReport::parse(NEXTPNR_REPORT, "interface_box").unwrap();
        assert_eq!(
            report.usage("TRELLIS_COMB"),
            Use {
                used: 5581,
                available: 24288
            }
        );
        assert_eq!(report.usage("TRELLIS_IO").used, 17);
        assert_eq!(report.usage("MULT18X18D"), Use::default());
        let (clock, fmax) = report.clock_at(125.0, None).unwrap();
        assert_eq!(clock, "$glbnet$clk125");
        assert_eq!(fmax.achieved, 68.7);
        assert!(report.clock_at(100.0, None).is_none());
        // another clock of the same frequency is told apart by its name
        let (rx, rx_fmax) = report.clock_at(125.0, Some("clk125")).unwrap();
        assert_eq!((rx, rx_fmax.achieved), ("$glbnet$eth_rx_clk", 210.5));
        assert_eq!(
            report.clock_at(125.0, Some("eth_rx_clk")).unwrap().0,
            "$glbnet$clk125"
        );

        let path = &report.critical_paths[0];
        assert_eq!(path.from_clock, "posedge clk125");
        assert!((path.delay_ns - 3.5).abs() < 1e-9);
        assert!((path.routing_ns - 2.25).abs() < 1e-9);
        assert_eq!(path.logic_levels, 1);
        assert_eq!(path.start_cell, "interface_box.framer.state_q");
        assert_eq!(path.end_cell, "interface_box.buffers$3.ram");
        assert_eq!(path.blocks, ["framer", "arbiter", "buffers$3"]);
    }

    #[test]
    fn cells_outside_the_box_belong_to_the_board_and_made_up_ones_to_no_block() {
        let block = |cell| block_of(cell, "interface_box");
        assert_eq!(block("reset_count_TRELLIS_FF_Q").as_deref(), Some("board"));
        assert_eq!(block("interface_box.uarts$0.x").as_deref(), Some("uarts$0"));
        assert_eq!(block("$nextpnr_CCU2C_103$CCU2_COMB0"), None);
    }

    #[test]
    fn utilisation_lines_of_the_log_parse_and_other_lines_do_not() {
        assert_eq!(
            utilisation_line("Info: \t        TRELLIS_COMB:   27625/  24288   113%"),
            Some((
                "TRELLIS_COMB".to_string(),
                Use {
                    used: 27625,
                    available: 24288
                }
            ))
        );
        assert_eq!(
            utilisation_line("Info: \t              DP16KD:       5/     56     8%")
                .unwrap()
                .1
                .used,
            5
        );
        for other in [
            "Info: Device utilisation:",
            "Info: constraining clock net 'clk25' to 25.00 MHz",
            "Info:     at initial placer iter 0, wirelen = 9288",
            "Info: Max frequency for clock 'clk': 72.68 MHz (FAIL at 125.00 MHz)",
        ] {
            assert_eq!(utilisation_line(other), None, "{other}");
        }
    }

    #[test]
    fn reports_of_another_shape_are_refused_with_the_tool_named() {
        let err = YosysStats::parse("{\"modules\": {}}").unwrap_err();
        assert_eq!(err.tool, "yosys");
        let err = NextpnrReport::parse("[]", "interface_box").unwrap_err();
        assert_eq!(err.tool, "nextpnr");
        assert!(err.to_string().starts_with("nextpnr report: "), "{err}");
    }
}
