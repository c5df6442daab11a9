"""The Foxglove live view: a WebSocket client (websocket-client) speaks the
`foxglove.websocket.v1` protocol to `skinbox capture --foxglove` and to `skinbox emulate
--foxglove`, subscribes to every advertised channel and decodes each message with rosbags'
CDR decoder fed the `.msg` files; the samples equal `skinbox decode --jsonl` of the
capture's own pcap."""

from __future__ import annotations

import json
import struct
import subprocess
import time

import websocket

from conftest import decode_jsonl

CHANNELS = ["accel_x", "accel_y", "accel_z", "force_1", "force_2", "force_3",
            "proximity", "temperature_1", "temperature_2"]
TYPES = {
    "/skinbox/samples": "skinbox_msgs/msg/CellSampleBatch",
    "/skinbox/status": "skinbox_msgs/msg/BoxStatus",
    "/skinbox/activity": "skinbox_msgs/msg/SkinActivity",
}


def wait_for_line(stream, prefix: str, limit: int = 20) -> str:
    for _ in range(limit):
        line = stream.readline()
        if line.startswith(prefix):
            return line
    raise AssertionError(f"no line starting {prefix!r}")


def watch(url: str, typestore, seconds: float) -> dict:
    """Connects, checks the handshake, subscribes to every channel, decodes what comes."""
    ws = websocket.create_connection(url, subprotocols=["foxglove.websocket.v1"], timeout=5)
    assert ws.getsubprotocol() == "foxglove.websocket.v1"
    info = json.loads(ws.recv())
    assert info["op"] == "serverInfo" and info["name"] == "skinbox"
    advertised = json.loads(ws.recv())
    assert advertised["op"] == "advertise"
    channels = {c["id"]: c for c in advertised["channels"]}
    assert {c["topic"]: c["schemaName"] for c in channels.values()} == TYPES
    for c in channels.values():
        assert c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg"
        assert c["schema"].startswith("#")
    subs = [{"id": 100 + cid, "channelId": cid} for cid in channels]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
    got = {t: [] for t in TYPES}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            frame = ws.recv()
        except (websocket.WebSocketConnectionClosedException, websocket.WebSocketTimeoutException):
            break
        assert isinstance(frame, bytes), frame
        op, sub, log_time = struct.unpack_from("<BIQ", frame, 0)
        assert op == 1
        topic = channels[sub - 100]["topic"]
        m = typestore.deserialize_cdr(frame[13:], TYPES[topic])
        assert log_time == m.stamp.sec * 1_000_000_000 + m.stamp.nanosec
        got[topic].append(m)
    ws.close()
    return got


def test_capture_serves_the_topics_to_a_websocket_client(skinbox_bin, emulated_box, typestore, tmp_path):
    pcap = tmp_path / "fox.pcap"
    capture = subprocess.Popen(
        [skinbox_bin, "capture", "--listen", "127.0.0.1:0", "--claim", emulated_box,
         "--duration-ms", "2500", "--foxglove", "127.0.0.1:0", "--pcap", str(pcap)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = wait_for_line(capture.stderr, "foxglove live view on ")
    url = line.split()[-1]
    got = watch(url, typestore, 4.0)
    capture.wait(timeout=20)
    assert capture.returncode == 0
    batches = got["/skinbox/samples"]
    assert len(batches) > 50
    assert got["/skinbox/status"] and got["/skinbox/activity"]
    rows = {(r["datagram_sequence"], r["cell_id"], r["event_sequence"]): r
            for r in decode_jsonl(skinbox_bin, pcap)}
    seen = 0
    for b in batches:
        for s in b.samples:
            row = rows[(s.datagram_sequence, s.cell_id, None if s.event_sequence < 0 else s.event_sequence)]
            assert (s.box_id, s.port) == (row["box_id"], row["port"])
            for i, name in enumerate(CHANNELS):
                if name in row["values"]:
                    assert s.values[i] == row["values"][name]
            seen += 1
    assert seen > 200
    activity = got["/skinbox/activity"][-1]
    assert activity.ports and sum(p.packets_per_s for p in activity.ports) > 0


def test_emulate_has_a_live_view(skinbox_bin, typestore):
    from conftest import free_udp_port

    port = free_udp_port()
    box = subprocess.Popen(
        [skinbox_bin, "emulate", "--listen", f"127.0.0.1:{port}", "--run-ms", "3000",
         "--foxglove", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = wait_for_line(box.stderr, "foxglove live view on ")
        got = watch(line.split()[-1], typestore, 2.0)
    finally:
        box.wait(timeout=20)
    samples = [s for b in got["/skinbox/samples"] for s in b.samples]
    assert len(samples) > 100
    assert {s.box_id for s in samples} == {1}
    assert all(s.host_time_source in (1, 2) for s in samples)


def test_the_layout_names_only_advertised_fields():
    """Every plotted path of ros/foxglove/skinbox-layout.json is a field of the `.msg`
    files on an advertised topic."""
    from conftest import MSG_DIR, REPO

    layout = json.loads((REPO / "ros" / "foxglove" / "skinbox-layout.json").read_text())
    fields = {}
    for path in MSG_DIR.glob("*.msg"):
        fields[path.stem] = {line.split()[1] for line in path.read_text().splitlines()
                             if line.strip() and not line.startswith("#") and "=" not in line}
    paths = [p["value"] for c in layout["configById"].values() for p in c.get("paths", [])]
    assert len(paths) >= 10
    for p in paths:
        topic, _, rest = p.partition(".")
        msg = TYPES[topic].split("/")[-1]
        first = rest.split(".")[0].split("[")[0]
        assert first in fields[msg], p
        if "ports[" in rest:
            leaf = rest.split(".")[-1]
            assert leaf in fields["PortActivity"], p
