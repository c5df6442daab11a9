//! BoxConfiguration: the box's run-time configuration, as the accepted commands set it
//! (docs/control.md): the datagrams' destination, the flush timeout and the status period,
//! each back to its build-time value at reset.
//!
//! The command unit raises one `apply_*` for one clock, the clock before its `done`; the
//! new value is in the register from the next clock on (the `done` clock), and
//! `status_period_set` / `status_now` are high in that clock only. A stream-to without
//! arguments makes the command's sender the destination.

use crate::hdl::*;
use skinbox_protocol::link::LinkConfig;

/// The run-time configuration.
#[derive(LogicBlock)]
pub struct BoxConfiguration {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the build-time values.
    pub reset: Signal<In, Bit>,
    /// One clock: an accepted stream-to.
    pub apply_stream_to: Signal<In, Bit>,
    /// With `apply_stream_to`: it has no arguments (the sender becomes the destination).
    pub to_sender: Signal<In, Bit>,
    /// The sender's MAC, IPv4 address and UDP port.
    pub peer_mac: Signal<In, Bits<48>>,
    /// See `peer_mac`.
    pub peer_ip: Signal<In, Bits<32>>,
    /// See `peer_mac`.
    pub peer_port: Signal<In, Bits<16>>,
    /// The stream-to's destination argument: MAC, IPv4 address, UDP port.
    pub argument_mac: Signal<In, Bits<48>>,
    /// See `argument_mac`.
    pub argument_ip: Signal<In, Bits<32>>,
    /// See `argument_mac`.
    pub argument_port: Signal<In, Bits<16>>,
    /// One clock: an accepted set-flush-timeout, to `value`.
    pub apply_flush_timeout: Signal<In, Bit>,
    /// One clock: an accepted set-status-period, to `value`.
    pub apply_status_period: Signal<In, Bit>,
    /// One clock: an accepted status-now.
    pub apply_status_now: Signal<In, Bit>,
    /// One clock: an accepted set-sync-period, to `value`.
    pub apply_sync_period: Signal<In, Bit>,
    /// The ticks of a set-flush-timeout, set-status-period or set-sync-period.
    pub value: Signal<In, Bits<32>>,
    /// Datagrams' destination MAC.
    pub destination_mac: Signal<Out, Bits<48>>,
    /// Datagrams' destination IPv4 address.
    pub destination_ip: Signal<Out, Bits<32>>,
    /// Datagrams' destination UDP port.
    pub destination_port: Signal<Out, Bits<16>>,
    /// Flush timeout, ticks.
    pub flush_timeout_ticks: Signal<Out, Bits<32>>,
    /// Status period, ticks.
    pub status_period_ticks: Signal<Out, Bits<32>>,
    /// One clock: the status period was set.
    pub status_period_set: Signal<Out, Bit>,
    /// One clock: a status-now was carried out.
    pub status_now: Signal<Out, Bit>,
    /// The box's time-sync period, ticks (0: no syncs).
    pub sync_period_ticks: Signal<Out, Bits<32>>,
    /// One clock: the sync period was set (its first clock).
    pub sync_period_set: Signal<Out, Bit>,
    default_mac: Constant<Bits<48>>,
    default_ip: Constant<Bits<32>>,
    default_port: Constant<Bits<16>>,
    default_flush_timeout: Constant<Bits<32>>,
    default_status_period: Constant<Bits<32>>,
    default_sync_period: Constant<Bits<32>>,
    mac: DFF<Bits<48>>,
    ip: DFF<Bits<32>>,
    port: DFF<Bits<16>>,
    flush_timeout: DFF<Bits<32>>,
    status_period: DFF<Bits<32>>,
    period_set: DFF<Bit>,
    now: DFF<Bit>,
    sync_period: DFF<Bits<32>>,
    sync_set: DFF<Bit>,
}

impl BoxConfiguration {
    /// The configuration whose reset values are `link`'s host (the destination) and these
    /// ticks.
    pub fn new(
        link: &LinkConfig,
        flush_timeout_ticks: u32,
        status_period_ticks: u32,
        sync_period_ticks: u32,
    ) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            apply_stream_to: Default::default(),
            to_sender: Default::default(),
            peer_mac: Default::default(),
            peer_ip: Default::default(),
            peer_port: Default::default(),
            argument_mac: Default::default(),
            argument_ip: Default::default(),
            argument_port: Default::default(),
            apply_flush_timeout: Default::default(),
            apply_status_period: Default::default(),
            apply_status_now: Default::default(),
            apply_sync_period: Default::default(),
            value: Default::default(),
            destination_mac: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            flush_timeout_ticks: Default::default(),
            status_period_ticks: Default::default(),
            status_period_set: Default::default(),
            status_now: Default::default(),
            sync_period_ticks: Default::default(),
            sync_period_set: Default::default(),
            default_mac: constant(big_endian(&link.host_mac)),
            default_ip: constant(u32::from_be_bytes(link.host_ip).into()),
            default_port: constant(link.host_port.into()),
            default_flush_timeout: constant(flush_timeout_ticks.into()),
            default_status_period: constant(status_period_ticks.into()),
            default_sync_period: constant(sync_period_ticks.into()),
            mac: Default::default(),
            ip: Default::default(),
            port: Default::default(),
            flush_timeout: Default::default(),
            status_period: Default::default(),
            period_set: Default::default(),
            now: Default::default(),
            sync_period: Default::default(),
            sync_set: Default::default(),
        }
    }
}

impl Logic for BoxConfiguration {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            mac,
            ip,
            port,
            flush_timeout,
            status_period,
            period_set,
            now,
            sync_period,
            sync_set
        );
        if self.apply_stream_to.val() {
            if self.to_sender.val() {
                self.mac.d.next = self.peer_mac.val();
                self.ip.d.next = self.peer_ip.val();
                self.port.d.next = self.peer_port.val();
            } else {
                self.mac.d.next = self.argument_mac.val();
                self.ip.d.next = self.argument_ip.val();
                self.port.d.next = self.argument_port.val();
            }
        }
        if self.apply_flush_timeout.val() {
            self.flush_timeout.d.next = self.value.val();
        }
        if self.apply_status_period.val() {
            self.status_period.d.next = self.value.val();
        }
        self.period_set.d.next = self.apply_status_period.val();
        self.now.d.next = self.apply_status_now.val();
        if self.apply_sync_period.val() {
            self.sync_period.d.next = self.value.val();
        }
        self.sync_set.d.next = self.apply_sync_period.val();
        if self.reset.val() {
            self.mac.d.next = self.default_mac.val();
            self.ip.d.next = self.default_ip.val();
            self.port.d.next = self.default_port.val();
            self.flush_timeout.d.next = self.default_flush_timeout.val();
            self.status_period.d.next = self.default_status_period.val();
            self.period_set.d.next = false;
            self.now.d.next = false;
            self.sync_period.d.next = self.default_sync_period.val();
            self.sync_set.d.next = false;
        }
        self.destination_mac.next = self.mac.q.val();
        self.destination_ip.next = self.ip.q.val();
        self.destination_port.next = self.port.q.val();
        self.flush_timeout_ticks.next = self.flush_timeout.q.val();
        self.status_period_ticks.next = self.status_period.q.val();
        self.status_period_set.next = self.period_set.q.val();
        self.status_now.next = self.now.q.val();
        self.sync_period_ticks.next = self.sync_period.q.val();
        self.sync_period_set.next = self.sync_set.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// (destination MAC, IP, port, flush timeout, status period, sync period)
    type Values = (u64, u32, u16, u32, u32, u32);

    fn seen(u: &BoxConfiguration) -> Values {
        (
            u.destination_mac.val().to_u64(),
            u.destination_ip.val().to_u32(),
            u.destination_port.val().to_u64() as u16,
            u.flush_timeout_ticks.val().to_u32(),
            u.status_period_ticks.val().to_u32(),
            u.sync_period_ticks.val().to_u32(),
        )
    }

    #[test]
    fn applied_commands_set_the_values_and_reset_restores_the_build_time_ones() {
        let link = LinkConfig::DEFAULT;
        let defaults: Values = (
            big_endian(&link.host_mac),
            u32::from_be_bytes(link.host_ip),
            link.host_port,
            12_500,
            125_000_000,
            12_500_000,
        );
        let mut bench = Bench::new(
            BoxConfiguration::new(&link, 12_500, 125_000_000, 12_500_000),
            |b| &mut b.clock,
        );
        let mut rng = TestRng::new(0xC0F);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut want = defaults;
        assert_eq!(seen(&bench.uut), want);
        for step in 0..2000 {
            let u = &mut bench.uut;
            let r = rng.next_u64();
            let (peer, argument) = (rng.next_u64(), rng.next_u64());
            let value = rng.next_u64() as u32;
            u.peer_mac.next = (peer >> 16).into();
            u.peer_ip.next = (peer & 0xFFFF_FFFF).into();
            u.peer_port.next = (peer >> 48).into();
            u.argument_mac.next = (argument >> 16).into();
            u.argument_ip.next = (argument & 0xFFFF_FFFF).into();
            u.argument_port.next = (argument >> 48).into();
            u.value.next = u64::from(value).into();
            // at most one command per clock, as the command unit applies them
            let which = r % 7;
            u.apply_stream_to.next = which == 0;
            u.to_sender.next = (r >> 8) & 1 == 1;
            u.apply_flush_timeout.next = which == 1;
            u.apply_status_period.next = which == 2;
            u.apply_status_now.next = which == 3;
            u.apply_sync_period.next = which == 5;
            let reset = which == 4 && (r >> 16).is_multiple_of(10);
            u.reset.next = reset;
            bench.cycle();
            match which {
                0 if (r >> 8) & 1 == 1 => {
                    want = (
                        peer >> 16,
                        peer as u32,
                        (peer >> 48) as u16,
                        want.3,
                        want.4,
                        want.5,
                    )
                }
                0 => {
                    want = (
                        argument >> 16,
                        argument as u32,
                        (argument >> 48) as u16,
                        want.3,
                        want.4,
                        want.5,
                    )
                }
                1 => want.3 = value,
                2 => want.4 = value,
                5 => want.5 = value,
                _ => {}
            }
            if reset {
                want = defaults;
            }
            let u = &bench.uut;
            assert_eq!(seen(u), want, "step {step}");
            assert_eq!(
                u.status_period_set.val(),
                which == 2 && !reset,
                "step {step}"
            );
            assert_eq!(u.status_now.val(), which == 3 && !reset, "step {step}");
            assert_eq!(u.sync_period_set.val(), which == 5 && !reset, "step {step}");
        }
    }
}
