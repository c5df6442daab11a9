//! The emulated box: the reference model played in time slices sends exactly the frames of
//! the whole-run prediction (which the RTL tests hold to the RTL), and commands change the
//! stream from their tick on.

use skinbox_cosim::reference::{predict_frames, prepare};
use skinbox_cosim::run::{cycles, lines, TICK_ZERO_CYCLE};
use skinbox_cosim::scene::builtin_spec;
use skinbox_frame_check::{encode, UdpAddresses};
use skinbox_model::emulator::{EmulatedBox, SENDER_MAC};
use skinbox_protocol::command::{AckRepr, AckResult, CommandRepr, Request};
use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
use skinbox_protocol::link::LinkConfig;
use skinbox_protocol::{DatagramRepr, TICKS_PER_SECOND};
use std::net::SocketAddrV4;

const MS: u64 = TICKS_PER_SECOND / 1000;

fn spec() -> skinbox_cosim::run::SimSpec {
    // 40 ms of a busy scene, status every 5 ms
    let mut spec = builtin_spec("moving_arm", 1_000_000_000, 40_000_000, 5 * MS).unwrap();
    spec.config.link = LinkConfig {
        box_ip: [127, 0, 0, 1],
        host_subnet: [127, 0, 0, 0],
        host_subnet_prefix_len: 8,
        ..LinkConfig::DEFAULT
    };
    spec
}

#[test]
fn time_slices_send_the_frames_of_the_whole_run() {
    let spec = spec();
    let (lines, _) = lines(&spec);
    let end = cycles(&spec);
    let whole = predict_frames(&spec.config, &lines, end).unwrap();
    let prepared = prepare(&spec.config, &lines, end).unwrap();
    let mut sliced = prepared.start();
    let link = &spec.config.link;
    let addresses = UdpAddresses {
        source_mac: link.box_mac,
        destination_mac: link.host_mac,
        source_ip: link.box_ip,
        destination_ip: link.host_ip,
        source_port: link.box_port,
        destination_port: link.host_port,
    };
    let mut got = Vec::new();
    // uneven slices, as a real-time loop makes them
    let mut at = TICK_ZERO_CYCLE;
    let mut step = 1u64;
    while at < end {
        at = (at + step).min(end);
        step = (step * 7 + 13) % 400_000 + 1;
        for d in sliced.run_until(at) {
            got.push((d.first_cycle, encode(&addresses, &d.payload()).unwrap()));
        }
    }
    assert!(whole.len() > 100, "{} frames", whole.len());
    // the whole run cuts its last frame at the end; compare the complete ones
    let complete = whole.len() - 1;
    for (i, (w, g)) in whole.iter().zip(&got).take(complete).enumerate() {
        assert_eq!(w.first_cycle, g.0, "frame {i}");
        assert_eq!(w.bytes, g.1, "frame {i}");
    }
    assert!(got.len() >= complete);
}

fn command(sequence: u32, request: Request) -> Vec<u8> {
    CommandRepr {
        box_id: 1,
        sequence,
        host_time: 5,
        request,
    }
    .to_bytes()
}

#[test]
fn commands_change_the_stream_from_their_tick() {
    let spec = spec();
    let (lines, _) = lines(&spec);
    let prepared = prepare(&spec.config, &lines, cycles(&spec)).unwrap();
    let mut emulated = EmulatedBox::new(&prepared, &spec.config);
    let host: SocketAddrV4 = "127.0.0.1:40000".parse().unwrap();

    // nothing goes anywhere before a claim
    assert!(emulated.advance(5 * MS).is_empty());
    assert!(emulated.stats.datagrams_unclaimed > 0);

    let ack = emulated
        .command(
            host,
            &command(1, Request::StreamTo { to: None }),
            5 * MS,
            || 5 * MS + 10,
        )
        .unwrap();
    assert_eq!(ack.to, host);
    let parsed = AckRepr::parse(&ack.payload).unwrap();
    assert_eq!(
        (parsed.result, parsed.receive_tick, parsed.send_tick),
        (AckResult::Ok, 5 * MS, 5 * MS + 10)
    );
    assert_eq!(emulated.control().destination.mac, SENDER_MAC);

    let before = emulated.advance(15 * MS);
    assert!(before.iter().all(|o| o.to == host));
    let datagrams = |out: &[skinbox_model::emulator::Outgoing]| -> Vec<DatagramRepr> {
        out.iter()
            .map(|o| DatagramRepr::parse(&o.payload).unwrap())
            .collect()
    };
    let flushed_spread = |ds: &[DatagramRepr]| {
        ds.iter()
            .filter(|d| d.flags & FLAG_FLUSH_TIMEOUT != 0)
            .filter_map(|d| match &d.body {
                DatagramBody::Records(r) => Some(
                    r.iter().map(|r| r.tick_offset).max()?
                        - r.iter().map(|r| r.tick_offset).min()?,
                ),
                DatagramBody::Status(_) => None,
            })
            .max()
            .unwrap_or(0)
    };
    let spread_before = flushed_spread(&datagrams(&before));

    // a 10 us flush timeout from 15 ms on
    let ack = emulated
        .command(
            host,
            &command(2, Request::SetFlushTimeout { ticks: 1250 }),
            15 * MS,
            || 15 * MS,
        )
        .unwrap();
    assert_eq!(AckRepr::parse(&ack.payload).unwrap().result, AckResult::Ok);
    // datagrams opened before the command may still close on the old timeout
    let after = datagrams(&emulated.advance(30 * MS));
    let late: Vec<DatagramRepr> = after
        .into_iter()
        .filter(|d| d.base_tick > 15 * MS + 100 * MS / 1000)
        .collect();
    let spread_after = flushed_spread(&late);
    assert!(
        spread_before > 2500 && spread_after < 2500,
        "spread of flushed datagrams: {spread_before} ticks before, {spread_after} after"
    );

    // status now: a status report with the box counters right after the command
    let ack = emulated
        .command(host, &command(3, Request::StatusNow), 30 * MS + 1, || {
            30 * MS + 1
        })
        .unwrap();
    assert_eq!(AckRepr::parse(&ack.payload).unwrap().result, AckResult::Ok);
    let out = emulated.advance(30 * MS + MS / 10);
    let status: Vec<_> = out
        .iter()
        .filter_map(|o| DatagramRepr::parse_box_counters(&o.payload).ok())
        .filter(|(d, _)| matches!(d.body, DatagramBody::Status(_)))
        .collect();
    assert_eq!(status.len(), 1, "one status datagram within 100 us");
    let counters = status[0].1.expect("the box counter block");
    assert_eq!(
        counters.get(skinbox_protocol::BoxCounter::CommandsAccepted),
        3
    );
    assert!(status[0].0.base_tick > 30 * MS && status[0].0.base_tick < 30 * MS + MS / 10);

    // a 1 ms status period from 31 ms on: the timer restarts, reports every ms from 32 ms
    // (it was 5 ms)
    assert!(emulated
        .advance(31 * MS)
        .iter()
        .all(|o| DatagramRepr::parse(&o.payload)
            .is_ok_and(|d| matches!(d.body, DatagramBody::Records(_)))));
    let ack = emulated
        .command(
            host,
            &command(4, Request::SetStatusPeriod { ticks: MS as u32 }),
            31 * MS,
            || 31 * MS,
        )
        .unwrap();
    assert_eq!(AckRepr::parse(&ack.payload).unwrap().result, AckResult::Ok);
    let report_ticks: Vec<u64> = emulated
        .advance(40 * MS)
        .iter()
        .map(|o| DatagramRepr::parse(&o.payload).unwrap())
        .filter(|d| matches!(d.body, DatagramBody::Status(_)))
        .map(|d| d.base_tick)
        .collect();
    assert_eq!(report_ticks.len(), 8, "{report_ticks:?}");
    for (k, tick) in report_ticks.iter().enumerate() {
        let period_start = (32 + k as u64) * MS;
        assert!(
            (period_start..period_start + MS / 10).contains(tick),
            "{report_ticks:?}"
        );
    }
}

/// A port whose cells send otherwise from some cycle on (the emulator's cells obeying a
/// command): given its new transitions mid-run, the sliced reference sends from then on
/// what a run on the new transitions from the start sends; new transitions that differ
/// before the cycle reached are refused.
#[test]
fn a_port_given_new_transitions_mid_run_sends_what_a_run_on_them_sends() {
    use skinbox_cosim::run::line;
    let spec = spec();
    let (old, _) = lines(&spec);
    let end = cycles(&spec);
    let cut = TICK_ZERO_CYCLE + 15 * MS;
    let cut_ns = (cut * 8) as f64;
    // port 1: its own packets before the cut, port 2's from 20 us after it on
    let before = spec.ports[1].iter().filter(|p| p.start_ns < cut_ns);
    let after = spec.ports[2]
        .iter()
        .filter(|p| p.start_ns > cut_ns + 20_000.0);
    let packets: Vec<_> = before.chain(after).cloned().collect();
    let mut new = old.clone();
    new[1] = line(&packets, &spec.jitter, 1).0;
    assert_eq!(
        old[1].iter().filter(|t| t.edge < cut).count(),
        new[1].iter().filter(|t| t.edge < cut).count()
    );
    assert_ne!(old[1], new[1]);
    let run = |prepared: &skinbox_model::reference::PreparedReference, swap_at: Option<u64>| {
        let mut sliced = prepared.start();
        let mut sent = vec![];
        if let Some(at) = swap_at {
            sent.extend(sliced.run_until(at));
            sliced.replace_port(1, &new[1]).unwrap();
        }
        sent.extend(sliced.run_until(end));
        sent.iter()
            .map(|d| (d.first_cycle, d.payload()))
            .collect::<Vec<_>>()
    };
    let swapped = run(&prepare(&spec.config, &old, end).unwrap(), Some(cut));
    let fresh = run(&prepare(&spec.config, &new, end).unwrap(), None);
    let unchanged = run(&prepare(&spec.config, &old, end).unwrap(), None);
    assert!(fresh.len() > 100, "{}", fresh.len());
    assert_eq!(swapped, fresh);
    assert_ne!(swapped, unchanged);
    // a pin that changed before the cycle reached is refused
    let prepared = prepare(&spec.config, &old, end).unwrap();
    let mut sliced = prepared.start();
    sliced.run_until(cut + 5 * MS);
    assert!(sliced.replace_port(1, &new[1]).is_err());
}
