"""`read` against `skinbox decode --jsonl` and `skinbox stats --json`: every field of every
record, and the report, on synthetic captures of the box's reference model."""

from __future__ import annotations

import ipaddress
import math
import struct

import numpy as np
import pytest

import skinbox
from conftest import decode_jsonl, stats_json

SOURCES = {
    "none": skinbox.HOST_TIME_NONE,
    "receive_stamps": skinbox.HOST_TIME_RECEIVE_STAMPS,
    "exchanges": skinbox.HOST_TIME_EXCHANGES,
}


def assert_row_equals(row: np.void, want: dict) -> None:
    assert row["tick"] == want["tick"]
    assert row["tick"] / 125e6 == want["time_s"]
    assert row["box_time_ns"] == want["tick"] * 8
    for field in ("box_id", "datagram_sequence", "port", "flags", "cell_id"):
        assert row[field] == want[field], field
    assert row["event_packets_missing_before"] == want["event_packets_missing_before"]
    # the box's source address, "IP:port" in the JSON lines
    if want["source"] is None:
        assert (row["source_ip"], row["source_port"]) == (0, 0)
    else:
        ip, port = want["source"].rsplit(":", 1)
        assert str(ipaddress.IPv4Address(int(row["source_ip"]))) == ip
        assert row["source_port"] == int(port)
    assert row["kind"] == {"data": skinbox.KIND_DATA, "event": skinbox.KIND_EVENT}[want["kind"]]
    assert row["event_sequence"] == (
        -1 if want["event_sequence"] is None else want["event_sequence"]
    )
    assert bool(row["second_part"]) == want["second_part"]
    mask = 0
    for i, name in enumerate(skinbox.CHANNELS):
        if name in want["values"]:
            mask |= 1 << i
            assert row["values"][i] == want["values"][name], name
        else:
            assert math.isnan(row["values"][i]), name
    assert row["mask"] == mask
    assert row["sample_box_time_ns"] * 1e-9 == want["sample_box_time_s"]
    assert row["sample_index"] == want["sample_index"]
    assert row["host_time_source"] == SOURCES[want["host_time_source"]]
    if want["sample_host_time_ns"] is None:
        assert row["host_time_ns"] == 0
    else:
        assert row["host_time_ns"] == int(want["sample_host_time_ns"])
    if want["host_time_bound_ns"] is None:
        assert math.isnan(row["host_time_bound_ns"])
    else:
        assert row["host_time_bound_ns"] == want["host_time_bound_ns"]


@pytest.mark.parametrize(
    "name", ["data", "event", "mixed", "two_boxes", "shared_id", "gaps", "pcapng"]
)
def test_every_field_equals_decode_jsonl(name, captures, skinbox_bin):
    path, truth = captures[name]
    records, report = skinbox.read(path)
    want = decode_jsonl(skinbox_bin, path)
    assert records.dtype == skinbox.RECORD_DTYPE
    assert len(records) == len(want) == len(truth["tick"]) > 0
    for row, w in zip(records, want):
        assert_row_equals(row, w)
    # the records are the generator's, in order
    assert np.array_equal(records["tick"], truth["tick"])
    assert np.array_equal(records["cell_id"], truth["cell_id"])
    assert np.array_equal(records["box_id"], truth["box_id"])
    assert np.array_equal(records["source_ip"], truth["source_ip"])
    assert np.array_equal(records["source_port"], truth["source_port"])
    assert np.array_equal(records["mask"], truth["mask"])
    assert (records["source_port"] != 0).all(), "every datagram of a pcap has its source"


@pytest.mark.parametrize("name", ["mixed", "two_boxes", "gaps", "pcapng"])
def test_report_equals_stats(name, captures, skinbox_bin):
    path, _ = captures[name]
    _, report = skinbox.read(path)
    want = stats_json(skinbox_bin, path)
    assert report["host_times"], "receive stamps map box time to host time"
    for key in want:
        if key == "host":  # CPU time of the run
            continue
        assert report[key] == want[key], key


def test_kinds_of_the_captures(captures):
    data, _ = skinbox.read(captures["data"][0])
    assert np.all(data["kind"] == skinbox.KIND_DATA)
    assert np.all(data["event_sequence"] == -1)
    event, _ = skinbox.read(captures["event"][0])
    assert np.all(event["kind"] == skinbox.KIND_EVENT)
    assert event["second_part"].any(), "split samples in the event capture"
    boxes, report = skinbox.read(captures["two_boxes"][0])
    assert set(boxes["box_id"]) == {1, 2}
    assert [b["box_id"] for b in report["boxes"]] == [1, 2]


def datagram_sequences(path):
    """The sequence number of every datagram of a pcap of Ethernet/IPv4/UDP frames (bytes
    8-11 of the box datagram, big-endian)."""
    data = path.read_bytes()
    offset = 24
    while offset + 16 <= len(data):
        caplen = struct.unpack_from("<I", data, offset + 8)[0]
        frame = data[offset + 16 : offset + 16 + caplen]
        offset += 16 + caplen
        yield struct.unpack_from(">I", frame, 14 + 20 + 8 + 8)[0]


def test_gaps_are_losses(captures, tmp_path):
    path, truth = captures["gaps"]
    records, report = skinbox.read(path)
    # the same capture with every records datagram: every 4th was left out
    whole = skinbox.write_synthetic_capture(
        tmp_path / "whole.pcap", cells=48, samples_per_cell=40, seed=7, event_every=2
    )
    kept = np.unique(truth["datagram_sequence"])
    left_out = np.setdiff1d(np.unique(whole["datagram_sequence"]), kept)
    assert len(left_out) > 0
    # a datagram left out after the last one that arrived cannot be seen missing
    last = max(datagram_sequences(path))
    assert report["losses"]["datagrams_missing"] == np.count_nonzero(left_out < last)
    assert report["losses"]["event_packets_missing"] > 0
    assert (records["event_packets_missing_before"] > 0).any()


def test_options_are_checked(captures):
    with pytest.raises(ValueError, match="sample_rate_hz"):
        skinbox.read(captures["data"][0], sample_rate_hz=-1.0)
    with pytest.raises(ValueError, match="cells_per_bus"):
        skinbox.read(captures["data"][0], cells_per_bus=0)


def test_rate_given_is_one_pass_and_equals_decode_with_that_rate(captures, skinbox_bin):
    path, _ = captures["mixed"]
    records, _ = skinbox.read(path, sample_rate_hz=125.0)
    want = decode_jsonl(skinbox_bin, path, "--sample-rate-hz", "125")
    assert len(records) == len(want)
    for row, w in zip(records, want):
        assert_row_equals(row, w)


def test_without_times_the_records_are_the_same(captures):
    path, _ = captures["two_boxes"]
    timed, _ = skinbox.read(path)
    untimed, report = skinbox.read(path, times=False)
    assert report["host_times"] == []
    assert np.isnan(untimed["sample_box_time_ns"]).all()
    assert (untimed["sample_index"] == -1).all()
    assert (untimed["host_time_source"] == skinbox.HOST_TIME_NONE).all()
    for field in ("tick", "box_id", "cell_id", "kind", "mask", "event_sequence", "port"):
        assert np.array_equal(timed[field], untimed[field]), field
    assert np.array_equal(timed["values"], untimed["values"], equal_nan=True)


@pytest.mark.parametrize("options", [{}, {"sample_rate_hz": 125.0}])
def test_timed_parts_give_the_same_rows_wherever_they_end(options, tmp_path):
    """`read` and `Reader` fill in the times in a second thread, handed the rows in parts
    of 4,096 (the reader's within its batches of 10,000): two boxes with losses, the parts'
    ends at other rows in each, every field the same, bit for bit. (The other tests hold
    both to `skinbox decode`, whose times come from one thread.)"""
    path = tmp_path / "parts.pcap"
    skinbox.write_synthetic_capture(
        path, cells=48, samples_per_cell=300, event_every=2, boxes=2, drop_every=5, seed=3
    )
    records, report = skinbox.read(path, **options)
    assert len(records) > 4 * 4096 and report["losses"]["datagrams_missing"] > 0
    batches = np.concatenate([b.copy() for b in skinbox.Reader(path, rows=10_000, **options)])
    assert len(batches) == len(records)
    for field in records.dtype.names:
        assert np.array_equal(
            records[field], batches[field], equal_nan=records[field].dtype.kind == "f"
        ), field
    assert (records["host_time_source"] != skinbox.HOST_TIME_NONE).all()
    assert report["host"]["timing_cpu_s"] > 0, "the timing thread's CPU time"
