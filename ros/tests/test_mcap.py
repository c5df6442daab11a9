"""`skinbox decode --mcap`: the recordings read by three independent readers (the `mcap`
library with `mcap-ros2-support`'s decoder of the schemas the file carries, and `rosbags`
with its own CDR decoder fed the `.msg` files); every sample equals `skinbox decode
--jsonl` of the same capture, and the layout is rosbag2's."""

from __future__ import annotations

import json
import math
import subprocess

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from ruamel.yaml import YAML

from conftest import decode_jsonl, run

CHANNELS = ["accel_x", "accel_y", "accel_z", "force_1", "force_2", "force_3",
            "proximity", "temperature_1", "temperature_2"]
SOURCES = {"none": 0, "receive_stamps": 1, "exchanges": 2}
TOPICS = {
    "/skinbox/samples": "skinbox_msgs/msg/CellSampleBatch",
    "/skinbox/status": "skinbox_msgs/msg/BoxStatus",
    "/skinbox/activity": "skinbox_msgs/msg/SkinActivity",
}


def check_sample(s, row) -> None:
    """One CellSample against one `decode --jsonl` row."""
    where = f"row {row}"
    assert s.box_id == row["box_id"], where
    assert s.port == row["port"], where
    assert s.cell_id == row["cell_id"], where
    assert s.kind == (0 if row["kind"] == "data" else 1), where
    assert s.event_sequence == (-1 if row["event_sequence"] is None else row["event_sequence"]), where
    assert bool(s.second_part) == row["second_part"], where
    assert s.flags == row["flags"], where
    assert s.datagram_sequence == row["datagram_sequence"], where
    assert s.event_packets_missing_before == row["event_packets_missing_before"], where
    assert s.box_time_ns == row["tick"] * 8, where
    mask = 0
    for i, name in enumerate(CHANNELS):
        value = s.values[i]
        if name in row["values"]:
            mask |= 1 << i
            assert value == row["values"][name], f"{name}: {where}"
        else:
            assert math.isnan(value), f"{name}: {where}"
    assert s.event_mask == mask, where
    assert s.sample_box_time_ns == pytest.approx(row["sample_box_time_s"] * 1e9, abs=1.0), where
    host = row["sample_host_time_ns"]
    assert s.host_time_ns == (0 if host is None else int(host)), where
    bound = row["host_time_bound_ns"]
    if bound is None:
        assert math.isnan(s.host_time_bound_ns), where
    else:
        assert s.host_time_bound_ns == bound, where
    assert s.host_time_source == SOURCES[row["host_time_source"]], where


@pytest.mark.parametrize("name", ["data", "event", "two_boxes", "gaps"])
def test_every_sample_equals_decode_jsonl_in_both_readers(skinbox_bin, captures, typestore, tmp_path, name):
    pcap = captures[name]
    rows = decode_jsonl(skinbox_bin, pcap)
    assert len(rows) > 300
    bag = tmp_path / "bag"
    run(skinbox_bin, "decode", str(pcap), "--mcap", str(bag))
    mcap_file = bag / "bag_0.mcap"

    # the mcap library, messages decoded from the schema text the file carries
    samples = []
    stamps = []
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert schema.name == TOPICS[channel.topic]
            stamp = decoded.stamp.sec * 1_000_000_000 + decoded.stamp.nanosec
            assert message.log_time == stamp == message.publish_time
            if channel.topic == "/skinbox/samples":
                assert decoded.samples, "no empty batches"
                assert {s.datagram_sequence for s in decoded.samples} == {decoded.datagram_sequence}
                assert {s.box_id for s in decoded.samples} == {decoded.box_id}
                samples.extend(decoded.samples)
                stamps.append(stamp)
    assert len(samples) == len(rows)
    for s, row in zip(samples, rows):
        check_sample(s, row)
    # log times are the host's receive times: the capture's clock, in arrival order
    assert stamps == sorted(stamps) and stamps[0] > 0

    # rosbags: the bag directory, its own CDR decoder fed the .msg files
    again = []
    with Reader(bag) as rd:
        assert {c.topic: c.msgtype for c in rd.connections} == TOPICS
        for connection, timestamp, raw in rd.messages():
            m = typestore.deserialize_cdr(raw, connection.msgtype)
            assert timestamp == m.stamp.sec * 1_000_000_000 + m.stamp.nanosec
            if connection.topic == "/skinbox/samples":
                again.extend(m.samples)
    assert len(again) == len(rows)
    for s, row in zip(again, rows):
        check_sample(s, row)

    boxes = {r["box_id"] for r in rows}
    assert boxes == ({1, 2} if name == "two_boxes" else {1})


def test_losses_and_status_reach_the_status_topic(skinbox_bin, captures, typestore, tmp_path):
    stats = json.loads(run(skinbox_bin, "stats", str(captures["gaps"]), "--json"))
    missing = sum(b["losses"]["datagrams_missing"] for b in stats["report"]["boxes"]) \
        if "report" in stats else stats["losses"]["datagrams_missing"]
    assert missing > 0
    bag = tmp_path / "gaps.mcap"
    run(skinbox_bin, "decode", str(captures["gaps"]), "--mcap", str(bag))
    last = None
    activity_missing = 0
    with open(bag, "rb") as f:
        for _, channel, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            if channel.topic == "/skinbox/status":
                last = m
                assert len(m.ports) == 4
                assert [p.port for p in m.ports] == [0, 1, 2, 3]
            if channel.topic == "/skinbox/activity":
                activity_missing += m.datagrams_missing
                assert m.channel_name == "force_1" and m.channel == 3
    assert last is not None
    # the status topic's host-side losses reach the decoder's count (datagrams missing
    # after the last status datagram are not in it)
    assert 0 < last.datagrams_missing <= missing
    assert last.records_received > 0


def test_the_layout_is_rosbag2s(skinbox_bin, captures, tmp_path):
    bag = tmp_path / "layout"
    out = run(skinbox_bin, "--json", "decode", str(captures["event"]), "--mcap", str(bag))
    published = json.loads(out)["published"]
    with open(bag / "layout_0.mcap", "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        assert header.profile == "ros2"
        assert header.library.startswith("skinbox")
        summary = reader.get_summary()
        assert summary.statistics.message_count == (
            published["samples_messages"] + published["status_messages"] + published["activity_messages"])
        assert summary.chunk_indexes, "chunked, with chunk indexes"
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            qos = YAML(typ="safe").load(channel.metadata["offered_qos_profiles"])
            assert qos[0]["reliability"] == 1 and qos[0]["history"] == 1
            assert summary.schemas[channel.schema_id].encoding == "ros2msg"
        records = list(reader.iter_metadata())
        assert [r.name for r in records] == ["rosbag2"]
        meta = YAML(typ="safe").load(records[0].metadata["serialized_metadata"])
    info = meta["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["version"] == 8
    assert info["relative_file_paths"] == ["layout_0.mcap"]
    assert info["message_count"] == summary.statistics.message_count
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts["/skinbox/samples"] == published["samples_messages"]
    assert info["duration"]["nanoseconds"] == (
        summary.statistics.message_end_time - summary.statistics.message_start_time)
    assert YAML(typ="safe").load((bag / "metadata.yaml").read_text()) == meta
    with Reader(bag) as rd:
        assert rd.message_count == info["message_count"]
        assert rd.duration == info["duration"]["nanoseconds"] + 1
        for c in rd.connections:
            assert c.ext.serialization_format == "cdr"
            assert c.ext.offered_qos_profiles[0].depth in (100, 1000)


def test_bad_output_paths_are_clear_errors(skinbox_bin, captures, tmp_path):
    existing = tmp_path / "exists"
    existing.mkdir()
    done = subprocess.run([skinbox_bin, "decode", str(captures["event"]), "--mcap", str(existing)],
                          capture_output=True, text=True)
    assert done.returncode != 0 and "exists already" in done.stderr
    done = subprocess.run([skinbox_bin, "decode", str(captures["event"]), "--mcap", "/nonexistent/dir/x.mcap"],
                          capture_output=True, text=True)
    assert done.returncode != 0 and "x.mcap" in done.stderr and "panick" not in done.stderr


def test_capture_records_what_it_received(skinbox_bin, emulated_box, typestore, tmp_path):
    """`skinbox capture --claim --mcap` from an emulated box: the recording holds every
    record the capture decoded, equal to `decode --jsonl` of its own pcap (the host times
    of a live capture come from its exchanges, not in the pcap's decode: not compared)."""
    bag = tmp_path / "live"
    pcap = tmp_path / "live.pcap"
    out = run(skinbox_bin, "--json", "capture", "--listen", "127.0.0.1:0", "--claim", emulated_box,
              "--duration-ms", "1500", "--cells-per-bus", "65", "--mcap", str(bag), "--pcap", str(pcap))
    report = json.loads(out)
    records = report["report"]["records"]
    assert records > 500
    assert report["ros"]["samples"] == records
    rows = decode_jsonl(skinbox_bin, pcap)
    sources = set()
    with Reader(bag) as rd:
        samples = []
        for connection, _, raw in rd.messages():
            m = typestore.deserialize_cdr(raw, connection.msgtype)
            if connection.topic == "/skinbox/samples":
                samples.extend(m.samples)
    assert len(samples) == len(rows) == records
    for s, row in zip(samples, rows):
        sources.add(s.host_time_source)
        assert (s.box_id, s.cell_id, s.port, s.datagram_sequence) == (
            row["box_id"], row["cell_id"], row["port"], row["datagram_sequence"])
        for i, name in enumerate(CHANNELS):
            if name in row["values"]:
                assert s.values[i] == row["values"][name]
    # the first records come before the first exchange: timed by their receive stamps
    assert sources <= {1, 2} and samples[-1].host_time_source == 2, "mapped by exchanges"
    assert not math.isnan(samples[-1].host_time_bound_ns)
