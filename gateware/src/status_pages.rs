//! StatusPages: which ports the status reporter's page holds: its first port and its port
//! count, [`PORTS_PER_STATUS`] or the ports left.
//!
//! `rewind` (a report starts) goes back to port 0; `load` (the page is set up) takes the
//! page's port count; `advance` (the page was sent) moves on to the ports after it, and
//! `last_page` says that none are left. The ports left are a register of their own, kept
//! beside the first port (`ports - first_port`, set and decreased with it), so the page's
//! count is chosen from registers only: no subtraction in front of its load. Cost: 21
//! flip-flops, a 7-bit adder, a subtractor and a compare.

use crate::hdl::*;

/// Ports per status datagram.
pub const PORTS_PER_STATUS: usize = 32;

/// The first port and port count of the status reporter's page.
#[derive(LogicBlock)]
pub struct StatusPages {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// A report starts: its first page from port 0.
    pub rewind: Signal<In, Bit>,
    /// The page is set up: its port count is taken.
    pub load: Signal<In, Bit>,
    /// The page was sent: the next page starts after its ports.
    pub advance: Signal<In, Bit>,
    /// The page's first port.
    pub first_port: Signal<Out, Bits<7>>,
    /// The page's port count (from its `load` on).
    pub page_ports: Signal<Out, Bits<7>>,
    /// The page holds the last port.
    pub last_page: Signal<Out, Bit>,
    ports: Constant<Bits<7>>,
    ports_per_page: Constant<Bits<7>>,
    first: DFF<Bits<7>>,
    count: DFF<Bits<7>>,
    // ports - first, kept in a register
    remaining: DFF<Bits<7>>,
}

impl StatusPages {
    /// The pages of `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=64).contains(&ports),
            "StatusPages: {ports} ports, must be 1 to 64"
        );
        Self {
            clock: Default::default(),
            rewind: Default::default(),
            load: Default::default(),
            advance: Default::default(),
            first_port: Default::default(),
            page_ports: Default::default(),
            last_page: Default::default(),
            ports: Constant::new((ports as u64).into()),
            ports_per_page: Constant::new((PORTS_PER_STATUS as u64).into()),
            first: Default::default(),
            count: Default::default(),
            remaining: Default::default(),
        }
    }
}

impl Logic for StatusPages {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, first, count, remaining);
        if self.rewind.val() {
            self.first.d.next = 0.into();
            self.remaining.d.next = self.ports.val();
        }
        if self.load.val() {
            self.count.d.next = self.ports_per_page.val();
            if self.remaining.q.val() < self.ports_per_page.val() {
                self.count.d.next = self.remaining.q.val();
            }
        }
        if self.advance.val() {
            self.first.d.next = self.first.q.val() + self.count.q.val();
            self.remaining.d.next = self.remaining.q.val() - self.count.q.val();
        }
        self.first_port.next = self.first.q.val();
        self.page_ports.next = self.count.q.val();
        self.last_page.next = self.first.q.val() + self.count.q.val() == self.ports.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// Reports of 1 to 64 ports, each begun, its pages loaded and sent until the last, with
    /// idle clocks between: the pages are 32 ports each from port 0, the last one the rest.
    #[test]
    fn pages_of_32_ports_cover_every_port_once() {
        for ports in 1..=64usize {
            let mut bench = Bench::new(StatusPages::new(ports), |b| &mut b.clock);
            for _report in 0..3 {
                bench.uut.rewind.next = true;
                bench.cycle();
                bench.uut.rewind.next = false;
                bench.cycles(2);
                let mut pages = vec![];
                loop {
                    bench.uut.load.next = true;
                    bench.cycle();
                    bench.uut.load.next = false;
                    bench.cycles(3);
                    let u = &bench.uut;
                    pages.push((u.first_port.val().index(), u.page_ports.val().index()));
                    let last = u.last_page.val();
                    bench.uut.advance.next = true;
                    bench.cycle();
                    bench.uut.advance.next = false;
                    if last {
                        break;
                    }
                    assert!(pages.len() < 3, "{ports} ports: {pages:?}");
                }
                let expected: Vec<(usize, usize)> = (0..ports)
                    .step_by(PORTS_PER_STATUS)
                    .map(|first| (first, (ports - first).min(PORTS_PER_STATUS)))
                    .collect();
                assert_eq!(pages, expected, "{ports} ports");
            }
        }
    }

    /// A page is loaded in the clock right after `rewind` or `advance` (as the reporter
    /// does): its count is already that of the new first port.
    #[test]
    fn a_page_loaded_right_after_the_move_has_its_own_count() {
        let mut bench = Bench::new(StatusPages::new(45), |b| &mut b.clock);
        for _report in 0..2 {
            bench.uut.rewind.next = true;
            bench.cycle();
            bench.uut.rewind.next = false;
            bench.uut.load.next = true;
            bench.cycle();
            bench.uut.load.next = false;
            assert_eq!(bench.uut.first_port.val().index(), 0);
            assert_eq!(bench.uut.page_ports.val().index(), 32);
            assert!(!bench.uut.last_page.val());
            bench.uut.advance.next = true;
            bench.cycle();
            bench.uut.advance.next = false;
            bench.uut.load.next = true;
            bench.cycle();
            bench.uut.load.next = false;
            assert_eq!(bench.uut.first_port.val().index(), 32);
            assert_eq!(bench.uut.page_ports.val().index(), 13);
            assert!(bench.uut.last_page.val());
            bench.uut.advance.next = true;
            bench.cycle();
            bench.uut.advance.next = false;
            assert_eq!(bench.uut.first_port.val().index(), 45);
        }
    }
}
