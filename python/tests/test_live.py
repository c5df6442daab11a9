"""`Capture`, `Box` and `emulate` on loopback: the emulated box (`skinbox emulate` in a
thread) streams a scene to a claimed capture and answers commands."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

import skinbox


@pytest.fixture(scope="module")
def box():
    # 200 ms of the arm being stroked, played at real time, then status reports only
    with skinbox.emulate(
        "stroking_upper_arm", duration_ms=200.0, status_period_ms=20.0
    ) as emulated:
        yield emulated


@pytest.mark.parametrize("times", [True, False])
def test_a_claimed_capture_gets_every_record_the_box_sent(times):
    with skinbox.emulate("stroking_upper_arm", duration_ms=300.0) as emulated:
        capture = skinbox.Capture(
            listen="127.0.0.1:0",
            claim=emulated.address,
            batch_ms=20,
            exchange_ms=50,
            # the scene's 65 cells a bus: each cell's path latency, so each time's bound
            cells_per_bus=65,
            times=times,
        )
        batches = []
        consumer = threading.Thread(target=lambda: batches.extend(capture))
        consumer.start()
        # the cells send for 300 ms of scene time; then the box sends status reports only
        deadline = time.monotonic() + 60
        sent, last = -1, 0
        while sent != last or sent == 0:
            assert time.monotonic() < deadline, sent
            last = sent
            time.sleep(0.3)
            sent = emulated.stats()["records_sent"]
        summary = emulated.stop()
    # every record the box sent arrives
    deadline = time.monotonic() + 20
    while sum(len(b) for b in batches) < summary["records_sent"]:
        assert time.monotonic() < deadline, (sum(len(b) for b in batches), summary)
        time.sleep(0.05)
    capture.close()
    consumer.join()
    rest = list(capture)
    assert all(b.dtype == skinbox.RECORD_DTYPE for b in batches + rest)
    records = np.concatenate(batches + rest)
    assert len(records) == summary["records_sent"] > 0
    report = capture.report
    assert report["running"] is False
    assert report["claim"]["result"] == "ok"
    assert report["report"]["records"] == len(records)
    assert report["report"]["losses"]["datagrams_missing"] == 0
    assert report["report"]["bad_input"]["total"] == 0
    if not times:
        assert (records["host_time_source"] == skinbox.HOST_TIME_NONE).all()
        assert np.isnan(records["sample_box_time_ns"]).all()
        return
    # the read-tick exchanges map box time to host time, with a bound
    assert report["host_times"][0]["source"] == "exchanges"
    mapped = records["host_time_source"] == skinbox.HOST_TIME_EXCHANGES
    assert mapped.any()
    assert np.isfinite(records["host_time_bound_ns"][mapped]).all()
    now_ns = time.time_ns()
    assert np.all(np.abs(records["host_time_ns"][mapped] - now_ns) < 60e9)


def test_close_stops_a_capture_that_waits():
    capture = skinbox.Capture(listen="127.0.0.1:0")
    threading.Timer(0.3, capture.close).start()
    started = time.monotonic()
    assert list(capture) == []
    assert time.monotonic() - started < 5
    assert capture.report["running"] is False


def test_ctrl_c_stops_the_capture():
    # Python's Ctrl-C handler, which a process started with SIGINT ignored (a background
    # job of a shell without job control) does not get
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        capture = skinbox.Capture(listen="127.0.0.1:0")
        threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()
        with pytest.raises(KeyboardInterrupt):
            for _ in capture:
                pass
    finally:
        signal.signal(signal.SIGINT, previous)
    # the capture stopped with its report
    assert capture.report["running"] is False


def test_a_capture_that_cannot_claim_raises():
    with pytest.raises(skinbox.CaptureError, match="no acknowledgement"):
        skinbox.Capture(listen="127.0.0.1:0", claim="127.0.0.1:9")


def test_box_commands_are_acknowledged(box):
    client = skinbox.Box(box.address)
    status = client.status()
    assert status["result"] == "ok" and status["command"] == "status_now"
    assert "box_counters" in status
    tick = client.time()
    assert tick["result"] == "ok" and tick["box_send_tick"] >= tick["box_receive_tick"]
    assert client.set("flush-timeout-us", 200)["result"] == "ok"
    assert client.set("status-period-ms", 50)["result"] == "ok"
    pings = client.ping(3)
    assert [p["result"] for p in pings] == ["ok"] * 3
    streaming = client.stream_to()
    assert streaming["streaming_to"]["port"] == int(client.local_address.split(":")[1])
    assert client.cells_mode("event")["result"] == "ok"
    time.sleep(0.01)  # the downlink queues two packets per port: let it drain
    assert client.cells_rate(250.0, port=0)["result"] == "ok"


def test_bad_commands_raise_before_sending(box):
    client = skinbox.Box(box.address)
    with pytest.raises(ValueError, match="flush-timeout-us, status-period-ms and sync-period-ms"):
        client.set("speed", 1)
    with pytest.raises(ValueError, match="62.5, 125, 250, 500 or 1000"):
        client.cells_rate(300)
    with pytest.raises(ValueError, match="unknown channel"):
        client.cells_enable(["elbow"])


def test_a_refused_command_raises_with_its_reason(box):
    # the emulated box is box 1: a command to box 7 is refused
    other = skinbox.Box(box.address, box_id=7)
    with pytest.raises(skinbox.BoxRefusedError, match="other_box"):
        other.status()


def test_no_box_raises_after_the_retries():
    client = skinbox.Box("127.0.0.1:9", timeout_ms=20, retries=1)
    with pytest.raises(skinbox.BoxError, match="no acknowledgement .* after 2 attempts"):
        client.status()


def test_an_unknown_scene_raises():
    with pytest.raises(skinbox.EmulatorError, match="no scene file"):
        skinbox.emulate("no_such_scene")


@pytest.mark.parametrize("times", [True, False])
def test_live_rows_equal_read_of_the_recorded_datagrams(times, tmp_path):
    """A capture's rows, times filled in by its timing thread, are `read`'s rows of the pcap
    it recorded (the same datagrams with the same receive stamps), every field."""
    from test_chunks import assert_same_records

    source = tmp_path / "sent.pcap"
    truth = skinbox.write_synthetic_capture(
        source, cells=48, samples_per_cell=40, seed=7, event_every=2, boxes=2
    )
    recorded = tmp_path / "recorded.pcap"
    capture = skinbox.Capture(
        listen="127.0.0.1:0",
        batch_records=500,
        batch_ms=20,
        sample_rate_hz=125.0,
        pcap=recorded,
        times=times,
    )
    batches = []
    consumer = threading.Thread(target=lambda: batches.extend(capture))
    consumer.start()
    skinbox._native.replay_capture(source, capture.address, 20_000.0)
    deadline = time.monotonic() + 20
    while sum(len(b) for b in batches) < len(truth["tick"]):
        assert time.monotonic() < deadline, sum(len(b) for b in batches)
        time.sleep(0.05)
    capture.close()
    consumer.join()
    batches += list(capture)
    live = np.empty(sum(len(b) for b in batches), dtype=skinbox.RECORD_DTYPE)
    at = 0
    for b in batches:
        live[at : at + len(b)] = b
        at += len(b)
    assert np.array_equal(live["tick"], truth["tick"])
    want, _ = skinbox.read(recorded, sample_rate_hz=125.0, times=times)
    # the live rows' source ports are the sender's (127.0.0.1:ephemeral), as recorded
    assert_same_records(live, want)
    if times:
        assert (live["host_time_source"] == skinbox.HOST_TIME_RECEIVE_STAMPS).all()
        assert np.isfinite(live["sample_box_time_ns"]).all()
        assert capture.report["host_times"], "the summary of the host times"
