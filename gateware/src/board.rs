//! Board tops for synthesis: the box's `top` with what a real board needs around it.
//!
//! The box itself ([`crate::interface_box`]) has a 125 MHz clock, a reset, one UART pin per
//! port and a GMII transmitter. A board top, written here as Verilog text around the box's
//! Verilog, adds:
//!
//! - an ECP5 PLL (`EHXPLLL`) from the board oscillator to the box clock ([`Pll`]);
//! - RGMII transmit with the ECP5 DDR output primitive `ODDRX1F`: each GMII byte leaves as
//!   two nibbles, the low one while the forwarded clock is high (rising edge), the high one
//!   while it is low; TX_CTL carries `tx_en` on the rising edge and `tx_en ^ tx_er` on the
//!   falling edge (RGMII 2.0, section 3.4). The clock leaves through an `ODDRX1F` of its own
//!   (1 then 0), so it is edge-aligned with the data at the pins: the B50612D PHYs of the
//!   Colorlight boards delay their GTXCLK by about 1.9 ns internally by default, which puts
//!   the sampling edge inside the data eye (see `constraints/colorlight_i5.lpf` for the
//!   source). A PHY without that delay would need the clock shifted by 90 degrees (2 ns).
//! - RGMII receive: RX_CTL and `RXD[3:0]` each through a `DELAYG` of 2 ns ([`RX_DELAY_TAPS`])
//!   into an `IDDRX1F` (the ECP5 DDR input primitive) in the PHY's receive clock
//!   `eth_rx_clk`, the second clock of the design: Q0 (the rising edge) holds `RXD[3:0]` and
//!   rx_dv, Q1 (the falling edge) `RXD[7:4]` and rx_dv XOR rx_er (RGMII 2.0, section 3.4).
//!   The delay is what LiteEth's ECP5 RGMII PHY (`liteeth/phy/ecp5rgmii.py`) applies by
//!   default and litex-boards' `targets/colorlight_i5.py` keeps for this board: the
//!   B50612D sends RXC edge-aligned with the data, and 2 ns put the edge inside the data
//!   eye. [`crate::rx_clock_crossing::RxClockCrossing`] (module [`RX_CROSSING_MODULE`])
//!   takes the bytes into the box clock as `gmii_rxd`, `gmii_rx_dv` and `gmii_rx_er`.
//! - PHY reset: `eth_rst_n` stays low until the PLL has been locked for [`PHY_RESET_CLOCKS`]
//!   clocks (16.8 ms, more than the 10 ms of docs/design.md section 9), and the box stays in
//!   reset until then too, so its first status datagram is not sent into a PHY in reset.
//!   Losing lock starts the sequence again.
//! - MDIO ([`crate::mdio::MdioMaster`], on MDC/MDIO shared by both PHYs, the PHY at
//!   [`PHY_ADDRESS`]): [`MDIO_STARTUP_CLOCKS`] after the PHY reset it restricts
//!   auto-negotiation to 1000BASE-T full duplex, then polls the link every
//!   [`MDIO_POLL_CLOCKS`]. Its `link_up` and `link_speed` outputs go to the box, which
//!   reports them in every status datagram's box counter block.
//! - one status LED (active low): dark until the PHY reset ends; then a 1 Hz heartbeat (bit 26
//!   of a free-running counter) that each frame start, sent or received, inverts for 2^19
//!   clocks (4.2 ms), so traffic shows as flicker.
//! - the UART inputs, straight from the pins: the box's `UartRx` synchronises them.
//!
//! Pins and the clock constraint are in `constraints/` ([`Board::lpf`]).

use crate::interface_box::{verilog, BoxConfig, ConfigError};
use crate::mdio::MdioMaster;
use std::fmt::Write as _;

/// Constraints of the Colorlight i5 on its extension board (and, with another LED pin, the i9).
pub const COLORLIGHT_I5_LPF: &str = include_str!("../../constraints/colorlight_i5.lpf");

/// Clocks the PHY stays in reset after PLL lock: 2^21 at 125 MHz is 16.8 ms.
pub const PHY_RESET_CLOCKS: u64 = 1 << 21;

/// MDIO address of the PHY the box sends through: LiteX's `eth` 0, whose `PHYA[0]` strap
/// is 0 (litex-boards, `platforms/colorlight_i5.py`).
pub const PHY_ADDRESS: u8 = 0;

/// Clocks from the end of the PHY reset to the first MDIO frame, at least: 2^17 (1.05
/// ms), a margin for the PHY's own start-up.
pub const MDIO_STARTUP_CLOCKS: u64 = 1 << 17;

/// Clocks between link polls: 2^24 (134 ms).
pub const MDIO_POLL_CLOCKS: u64 = 1 << 24;

/// Name of the MDIO master's module in the board top's Verilog.
pub const MDIO_MODULE: &str = "skinbox_mdio";

/// Name of the receive clock crossing's module in the board top's Verilog.
pub const RX_CROSSING_MODULE: &str = "skinbox_rx_crossing";

/// The board top's input of the PHY's receive clock, 125 MHz (nextpnr names the clock
/// after it).
pub const RX_CLOCK_PORT: &str = "eth_rx_clk";

/// `DELAYG` taps (25 ps each) on the RGMII receive pins: 2 ns, LiteEth's default
/// `rx_delay`, which litex-boards keeps for the Colorlight i5.
pub const RX_DELAY_TAPS: u32 = 80;

/// The board top's wires of the received GMII in the box clock (the crossing's outputs),
/// named as the box's receive inputs: the box's `top` instance connects each to its port
/// of the same name.
pub const RX_GMII_WIRES: [&str; 3] = ["gmii_rxd", "gmii_rx_dv", "gmii_rx_er"];

/// A board the box can be synthesised for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Board {
    /// Colorlight i5 v7.0: LFE5U-25F-6BG381C, 25 MHz oscillator, two Broadcom B50612D RGMII
    /// PHYs, on the Muse Lab extension board.
    ColorlightI5,
    /// Colorlight i9 v7.2: the i5's pinout with an LFE5U-45F-6BG381C and the LED on L2; the
    /// larger FPGA for comparison.
    ColorlightI9,
}

impl Board {
    /// Every board, the default first.
    pub const ALL: [Board; 2] = [Board::ColorlightI5, Board::ColorlightI9];

    /// Name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Board::ColorlightI5 => "colorlight-i5",
            Board::ColorlightI9 => "colorlight-i9",
        }
    }

    /// The board called `name`, if there is one.
    pub fn from_name(name: &str) -> Option<Board> {
        Board::ALL.into_iter().find(|b| b.name() == name)
    }

    /// The FPGA's part number.
    pub fn part(self) -> &'static str {
        match self {
            Board::ColorlightI5 => "LFE5U-25F-6BG381C",
            Board::ColorlightI9 => "LFE5U-45F-6BG381C",
        }
    }

    /// The device, package and speed grade as nextpnr-ecp5 options.
    pub fn nextpnr_device_args(self) -> &'static [&'static str] {
        match self {
            Board::ColorlightI5 => &["--25k", "--package", "CABGA381", "--speed", "6"],
            Board::ColorlightI9 => &["--45k", "--package", "CABGA381", "--speed", "6"],
        }
    }

    /// Frequency of the board oscillator.
    pub fn oscillator_hz(self) -> u64 {
        25_000_000
    }

    /// Name of the board top module.
    pub fn top_module(self) -> &'static str {
        match self {
            Board::ColorlightI5 => "skinbox_colorlight_i5",
            Board::ColorlightI9 => "skinbox_colorlight_i9",
        }
    }

    /// The board's constraint file (LPF) text.
    pub fn lpf(self) -> String {
        match self {
            Board::ColorlightI5 => COLORLIGHT_I5_LPF.to_string(),
            Board::ColorlightI9 => {
                let i5_led = "LOCATE COMP \"led_n\" SITE \"U16\";";
                assert_eq!(COLORLIGHT_I5_LPF.matches(i5_led).count(), 1);
                COLORLIGHT_I5_LPF
                    .replace(i5_led, "LOCATE COMP \"led_n\" SITE \"L2\"; # i9 v7.2 LED")
            }
        }
    }

    /// Ports the constraints give a receive and a transmit pin: the most ports the board
    /// top can have.
    pub fn uart_pins(self) -> usize {
        let sites = lpf_sites(&self.lpf());
        let count = |prefix: &str| sites.iter().filter(|(p, _)| p.starts_with(prefix)).count();
        count("uart_rx[").min(count("uart_tx["))
    }

    /// The box and its board top as one Verilog text; the top module is
    /// [`Board::top_module`].
    pub fn verilog(self, config: &BoxConfig) -> Result<String, ConfigError> {
        if config.ports > self.uart_pins() {
            return Err(ConfigError::BoardPins {
                ports: config.ports,
                board: self.name(),
                pins: self.uart_pins(),
            });
        }
        let pll = Pll::new(self.oscillator_hz(), config.clock_hz).ok_or(ConfigError::Pll {
            clock_hz: config.clock_hz,
            oscillator_hz: self.oscillator_hz(),
        })?;
        let box_verilog = verilog(config)?;
        let mdio = crate::mdio::module_verilog(
            MdioMaster::new(
                PHY_ADDRESS,
                MDIO_STARTUP_CLOCKS / crate::mdio::MDC_DIVIDER,
                MDIO_POLL_CLOCKS / crate::mdio::MDC_DIVIDER,
            ),
            MDIO_MODULE,
        );
        let rx_crossing = crate::rx_clock_crossing::module_verilog(RX_CROSSING_MODULE);
        Ok(format!(
            "{box_verilog}\n{mdio}\n{rx_crossing}\n{}",
            board_top(self, config.ports, self.oscillator_hz(), &pll)
        ))
    }
}

/// `(port, site)` of every `LOCATE COMP "port" SITE "site";` line of an LPF text.
pub fn lpf_sites(lpf: &str) -> Vec<(String, String)> {
    lpf.lines()
        .filter_map(|line| {
            let line = line.split('#').next()?.trim();
            let rest = line.strip_prefix("LOCATE COMP \"")?;
            let (port, rest) = rest.split_once('"')?;
            let rest = rest.trim_start().strip_prefix("SITE \"")?;
            let (site, _) = rest.split_once('"')?;
            Some((port.to_string(), site.to_string()))
        })
        .collect()
}

/// Dividers of an ECP5 `EHXPLLL` with feedback from its primary output CLKOP:
/// `f_out = f_in * clkfb_div / clki_div`, `f_vco = f_out * clkop_div`.
///
/// Limits as Project Trellis' PLL calculator (`ecppll.cpp`) has them: phase detector input
/// 3.125 to 400 MHz, VCO 400 to 800 MHz, output 10 to 400 MHz. For 25 to 125 MHz this gives
/// the same dividers as `ecppll -i 25 -o 125`: CLKI_DIV 1, CLKFB_DIV 5, CLKOP_DIV 5 (VCO
/// 625 MHz), CLKOP_CPHASE 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Pll {
    /// Reference divider.
    pub clki_div: u64,
    /// Feedback divider.
    pub clkfb_div: u64,
    /// Output divider of CLKOP.
    pub clkop_div: u64,
    /// Coarse phase of CLKOP in VCO cycles: half the divider, no shift.
    pub clkop_cphase: u64,
}

impl Pll {
    const PFD_HZ: (u64, u64) = (3_125_000, 400_000_000);
    const VCO_HZ: (u64, u64) = (400_000_000, 800_000_000);
    const OUTPUT_HZ: (u64, u64) = (10_000_000, 400_000_000);

    /// Dividers that make exactly `output_hz` from `input_hz`, with the VCO nearest
    /// 600 MHz (mid-range); `None` when no divider set makes it exactly.
    pub fn new(input_hz: u64, output_hz: u64) -> Option<Pll> {
        if !(Self::OUTPUT_HZ.0..=Self::OUTPUT_HZ.1).contains(&output_hz) {
            return None;
        }
        let mut best: Option<(u64, Pll)> = None;
        for clki_div in 1..=128u64 {
            let pfd = input_hz / clki_div;
            if !input_hz.is_multiple_of(clki_div) || pfd < Self::PFD_HZ.0 || pfd > Self::PFD_HZ.1 {
                continue;
            }
            if !output_hz.is_multiple_of(pfd) {
                continue;
            }
            let clkfb_div = output_hz / pfd;
            if !(1..=80).contains(&clkfb_div) {
                continue;
            }
            for clkop_div in 1..=128u64 {
                let vco = output_hz * clkop_div;
                if vco < Self::VCO_HZ.0 || vco > Self::VCO_HZ.1 {
                    continue;
                }
                let distance = vco.abs_diff(600_000_000);
                if best.is_none_or(|(d, _)| distance < d) {
                    let pll = Pll {
                        clki_div,
                        clkfb_div,
                        clkop_div,
                        clkop_cphase: (clkop_div - 1) / 2,
                    };
                    best = Some((distance, pll));
                }
            }
        }
        best.map(|(_, pll)| pll)
    }

    /// VCO frequency for `input_hz`.
    pub fn vco_hz(&self, input_hz: u64) -> u64 {
        input_hz / self.clki_div * self.clkfb_div * self.clkop_div
    }
}

/// The board top module around the box's `top`: its ports, then each part of the board.
fn board_top(board: Board, ports: usize, oscillator_hz: u64, pll: &Pll) -> String {
    [
        module_header(board, ports, oscillator_hz, pll),
        pll_instance(oscillator_hz, pll),
        phy_reset(),
        box_instance(ports),
        mdio_instance(),
        rgmii_receive(),
        rgmii_transmit(),
        status_led(),
        "endmodule\n".to_string(),
    ]
    .concat()
}

/// The board top's opening comment (board, clock and PLL dividers) and its module ports.
fn module_header(board: Board, ports: usize, oscillator_hz: u64, pll: &Pll) -> String {
    let (name, part, top) = (board.name(), board.part(), board.top_module());
    let clock_mhz = pll_mhz(oscillator_hz / pll.clki_div * pll.clkfb_div);
    let osc_mhz = pll_mhz(oscillator_hz);
    let vco_mhz = pll_mhz(pll.vco_hz(oscillator_hz));
    let (clki, clkfb, clkop) = (pll.clki_div, pll.clkfb_div, pll.clkop_div);
    let last_port = ports - 1;
    format!(
        r#"// Board top for the {name} ({part}), written by skinbox (gateware/src/board.rs).
// Box clock {clock_mhz} MHz from the {osc_mhz} MHz oscillator: EHXPLLL CLKI_DIV {clki},
// CLKFB_DIV {clkfb}, CLKOP_DIV {clkop} (VCO {vco_mhz} MHz), feedback from CLKOP.
module {top} (
    input  wire clk25,
    input  wire [{last_port}:0] uart_rx,
    output wire [{last_port}:0] uart_tx,
    output wire eth_tx_clk,
    output wire eth_tx_ctl,
    input  wire eth_rx_clk,
    input  wire eth_rx_ctl,
    input  wire [3:0] eth_rx_data,
    output wire [3:0] eth_tx_data,
    output wire eth_rst_n,
    output wire eth_mdc,
    inout  wire eth_mdio,
    output wire led_n
);
"#
    )
}

/// The ECP5 PLL (`EHXPLLL`) from the board oscillator to the box clock `clk125`.
fn pll_instance(oscillator_hz: u64, pll: &Pll) -> String {
    let clock_mhz = pll_mhz(oscillator_hz / pll.clki_div * pll.clkfb_div);
    let osc_mhz = pll_mhz(oscillator_hz);
    let (clki, clkfb, clkop, cphase) =
        (pll.clki_div, pll.clkfb_div, pll.clkop_div, pll.clkop_cphase);
    format!(
        r#"    wire clk125;
    wire pll_locked;

    (* FREQUENCY_PIN_CLKI="{osc_mhz}" *)
    (* FREQUENCY_PIN_CLKOP="{clock_mhz}" *)
    (* ICP_CURRENT="12" *) (* LPF_RESISTOR="8" *) (* MFG_ENABLE_FILTEROPAMP="1" *) (* MFG_GMCREF_SEL="2" *)
    EHXPLLL #(
        .PLLRST_ENA("DISABLED"),
        .INTFB_WAKE("DISABLED"),
        .STDBY_ENABLE("DISABLED"),
        .DPHASE_SOURCE("DISABLED"),
        .OUTDIVIDER_MUXA("DIVA"),
        .OUTDIVIDER_MUXB("DIVB"),
        .OUTDIVIDER_MUXC("DIVC"),
        .OUTDIVIDER_MUXD("DIVD"),
        .CLKI_DIV({clki}),
        .CLKFB_DIV({clkfb}),
        .CLKOP_ENABLE("ENABLED"),
        .CLKOP_DIV({clkop}),
        .CLKOP_CPHASE({cphase}),
        .CLKOP_FPHASE(0),
        .FEEDBK_PATH("CLKOP")
    ) pll (
        .RST(1'b0),
        .STDBY(1'b0),
        .CLKI(clk25),
        .CLKOP(clk125),
        .CLKFB(clk125),
        .PHASESEL0(1'b0),
        .PHASESEL1(1'b0),
        .PHASEDIR(1'b1),
        .PHASESTEP(1'b1),
        .PHASELOADREG(1'b1),
        .PLLWAKESYNC(1'b0),
        .ENCLKOP(1'b0),
        .LOCK(pll_locked)
    );

"#
    )
}

/// The PHY reset: `eth_rst_n` (and `released`, the box's reset) low until the PLL has been
/// locked for [`PHY_RESET_CLOCKS`] clocks.
fn phy_reset() -> String {
    let reset_top = PHY_RESET_CLOCKS.trailing_zeros();
    format!(
        r#"    // PLL lock into the clock domain, then the PHY reset count.
    reg [1:0] locked_sync = 2'b00;
    reg [{reset_top}:0] reset_count = 0;
    wire released = reset_count[{reset_top}];
    always @(posedge clk125) begin
        locked_sync <= {{locked_sync[0], pll_locked}};
        if (!locked_sync[1])
            reset_count <= 0;
        else if (!released)
            reset_count <= reset_count + 1'b1;
    end
    assign eth_rst_n = released;

"#
    )
}

/// The box's `top` with its UART pins, link inputs and GMII wires.
fn box_instance(ports: usize) -> String {
    let mut uart = String::new();
    for i in 0..ports {
        write!(uart, "\n        .uart_rx${i}(uart_rx[{i}]),").unwrap();
        write!(uart, "\n        .uart_tx${i}(uart_tx[{i}]),").unwrap();
    }
    format!(
        r#"    wire [7:0] gmii_txd;
    wire gmii_tx_en;
    wire gmii_tx_er;
    // the received bytes in the box clock, from the receive clock crossing below
    wire [7:0] gmii_rxd;
    wire gmii_rx_dv;
    wire gmii_rx_er;
    wire link_up;
    wire [1:0] link_speed;
    top interface_box (
        .clock(clk125),
        .reset(!released),{uart}
        .link_up(link_up),
        .link_speed(link_speed),
        .gmii_rxd(gmii_rxd),
        .gmii_rx_dv(gmii_rx_dv),
        .gmii_rx_er(gmii_rx_er),
        .gmii_txd(gmii_txd),
        .gmii_tx_en(gmii_tx_en),
        .gmii_tx_er(gmii_tx_er)
    );

"#
    )
}

/// The MDIO master on the shared MDC/MDIO pins, its link state into the box.
fn mdio_instance() -> String {
    format!(
        r#"    // MDIO: Gigabit-only advertisement after the PHY reset, then link polls; link_up and
    // link_speed go into the box's status datagrams.
    wire mdio_out;
    wire mdio_oe;
    {MDIO_MODULE} mdio (
        .clock(clk125),
        .reset(!released),
        .mdio_in(eth_mdio),
        .mdc(eth_mdc),
        .mdio_out(mdio_out),
        .mdio_oe(mdio_oe),
        .link_up(link_up),
        .link_speed(link_speed)
    );
    assign eth_mdio = mdio_oe ? mdio_out : 1'bz;

"#
    )
}

/// RGMII receive: each pin through a `DELAYG` into an `IDDRX1F`, then the receive clock
/// crossing into the box clock.
fn rgmii_receive() -> String {
    let rx_nibbles: String = (0..4)
        .map(|i| {
            format!(
                "    DELAYG #(.DEL_MODE(\"SCLK_ALIGNED\"), .DEL_VALUE({RX_DELAY_TAPS})) \
                 rx_data_delay_{i} (.A(eth_rx_data[{i}]), .Z(rx_data_delayed[{i}]));\n\
                 \x20   IDDRX1F rx_data_{i} (.SCLK(eth_rx_clk), .RST(1'b0), \
                 .D(rx_data_delayed[{i}]), .Q0(rx_data_rise[{i}]), .Q1(rx_data_fall[{i}]));\n"
            )
        })
        .collect();
    format!(
        r#"    // RGMII receive: each pin delayed by {RX_DELAY_TAPS} taps of 25 ps, then sampled on both edges
    // of the PHY's receive clock: Q0 (rising edge) RXD[3:0] and rx_dv, Q1 (falling edge)
    // RXD[7:4] and rx_dv ^ rx_er.
    wire rx_ctl_delayed;
    wire [3:0] rx_data_delayed;
    wire rx_ctl_rise;
    wire rx_ctl_fall;
    wire [3:0] rx_data_rise;
    wire [3:0] rx_data_fall;
    DELAYG #(.DEL_MODE("SCLK_ALIGNED"), .DEL_VALUE({RX_DELAY_TAPS})) rx_ctl_delay (.A(eth_rx_ctl), .Z(rx_ctl_delayed));
    IDDRX1F rx_ctl (.SCLK(eth_rx_clk), .RST(1'b0), .D(rx_ctl_delayed), .Q0(rx_ctl_rise), .Q1(rx_ctl_fall));
{rx_nibbles}
    // The receive bytes into the box clock: the box's receive inputs (top instance above).
    {RX_CROSSING_MODULE} rx_crossing (
        .rx_clock(eth_rx_clk),
        .rx_data({{rx_data_fall, rx_data_rise}}),
        .rx_dv(rx_ctl_rise),
        .rx_er(rx_ctl_rise ^ rx_ctl_fall),
        .clock(clk125),
        .reset(!released),
        .gmii_rxd(gmii_rxd),
        .gmii_rx_dv(gmii_rx_dv),
        .gmii_rx_er(gmii_rx_er)
    );

"#
    )
}

/// RGMII transmit: the forwarded clock, TX_CTL and the data nibbles through `ODDRX1F`s.
fn rgmii_transmit() -> String {
    let nibbles: String = (0..4)
        .map(|i| {
            format!(
                "    ODDRX1F tx_data_{i} (.SCLK(clk125), .RST(1'b0), .D0(gmii_txd[{i}]), \
                 .D1(gmii_txd[{hi}]), .Q(eth_tx_data[{i}]));\n",
                hi = i + 4
            )
        })
        .collect();
    format!(
        r#"    // RGMII: D0 leaves with the rising edge of the forwarded clock, D1 with the falling edge.
    ODDRX1F tx_clk (.SCLK(clk125), .RST(1'b0), .D0(1'b1), .D1(1'b0), .Q(eth_tx_clk));
    ODDRX1F tx_ctl (.SCLK(clk125), .RST(1'b0), .D0(gmii_tx_en), .D1(gmii_tx_en ^ gmii_tx_er), .Q(eth_tx_ctl));
{nibbles}
"#
    )
}

/// The status LED: a heartbeat, inverted for a moment at each frame start.
fn status_led() -> String {
    r#"    // LED: heartbeat, inverted for a moment at each frame start, sent or received.
    reg [26:0] heartbeat = 0;
    reg [18:0] activity = 0;
    reg tx_en_before = 1'b0;
    reg rx_dv_before = 1'b0;
    always @(posedge clk125) begin
        heartbeat <= heartbeat + 1'b1;
        tx_en_before <= gmii_tx_en;
        rx_dv_before <= gmii_rx_dv;
        if ((gmii_tx_en && !tx_en_before) || (gmii_rx_dv && !rx_dv_before))
            activity <= 19'h7ffff;
        else if (activity != 0)
            activity <= activity - 1'b1;
    end
    assign led_n = !(released && (heartbeat[26] ^ (activity != 0)));
"#
    .to_string()
}

/// A frequency in MHz as the PLL attributes write it: "125", or "12.5".
fn pll_mhz(hz: u64) -> String {
    let mhz = hz as f64 / 1e6;
    format!("{mhz}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn pll_for_25_to_125_mhz_matches_ecppll() {
        let pll = Pll::new(25_000_000, 125_000_000).unwrap();
        assert_eq!(
            pll,
            Pll {
                clki_div: 1,
                clkfb_div: 5,
                clkop_div: 5,
                clkop_cphase: 2
            }
        );
        assert_eq!(pll.vco_hz(25_000_000), 625_000_000);
    }

    #[test]
    fn pll_refuses_what_no_divider_makes_exactly() {
        assert_eq!(Pll::new(25_000_000, 124_999_999), None);
        // Above the 400 MHz output limit, below the 10 MHz one.
        assert_eq!(Pll::new(25_000_000, 500_000_000), None);
        assert_eq!(Pll::new(25_000_000, 5_000_000), None);
        let pll = Pll::new(25_000_000, 100_000_000).unwrap();
        assert_eq!(
            25_000_000 / pll.clki_div * pll.clkfb_div,
            100_000_000,
            "{pll:?}"
        );
        assert!((400_000_000..=800_000_000).contains(&pll.vco_hz(25_000_000)));
    }

    #[test]
    fn constraints_place_45_uart_pairs_on_distinct_pins_apart_from_the_board_signals() {
        for board in Board::ALL {
            let sites = lpf_sites(&board.lpf());
            assert_eq!(board.uart_pins(), 45, "{board:?}");
            let mut seen = HashSet::new();
            for (port, site) in &sites {
                assert!(
                    seen.insert(site.clone()),
                    "{board:?}: {site} used twice ({port})"
                );
            }
            for i in 0..45 {
                assert!(sites.iter().any(|(p, _)| *p == format!("uart_rx[{i}]")));
                assert!(sites.iter().any(|(p, _)| *p == format!("uart_tx[{i}]")));
            }
            // the button, the i9's LED and the debugger's links stay free
            for ball in ["K18", "L2", "F18", "H16", "G18", "H17", "H18", "J17"] {
                assert!(
                    !sites
                        .iter()
                        .any(|(p, b)| b == ball && p.starts_with("uart_")),
                    "{board:?}: {ball}"
                );
            }
            for port in [
                "clk25",
                "led_n",
                "eth_tx_clk",
                "eth_tx_ctl",
                "eth_rx_clk",
                "eth_rx_ctl",
                "eth_rx_data[0]",
                "eth_rx_data[3]",
                "eth_rst_n",
                "eth_mdc",
                "eth_mdio",
            ] {
                assert!(sites.iter().any(|(p, _)| p == port), "{board:?}: {port}");
            }
        }
        let led = |b: Board| {
            lpf_sites(&b.lpf())
                .into_iter()
                .find(|(p, _)| p == "led_n")
                .unwrap()
                .1
        };
        assert_eq!(led(Board::ColorlightI5), "U16");
        assert_eq!(led(Board::ColorlightI9), "L2");
    }

    #[test]
    fn board_names_round_trip() {
        for board in Board::ALL {
            assert_eq!(Board::from_name(board.name()), Some(board));
        }
        assert_eq!(Board::from_name("ulx3s"), None);
    }

    #[test]
    fn board_top_wires_every_port_and_splits_bytes_into_nibbles() {
        let config = BoxConfig {
            ports: 3,
            ..BoxConfig::default()
        };
        let text = Board::ColorlightI5.verilog(&config).unwrap();
        assert!(text.contains("module skinbox_colorlight_i5 ("));
        assert!(text.contains("input  wire [2:0] uart_rx,"));
        assert!(text.contains("output wire [2:0] uart_tx,"));
        for i in 0..3 {
            assert!(text.contains(&format!(".uart_rx${i}(uart_rx[{i}]),")));
            assert!(text.contains(&format!(".uart_tx${i}(uart_tx[{i}]),")));
        }
        assert!(!text.contains(".uart_rx$3("));
        assert!(text.contains(".D0(gmii_txd[0]), .D1(gmii_txd[4]), .Q(eth_tx_data[0])"));
        assert!(text.contains(".D0(gmii_txd[3]), .D1(gmii_txd[7]), .Q(eth_tx_data[3])"));
        assert!(text.contains(".D0(gmii_tx_en), .D1(gmii_tx_en ^ gmii_tx_er), .Q(eth_tx_ctl)"));
        assert!(text.contains(".CLKI_DIV(1),"));
        assert!(text.contains(".CLKFB_DIV(5),"));
        assert!(text.contains(".CLKOP_DIV(5),"));
        // The reset counter's top bit is PHY_RESET_CLOCKS.
        assert!(text.contains("reg [21:0] reset_count"));
        // The MDIO master, its module beside the box's, on the shared MDC/MDIO pins.
        assert!(text.contains("module skinbox_mdio("));
        assert!(text.contains("skinbox_mdio mdio ("));
        assert!(text.contains("assign eth_mdio = mdio_oe ? mdio_out : 1'bz;"));
        // RGMII receive: delayed pins into IDDRX1Fs, low nibble and rx_dv on the rising
        // edge, into the crossing in the PHY's receive clock, out in the box clock.
        assert!(text.contains("module skinbox_rx_crossing("));
        assert!(text.contains(".D(rx_ctl_delayed), .Q0(rx_ctl_rise), .Q1(rx_ctl_fall)"));
        assert!(text.contains(".D(rx_data_delayed[3]), .Q0(rx_data_rise[3]), .Q1(rx_data_fall[3])"));
        assert!(text.contains(".DEL_VALUE(80)) rx_data_delay_0 (.A(eth_rx_data[0])"));
        assert!(text.contains(".rx_data({rx_data_fall, rx_data_rise}),"));
        assert!(text.contains(".rx_er(rx_ctl_rise ^ rx_ctl_fall),"));
        assert!(text.contains(".rx_clock(eth_rx_clk),"));
        // both ends of each received GMII wire: the crossing's output, the box's input
        for wire in RX_GMII_WIRES {
            assert_eq!(
                text.matches(&format!(".{wire}({wire})")).count(),
                2,
                "{wire}"
            );
        }
    }

    #[test]
    fn board_top_refuses_more_ports_than_pins_and_clocks_the_pll_cannot_make() {
        let too_many = BoxConfig {
            ports: 65,
            ..BoxConfig::default()
        };
        assert!(matches!(
            Board::ColorlightI5.verilog(&too_many),
            Err(ConfigError::BoardPins { ports: 65, .. })
        ));
        let odd_clock = BoxConfig {
            clock_hz: 124_999_999,
            ..BoxConfig::default()
        };
        let err = Board::ColorlightI5.verilog(&odd_clock).unwrap_err();
        assert_eq!(
            err,
            ConfigError::Pll {
                clock_hz: 124_999_999,
                oscillator_hz: 25_000_000
            },
            "{err}"
        );
    }

    /// Behavioural stand-ins for the ECP5 primitives, only for Verilator's lint.
    const PRIMITIVE_STUBS: &str = r#"
module EHXPLLL #(
    parameter PLLRST_ENA = "DISABLED", parameter INTFB_WAKE = "DISABLED",
    parameter STDBY_ENABLE = "DISABLED", parameter DPHASE_SOURCE = "DISABLED",
    parameter OUTDIVIDER_MUXA = "DIVA", parameter OUTDIVIDER_MUXB = "DIVB",
    parameter OUTDIVIDER_MUXC = "DIVC", parameter OUTDIVIDER_MUXD = "DIVD",
    parameter CLKI_DIV = 1, parameter CLKFB_DIV = 1, parameter CLKOP_ENABLE = "ENABLED",
    parameter CLKOP_DIV = 8, parameter CLKOP_CPHASE = 0, parameter CLKOP_FPHASE = 0,
    parameter FEEDBK_PATH = "CLKOP"
) (
    input RST, input STDBY, input CLKI, output CLKOP, input CLKFB, input PHASESEL0,
    input PHASESEL1, input PHASEDIR, input PHASESTEP, input PHASELOADREG,
    input PLLWAKESYNC, input ENCLKOP, output LOCK
);
    assign CLKOP = CLKI;
    assign LOCK = 1'b1;
endmodule
module ODDRX1F (input SCLK, input RST, input D0, input D1, output Q);
    assign Q = SCLK ? D0 : D1;
endmodule
module IDDRX1F (input SCLK, input RST, input D, output reg Q0, output reg Q1);
    always @(posedge SCLK) Q0 <= D;
    always @(negedge SCLK) Q1 <= D;
endmodule
module DELAYG #(parameter DEL_MODE = "USER_DEFINED", parameter DEL_VALUE = 0) (input A, output Z);
    assign Z = A;
endmodule
"#;

    #[test]
    fn board_top_passes_verilator_lint_with_primitive_stand_ins() {
        let config = BoxConfig {
            ports: 2,
            ..BoxConfig::default()
        };
        let text = Board::ColorlightI5.verilog(&config).unwrap() + PRIMITIVE_STUBS;
        let dir = std::env::temp_dir().join(format!("skinbox-board-lint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("board.v");
        std::fs::write(&file, text).unwrap();
        let mut command = std::process::Command::new("verilator");
        command.args([
            "--lint-only",
            "-Wall",
            "--top-module",
            "skinbox_colorlight_i5",
        ]);
        for waiver in crate::verilog::LINT_WAIVERS {
            command.arg(format!("-Wno-{waiver}"));
        }
        // The stand-ins ignore most of the primitives' pins and parameters.
        command.args(["-Wno-UNUSEDSIGNAL", "-Wno-PINCONNECTEMPTY"]);
        let out = command.arg(&file).output().expect("run verilator");
        std::fs::remove_dir_all(&dir).ok();
        let messages = String::from_utf8_lossy(&out.stderr).into_owned()
            + &String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && !messages.contains("%Warning"),
            "{messages}"
        );
    }
}
