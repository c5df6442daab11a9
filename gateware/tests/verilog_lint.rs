//! The box's Verilog for 1, 8 and 64 ports passes `verilator --lint-only -Wall`, with only
//! the waivers of `skinbox_gateware::verilog::LINT_WAIVERS`.

use skinbox_gateware::interface_box::{verilog, BoxConfig};
use skinbox_gateware::verilog::lint;

fn lint_ports(ports: usize) {
    let config = BoxConfig {
        ports,
        ..BoxConfig::default()
    };
    let text = verilog(&config).expect("valid configuration");
    let dir = std::env::temp_dir().join(format!("skinbox-lint-{}-{ports}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let report = lint(&text, &dir).unwrap_or_else(|e| panic!("{ports} ports: {e}"));
    assert!(report.clean, "{ports} ports:\n{}", report.output);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn one_port_lints_clean() {
    lint_ports(1);
}

#[test]
fn eight_ports_lint_clean() {
    lint_ports(8);
}

#[test]
fn sixty_four_ports_lint_clean() {
    lint_ports(64);
}
