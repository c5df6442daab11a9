//! ReplicaRegister: a one-bit register that synthesis keeps apart from its copies.
//!
//! A signal that reaches thousands of flip-flops (the ports' reset at 64 ports) is a long
//! net across the whole chip. Several registers with the same input, each driving a region
//! (a group of ports), cut that net into short ones; but yosys merges registers with equal
//! inputs back into one (`opt_merge`). The Verilog of this block puts `(* keep *)` on its
//! `always` block, which yosys carries to the flip-flop and `opt_merge` respects; simulators
//! ignore the attribute. The output follows the input one clock later, like a `DFF`.

use crate::hdl::*;

/// A register of one bit that is never merged with another register of the same input.
#[derive(LogicBlock, Default)]
pub struct ReplicaRegister {
    /// The clock.
    pub clock: Signal<In, Clock>,
    /// The bit to copy.
    pub d: Signal<In, Bit>,
    /// `d` of the previous clock edge (0 before the first edge).
    pub q: Signal<Out, Bit>,
}

impl Logic for ReplicaRegister {
    fn update(&mut self) {
        if self.clock.pos_edge() {
            self.q.next = self.d.val();
        }
    }

    fn connect(&mut self) {
        self.q.connect();
    }

    fn hdl(&self) -> Verilog {
        Verilog::Custom(VERILOG_BODY.into())
    }

    fn timing(&self) -> Vec<TimingInfo> {
        vec![TimingInfo {
            name: "replica_register".into(),
            clock: "clock".into(),
            inputs: vec!["d".into()],
            outputs: vec!["q".into()],
        }]
    }
}

/// The module body: one register, kept.
const VERILOG_BODY: &str = "\
initial begin
   q = 1'b0;
end

(* keep *)
always @(posedge clock) begin
   q <= d;
end
";

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(LogicBlock, Default)]
    struct TwoCopies {
        clock: Signal<In, Clock>,
        d: Signal<In, Bit>,
        a: ReplicaRegister,
        b: ReplicaRegister,
    }

    impl Logic for TwoCopies {
        #[hdl_gen]
        fn update(&mut self) {
            self.a.clock.next = self.clock.val();
            self.b.clock.next = self.clock.val();
            self.a.d.next = self.d.val();
            self.b.d.next = self.d.val();
        }
    }

    #[test]
    fn output_follows_input_one_clock_later() {
        let pattern = [true, true, false, true, false, false, true, false];
        let mut bench = crate::testbench::Bench::new(ReplicaRegister::default(), |r| &mut r.clock);
        let mut seen = Vec::new();
        for &bit in &pattern {
            bench.uut.d.next = bit;
            bench.cycle();
            seen.push(bench.uut.q.val());
        }
        assert_eq!(seen, pattern, "q after each edge is d before it");
    }

    #[test]
    fn every_copy_is_an_instance_of_the_kept_register() {
        let mut uut = TwoCopies::default();
        uut.connect_all();
        let verilog = generate_verilog(&uut)
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        let module = verilog
            .split("module ")
            .find(|m| m.contains("replica_register") || m.starts_with("top$a"))
            .expect("a module for the replicas");
        assert!(
            module.contains("(* keep *) always @(posedge clock) begin q <= d; end"),
            "{module}"
        );
        // two instances of it in the top module, each with its own register
        let top = verilog.split("module top").nth(1).expect("top module");
        assert_eq!(top.matches(".d(").count(), 2, "{top}");
    }
}
