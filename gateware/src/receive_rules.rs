//! ReceiveRules: the rule table of docs/control.md, steps 1 to 16a, applied to one
//! frame's checks in the model's order.
//!
//! The receive layers register their checks of a frame's fields after its last beat; when
//! they all stand, the frame parser raises `check` for one clock with the table's
//! conditions on the inputs (each high when its step fails, or for the protocol steps when
//! the frame is of that kind), which hold for the next clock too (the layers hold their
//! checks until the next frame reaches the fields). In that next clock the rules resolve
//! the Ethernet steps 1-5 and the IPv4 steps 6-16 each in their order from the inputs
//! (no copy of them), register the two, choose between them and drive `decided` for one clock with `action` and
//! `fate`, [`RULES_LATENCY`] clocks after `check`. An answer (ARP reply, echo reply, command) of a frame that was not `stored`
//! becomes action NONE with fate `ReplyBusy` (step 16a).

use crate::hdl::*;
use skinbox_protocol::box_counters::BoxCounter;

/// Action: nothing to answer.
pub const ACTION_NONE: u8 = 0;
/// Action: answer an ARP request.
pub const ACTION_ARP: u8 = 1;
/// Action: answer an ICMP echo request.
pub const ACTION_ECHO: u8 = 2;
/// Action: a well-formed command from the host subnet (the command unit decides its fate).
pub const ACTION_COMMAND: u8 = 3;
/// Clocks from `check` to `decided`.
pub const RULES_LATENCY: u64 = 3;

fn fate_constant(fate: BoxCounter) -> Constant<Bits<5>> {
    constant(fate as u64)
}

/// The rule table of the receive path; see the module documentation.
#[derive(LogicBlock)]
pub struct ReceiveRules {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// One clock: the conditions below are a frame's (they hold for the next clock too).
    pub check: Signal<In, Bit>,
    /// Step 1 fails: the MAC's length error.
    pub bad_length: Signal<In, Bit>,
    /// Step 2 fails: the FCS.
    pub bad_fcs: Signal<In, Bit>,
    /// Step 3 fails: the destination MAC is neither the box's nor broadcast.
    pub not_to_box: Signal<In, Bit>,
    /// The frame is ARP.
    pub arp: Signal<In, Bit>,
    /// Step 4 holds: an ARP request for the box's IPv4 address.
    pub arp_for_box: Signal<In, Bit>,
    /// Step 5 holds: IPv4 to the box's own MAC.
    pub ipv4: Signal<In, Bit>,
    /// Step 6 fails: version or IHL.
    pub bad_version: Signal<In, Bit>,
    /// Step 7 fails: IPv4 options.
    pub options: Signal<In, Bit>,
    /// Step 8 fails: header checksum or total length.
    pub bad_header: Signal<In, Bit>,
    /// Step 9 fails: a fragment.
    pub fragment: Signal<In, Bit>,
    /// Step 10 fails: the destination IPv4 address is not the box's.
    pub ip_not_to_box: Signal<In, Bit>,
    /// The packet is ICMP.
    pub icmp: Signal<In, Bit>,
    /// Step 11 fails: ICMP length or checksum.
    pub icmp_bad: Signal<In, Bit>,
    /// Step 12 holds: an echo request.
    pub echo_request: Signal<In, Bit>,
    /// The packet is UDP.
    pub udp: Signal<In, Bit>,
    /// Step 13 fails: UDP length or checksum.
    pub udp_bad: Signal<In, Bit>,
    /// Step 14 fails: another UDP port.
    pub other_port: Signal<In, Bit>,
    /// Step 15 fails: the source is outside the host subnet.
    pub foreign: Signal<In, Bit>,
    /// Step 16 fails: not a well-formed command header.
    pub malformed: Signal<In, Bit>,
    /// Step 16a holds: the frame was stored in the reply buffer (read in the clock before
    /// `decided`).
    pub stored: Signal<In, Bit>,
    /// One clock: the decision comes in the next clock.
    pub deciding: Signal<Out, Bit>,
    /// One clock: the frame's decision.
    pub decided: Signal<Out, Bit>,
    /// With `decided`: `ACTION_*`.
    pub action: Signal<Out, Bits<2>>,
    /// With `decided`: the frame's `BoxCounter` index (0 for `ACTION_COMMAND`: the
    /// command unit decides).
    pub fate: Signal<Out, Bits<5>>,
    action_none: Constant<Bits<2>>,
    action_arp: Constant<Bits<2>>,
    action_echo: Constant<Bits<2>>,
    action_command: Constant<Bits<2>>,
    fate_bad_length: Constant<Bits<5>>,
    fate_bad_fcs: Constant<Bits<5>>,
    fate_not_for_us: Constant<Bits<5>>,
    fate_ipv4_bad_header: Constant<Bits<5>>,
    fate_ipv4_options: Constant<Bits<5>>,
    fate_ipv4_fragment: Constant<Bits<5>>,
    fate_bad_transport: Constant<Bits<5>>,
    fate_unknown_udp_port: Constant<Bits<5>>,
    fate_arp_answered: Constant<Bits<5>>,
    fate_pings_answered: Constant<Bits<5>>,
    fate_refused_foreign_subnet: Constant<Bits<5>>,
    fate_refused_malformed: Constant<Bits<5>>,
    fate_reply_busy: Constant<Bits<5>>,
    // the clock after `check`: the conditions are resolved
    registered: DFF<Bit>,
    // the two levels resolved
    resolved: DFF<Bit>,
    use_ip: DFF<Bit>,
    frame_fate: DFF<Bits<5>>,
    frame_action: DFF<Bits<2>>,
    ip_fate: DFF<Bits<5>>,
    ip_action: DFF<Bits<2>>,
    // the decision
    chosen_fate: Signal<Local, Bits<5>>,
    chosen_action: Signal<Local, Bits<2>>,
    decided_out: DFF<Bit>,
    action_out: DFF<Bits<2>>,
    fate_out: DFF<Bits<5>>,
}

impl Default for ReceiveRules {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            check: Default::default(),
            bad_length: Default::default(),
            bad_fcs: Default::default(),
            not_to_box: Default::default(),
            arp: Default::default(),
            arp_for_box: Default::default(),
            ipv4: Default::default(),
            bad_version: Default::default(),
            options: Default::default(),
            bad_header: Default::default(),
            fragment: Default::default(),
            ip_not_to_box: Default::default(),
            icmp: Default::default(),
            icmp_bad: Default::default(),
            echo_request: Default::default(),
            udp: Default::default(),
            udp_bad: Default::default(),
            other_port: Default::default(),
            foreign: Default::default(),
            malformed: Default::default(),
            stored: Default::default(),
            deciding: Default::default(),
            decided: Default::default(),
            action: Default::default(),
            fate: Default::default(),
            action_none: constant(u64::from(ACTION_NONE)),
            action_arp: constant(u64::from(ACTION_ARP)),
            action_echo: constant(u64::from(ACTION_ECHO)),
            action_command: constant(u64::from(ACTION_COMMAND)),
            fate_bad_length: fate_constant(BoxCounter::BadLength),
            fate_bad_fcs: fate_constant(BoxCounter::BadFcs),
            fate_not_for_us: fate_constant(BoxCounter::NotForUs),
            fate_ipv4_bad_header: fate_constant(BoxCounter::Ipv4BadHeader),
            fate_ipv4_options: fate_constant(BoxCounter::Ipv4Options),
            fate_ipv4_fragment: fate_constant(BoxCounter::Ipv4Fragment),
            fate_bad_transport: fate_constant(BoxCounter::BadTransport),
            fate_unknown_udp_port: fate_constant(BoxCounter::UnknownUdpPort),
            fate_arp_answered: fate_constant(BoxCounter::ArpAnswered),
            fate_pings_answered: fate_constant(BoxCounter::PingsAnswered),
            fate_refused_foreign_subnet: fate_constant(BoxCounter::RefusedForeignSubnet),
            fate_refused_malformed: fate_constant(BoxCounter::RefusedMalformed),
            fate_reply_busy: fate_constant(BoxCounter::ReplyBusy),
            registered: Default::default(),
            resolved: Default::default(),
            use_ip: Default::default(),
            frame_fate: Default::default(),
            frame_action: Default::default(),
            ip_fate: Default::default(),
            ip_action: Default::default(),
            chosen_fate: Default::default(),
            chosen_action: Default::default(),
            decided_out: Default::default(),
            action_out: Default::default(),
            fate_out: Default::default(),
        }
    }
}

impl Logic for ReceiveRules {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            registered,
            resolved,
            use_ip,
            frame_fate,
            frame_action,
            ip_fate,
            ip_action,
            decided_out,
            action_out,
            fate_out
        );
        self.registered.d.next = self.check.val();

        // steps 1-5 and steps 6-16, each in the model's order
        self.resolved.d.next = self.registered.q.val();
        if self.registered.q.val() {
            self.use_ip.d.next = false;
            self.frame_action.d.next = self.action_none.val();
            self.frame_fate.d.next = self.fate_not_for_us.val();
            if self.bad_length.val() {
                self.frame_fate.d.next = self.fate_bad_length.val();
            } else if self.bad_fcs.val() {
                self.frame_fate.d.next = self.fate_bad_fcs.val();
            } else if self.not_to_box.val() {
                self.frame_fate.d.next = self.fate_not_for_us.val();
            } else if self.arp.val() {
                if self.arp_for_box.val() {
                    self.frame_fate.d.next = self.fate_arp_answered.val();
                    self.frame_action.d.next = self.action_arp.val();
                }
            } else if self.ipv4.val() {
                self.use_ip.d.next = true;
            }
            self.ip_action.d.next = self.action_none.val();
            self.ip_fate.d.next = self.fate_not_for_us.val();
            if self.bad_version.val() {
                self.ip_fate.d.next = self.fate_ipv4_bad_header.val();
            } else if self.options.val() {
                self.ip_fate.d.next = self.fate_ipv4_options.val();
            } else if self.bad_header.val() {
                self.ip_fate.d.next = self.fate_ipv4_bad_header.val();
            } else if self.fragment.val() {
                self.ip_fate.d.next = self.fate_ipv4_fragment.val();
            } else if self.ip_not_to_box.val() {
                self.ip_fate.d.next = self.fate_not_for_us.val();
            } else if self.icmp.val() {
                if self.icmp_bad.val() {
                    self.ip_fate.d.next = self.fate_bad_transport.val();
                } else if self.echo_request.val() {
                    self.ip_fate.d.next = self.fate_pings_answered.val();
                    self.ip_action.d.next = self.action_echo.val();
                }
            } else if self.udp.val() {
                if self.udp_bad.val() {
                    self.ip_fate.d.next = self.fate_bad_transport.val();
                } else if self.other_port.val() {
                    self.ip_fate.d.next = self.fate_unknown_udp_port.val();
                } else if self.foreign.val() {
                    self.ip_fate.d.next = self.fate_refused_foreign_subnet.val();
                } else if self.malformed.val() {
                    self.ip_fate.d.next = self.fate_refused_malformed.val();
                } else {
                    self.ip_fate.d.next = 0.into();
                    self.ip_action.d.next = self.action_command.val();
                }
            }
        }

        // the decision; an answer without the buffer is ReplyBusy
        self.chosen_fate.next = self.frame_fate.q.val();
        self.chosen_action.next = self.frame_action.q.val();
        if self.use_ip.q.val() {
            self.chosen_fate.next = self.ip_fate.q.val();
            self.chosen_action.next = self.ip_action.q.val();
        }
        self.decided_out.d.next = self.resolved.q.val();
        if self.resolved.q.val() {
            self.fate_out.d.next = self.chosen_fate.val();
            self.action_out.d.next = self.chosen_action.val();
            if (self.chosen_action.val() != self.action_none.val()) & !self.stored.val() {
                self.fate_out.d.next = self.fate_reply_busy.val();
                self.action_out.d.next = self.action_none.val();
            }
        }
        self.deciding.next = self.resolved.q.val();
        self.decided.next = self.decided_out.q.val();
        self.action.next = self.action_out.q.val();
        self.fate.next = self.fate_out.q.val();

        if self.reset.val() {
            self.registered.d.next = false;
            self.resolved.d.next = false;
            self.decided_out.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use BoxCounter::*;

    /// The table's conditions, in input order.
    const CONDITIONS: usize = 19;

    /// docs/control.md's table read top to bottom: the first step that fails gives the
    /// fate; ARP and ping answers, commands and 16a as written there.
    fn table(c: [bool; CONDITIONS], stored: bool) -> (u8, BoxCounter) {
        let [bad_length, bad_fcs, not_to_box, arp, arp_for_box, ipv4, bad_version, options, bad_header, fragment, ip_not_to_box, icmp, icmp_bad, echo_request, udp, udp_bad, other_port, foreign, malformed] =
            c;
        let answer = |action: u8, fate: BoxCounter| {
            if stored {
                (action, fate)
            } else {
                (ACTION_NONE, ReplyBusy)
            }
        };
        let steps: [(bool, BoxCounter); 3] = [
            (bad_length, BadLength),
            (bad_fcs, BadFcs),
            (not_to_box, NotForUs),
        ];
        if let Some(&(_, fate)) = steps.iter().find(|(fails, _)| *fails) {
            return (ACTION_NONE, fate);
        }
        if arp {
            return if arp_for_box {
                answer(ACTION_ARP, ArpAnswered)
            } else {
                (ACTION_NONE, NotForUs)
            };
        }
        if !ipv4 {
            return (ACTION_NONE, NotForUs);
        }
        let ip_steps: [(bool, BoxCounter); 5] = [
            (bad_version, Ipv4BadHeader),
            (options, Ipv4Options),
            (bad_header, Ipv4BadHeader),
            (fragment, Ipv4Fragment),
            (ip_not_to_box, NotForUs),
        ];
        if let Some(&(_, fate)) = ip_steps.iter().find(|(fails, _)| *fails) {
            return (ACTION_NONE, fate);
        }
        if icmp {
            return match (icmp_bad, echo_request) {
                (true, _) => (ACTION_NONE, BadTransport),
                (false, true) => answer(ACTION_ECHO, PingsAnswered),
                (false, false) => (ACTION_NONE, NotForUs),
            };
        }
        if !udp {
            return (ACTION_NONE, NotForUs);
        }
        let udp_steps: [(bool, BoxCounter); 4] = [
            (udp_bad, BadTransport),
            (other_port, UnknownUdpPort),
            (foreign, RefusedForeignSubnet),
            (malformed, RefusedMalformed),
        ];
        match udp_steps.iter().find(|(fails, _)| *fails) {
            Some(&(_, fate)) => (ACTION_NONE, fate),
            // fate 0: the command unit decides
            None if stored => (ACTION_COMMAND, FramesReceived),
            None => (ACTION_NONE, ReplyBusy),
        }
    }

    fn drive(u: &mut ReceiveRules, c: [bool; CONDITIONS]) {
        let inputs = [
            &mut u.bad_length,
            &mut u.bad_fcs,
            &mut u.not_to_box,
            &mut u.arp,
            &mut u.arp_for_box,
            &mut u.ipv4,
            &mut u.bad_version,
            &mut u.options,
            &mut u.bad_header,
            &mut u.fragment,
            &mut u.ip_not_to_box,
            &mut u.icmp,
            &mut u.icmp_bad,
            &mut u.echo_request,
            &mut u.udp,
            &mut u.udp_bad,
            &mut u.other_port,
            &mut u.foreign,
            &mut u.malformed,
        ];
        for (input, &v) in inputs.into_iter().zip(&c) {
            input.next = v;
        }
    }

    /// Random condition sets, each step failing with a probability that reaches every
    /// row of the table, back to back and with gaps: each `decided` comes
    /// [`RULES_LATENCY`] clocks after its `checked`, once, with the table's action and fate.
    #[test]
    fn decisions_follow_the_table_in_order() {
        assert_eq!(FramesReceived as u8, 0, "a command's fate is counter 0");
        let mut rng = TestRng::new(5);
        let mut bench = Bench::new(ReceiveRules::default(), |r| &mut r.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut seen = std::collections::HashSet::new();
        for case in 0..2000 {
            let mut c = [false; CONDITIONS];
            for (i, v) in c.iter_mut().enumerate() {
                // the kinds (ARP, IPv4, ICMP, UDP) and answers often; failures rarely
                let p = if [3, 4, 5, 11, 13, 14].contains(&i) {
                    0.5
                } else {
                    0.08
                };
                *v = rng.chance(p);
            }
            let stored = rng.chance(0.8);
            let want = table(c, stored);
            seen.insert(want);
            drive(&mut bench.uut, c);
            bench.uut.check.next = true;
            bench.cycle();
            bench.uut.check.next = false;
            for k in 1..=RULES_LATENCY + 1 {
                bench.uut.stored.next = stored;
                bench.settle();
                let u = &bench.uut;
                assert_eq!(
                    u.decided.val(),
                    k == RULES_LATENCY,
                    "case {case}, clock {k}"
                );
                assert_eq!(
                    u.deciding.val(),
                    k + 1 == RULES_LATENCY,
                    "case {case}, clock {k}"
                );
                if k == RULES_LATENCY {
                    let got = (u.action.val().to_u8(), u.fate.val().index());
                    assert_eq!(
                        got,
                        (want.0, want.1 as usize),
                        "case {case}: {c:?} {stored}"
                    );
                }
                bench.cycle();
                // (the conditions hold for a clock after `check`); then the next frame's
                // may be on the inputs
                if k == 1 {
                    drive(&mut bench.uut, [true; CONDITIONS]);
                }
            }
        }
        assert!(seen.len() >= 14, "rows reached: {seen:?}");
    }
}
