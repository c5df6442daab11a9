"""Live ROS 2 over DDS: a `cyclonedds` subscriber (Eclipse Cyclone DDS, the C library ROS 2
ships by default, through its Python binding) with the message types declared here from
the `.msg` files as ROS 2 names them on the wire (`skinbox_msgs::msg::dds_::CellSample_`
...) receives what `skinbox capture --ros2` publishes from a claimed `skinbox emulate`
stream on loopback; the samples equal `skinbox decode --jsonl` of the capture's own pcap,
and every records datagram from the first one received on is there."""

import collections
import os
import random
import subprocess
import time
from dataclasses import dataclass

import pytest

from conftest import decode_jsonl

cyclonedds = pytest.importorskip("cyclonedds")

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import (  # noqa: E402
    array, float64, int32, int64, sequence, uint8, uint16, uint32, uint64)
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

CHANNELS = ["accel_x", "accel_y", "accel_z", "force_1", "force_2", "force_3",
            "proximity", "temperature_1", "temperature_2"]


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class CellSample_(IdlStruct, typename="skinbox_msgs::msg::dds_::CellSample_"):
    box_id: uint16
    port: uint8
    cell_id: uint16
    kind: uint8
    event_mask: uint16
    values: array[float64, 9]
    event_sequence: int32
    second_part: bool
    event_packets_missing_before: uint16
    flags: uint8
    datagram_sequence: uint32
    box_time_ns: uint64
    sample_box_time_ns: float64
    host_time_ns: int64
    host_time_bound_ns: float64
    host_time_source: uint8


@dataclass
class CellSampleBatch_(IdlStruct, typename="skinbox_msgs::msg::dds_::CellSampleBatch_"):
    stamp: Time_
    box_id: uint16
    box_address: str
    datagram_sequence: uint32
    samples: sequence[CellSample_]


@dataclass
class PortCounters_(IdlStruct, typename="skinbox_msgs::msg::dds_::PortCounters_"):
    port: uint8
    packets_good: uint32
    dropped_overflow: uint32
    rejected_end_byte: uint32
    rejected_framing: uint32
    rejected_truncated: uint32
    garbage_bytes: uint32
    framing_errors: uint32
    resyncs: uint32


@dataclass
class BoxStatus_(IdlStruct, typename="skinbox_msgs::msg::dds_::BoxStatus_"):
    stamp: Time_
    box_id: uint16
    box_address: str
    boot_id: uint32
    link_up: bool
    link_speed: uint8
    datagrams_sent: uint32
    records_sent: uint32
    ports: sequence[PortCounters_]
    datagrams_received: uint64
    datagrams_missing: uint64
    records_received: uint64
    event_packets_missing: uint64
    records_flagged_loss_before: uint64
    host_time_source: uint8
    drift_ppm: float64
    time_error_bound_ns: float64
    time_map_restarts: uint64


@dataclass
class PortActivity_(IdlStruct, typename="skinbox_msgs::msg::dds_::PortActivity_"):
    port: uint8
    packets_per_s: float64
    events_per_s: float64
    cells_active: uint16
    channel_max: float64
    channel_mean: float64


@dataclass
class SkinActivity_(IdlStruct, typename="skinbox_msgs::msg::dds_::SkinActivity_"):
    stamp: Time_
    box_id: uint16
    period_s: float64
    channel: uint8
    channel_name: str
    ports: sequence[PortActivity_]
    datagrams_missing: uint64
    event_packets_missing: uint64


# At most this many CellSample in a message: 1,372 bytes (what rustdds sends unfragmented)
# less the header, 144 bytes a sample at most (ros-bridge/src/dds.rs).
MAX_SAMPLES_PER_MESSAGE = 9

# The readers' history depths: room for the whole run (~4,200 samples messages a second),
# so Python's slow decoding (a fraction of a millisecond a message) never drops any.
TOPICS = {
    "rt/skinbox/samples": (CellSampleBatch_, 30000),
    "rt/skinbox/status": (BoxStatus_, 1000),
    "rt/skinbox/activity": (SkinActivity_, 1000),
}


def test_capture_publishes_the_topics_to_a_cyclonedds_subscriber(
        skinbox_bin, emulated_box, tmp_path, monkeypatch):
    domain = random.randint(100, 200)  # away from other tests' default domain 0
    participant = DomainParticipant(domain)
    readers = {}
    for name, (kind, depth) in TOPICS.items():
        qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                  Policy.Durability.Volatile, Policy.History.KeepLast(depth))
        readers[name] = DataReader(participant, Topic(participant, name, kind), qos=qos)
    pcap = tmp_path / "dds.pcap"
    capture = subprocess.Popen(
        [skinbox_bin, "capture", "--listen", "127.0.0.1:0", "--claim", emulated_box,
         "--duration-ms", "3000", "--ros2", "--pcap", str(pcap)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain)})
    got = {name: [] for name in TOPICS}
    end = time.monotonic() + 6.0
    while time.monotonic() < end:
        for name, r in readers.items():
            # (an InvalidSample tells of the writer gone at the end: no data)
            got[name].extend(m for m in r.take(N=1000) if isinstance(m, TOPICS[name][0]))
        time.sleep(0.01)
    _, err = capture.communicate(timeout=20)
    assert capture.returncode == 0, err
    assert f"ROS 2 topics over DDS in domain {domain}" in err
    line = next(l for l in err.splitlines() if l.startswith("ROS 2 over DDS:"))
    written = int(line.split()[4])

    batches = got["rt/skinbox/samples"]
    assert len(batches) > 200, err
    assert got["rt/skinbox/status"] and got["rt/skinbox/activity"]
    rows = decode_jsonl(skinbox_bin, pcap)
    # A datagram's samples come in parts (as many a message as fit one RTPS datagram),
    # consecutive, each with the datagram's stamp, box and sequence.
    assert all(len(b.samples) <= MAX_SAMPLES_PER_MESSAGE for b in batches)
    received = [s for i, s in enumerate(b.datagram_sequence for b in batches)
                if i == 0 or batches[i - 1].datagram_sequence != s]
    assert len(received) == len(set(received)), "a datagram's parts not consecutive"
    expected = sorted({r["datagram_sequence"] for r in rows if r["datagram_sequence"] >= received[0]})
    # Volatile durability: what is written while the subscriber has not yet matched the
    # writer (the first moments after discovery) may be missed; from then on, reliable,
    # nothing is: every records datagram of the pcap, in order.
    settled = received[100]
    gaps = [(a, b) for a, b in zip(received, received[1:]) if b != a + 1]
    assert ([s for s in received if s >= settled] == [s for s in expected if s >= settled]), (
        gaps, len(received), len(expected), line)
    assert len(expected) - len(received) < 100
    assert len(batches) <= written
    by_key = {(r["datagram_sequence"], r["cell_id"], r["event_sequence"]): r for r in rows}
    per_datagram = collections.Counter(r["datagram_sequence"] for r in rows)
    parts = collections.Counter()
    for b in batches:
        parts[b.datagram_sequence] += len(b.samples)
    # Every datagram received whole (the first one perhaps from a later part on).
    assert all(parts[s] == per_datagram[s] for s in received[1:])
    seen = 0
    for b in batches:
        assert b.box_id == 1 and b.box_address.startswith("127.0.0.1:")
        for s in b.samples:
            row = by_key[(s.datagram_sequence, s.cell_id,
                          None if s.event_sequence < 0 else s.event_sequence)]
            assert (s.box_id, s.port) == (row["box_id"], row["port"])
            for i, name in enumerate(CHANNELS):
                if name in row["values"]:
                    assert s.values[i] == row["values"][name]
            seen += 1
    assert seen > 200
    status = got["rt/skinbox/status"][-1]
    assert status.box_id == 1 and status.ports
    activity = got["rt/skinbox/activity"][-1]
    assert activity.channel_name == "force_1"
    assert activity.ports and sum(p.packets_per_s for p in activity.ports) > 0


def test_no_sample_lost_at_a_moderate_data_rate(skinbox_bin, tmp_path):
    """260 cells on 8 buses in data mode at 125 Hz (32,500 samples/s, datagrams of more
    samples than one message takes): from half a second after the first message received
    (the reader following the writer by then) every sample of the capture's pcap arrives,
    nothing twice, and no write fails."""
    from dds_rate import measure

    r = measure(skinbox_bin, tmp_path, seconds=3.0, buses=8, mode="data", rate_hz=125.0)
    assert r["samples_per_second_published"] > 20000, r
    assert r["dds_writes_failed"] == 0, r
    assert r["samples_received"] > 0.8 * r["samples_in_pcap"], r
    assert r["samples_expected_settled"] > 0.5 * r["samples_in_pcap"], r
    assert r["samples_lost_settled"] == 0, r
    assert r["extra_samples"] == 0, r
