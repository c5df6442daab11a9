//! VCD tracing on request: a traced model writes a waveform GTKWave can read.

use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;

#[test]
fn a_traced_run_writes_a_vcd_with_the_box_pins() {
    let config = BoxConfig {
        ports: 1,
        ..BoxConfig::default()
    };
    let dir = std::env::temp_dir().join(format!("skinbox-vcd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("box.vcd");
    let model = Model::build(&config, true, &skinbox_cosim::model::default_cache_dir()).unwrap();
    {
        let mut dut = Dut::new(&model, Some(&path)).unwrap();
        dut.set_reset(true);
        dut.run(4, |_| {});
        dut.set_reset(false);
        dut.set_rx(0, false);
        dut.run(200, |_| {});
    }
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.starts_with("$version") || text.contains("$timescale"),
        "not a VCD"
    );
    for signal in ["clock", "reset", "gmii_tx_en", "gmii_txd"] {
        assert!(
            text.contains(&format!(" {signal} ")),
            "no {signal} in the VCD"
        );
    }
    // 204 cycles of 8 ns: the last time stamp is 204 * 8
    assert!(text.contains("#1632"), "simulated time missing");
    std::fs::remove_dir_all(&dir).ok();
    // a model without tracing refuses a VCD path
    let plain = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    assert!(Dut::new(&plain, Some(&path)).is_err());
}
