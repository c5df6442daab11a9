"""Fixtures of the ROS 2 tests: the `skinbox` command (the recordings' writer and the
oracle, `skinbox decode --jsonl`), reference-model captures and the message types of
`ros/skinbox_msgs` for the independent readers."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MSG_DIR = REPO / "ros" / "skinbox_msgs" / "msg"


def _find_skinbox() -> str:
    given = os.environ.get("SKINBOX_BIN")
    if given:
        return given
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    binary = target / "debug" / "skinbox"
    if not binary.exists():
        subprocess.run(["cargo", "build", "--bin", "skinbox"], cwd=REPO, check=True)
    return str(binary)


@pytest.fixture(scope="session")
def skinbox_bin() -> str:
    return _find_skinbox()


def run(*args: str) -> str:
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


def decode_jsonl(skinbox_bin: str, path: Path) -> list:
    """Rows of `skinbox decode --jsonl` (one per cell packet)."""
    out = run(skinbox_bin, "decode", str(path), "--jsonl")
    return [json.loads(line) for line in out.splitlines()]


def _rewrite_box_id(src: Path, dst: Path, box_id: int) -> None:
    """A copy of a nanosecond Ethernet/IPv4/UDP pcap whose box datagrams carry another box
    id (bytes 4-5 of the datagram, big-endian, docs/wire-format.md); the UDP checksum is
    zeroed (IPv4: no checksum)."""
    data = bytearray(src.read_bytes())
    at = 24
    while at + 16 <= len(data):
        caplen = struct.unpack_from("<I", data, at + 8)[0]
        frame = at + 16
        if struct.unpack_from(">H", data, frame + 12)[0] == 0x0800:
            ihl = (data[frame + 14] & 0x0F) * 4
            udp = frame + 14 + ihl
            payload = udp + 8
            if data[payload : payload + 2] == b"SK":
                struct.pack_into(">H", data, payload + 4, box_id)
                struct.pack_into(">H", data, udp + 6, 0)
        at = frame + caplen
    dst.write_bytes(bytes(data))


@pytest.fixture(scope="session")
def captures(skinbox_bin, tmp_path_factory) -> dict:
    """Reference-model captures by name: data, event, two boxes (the event capture and a
    copy as box 2, merged by time), gaps (frames deleted from the event capture)."""
    folder = tmp_path_factory.mktemp("ros-captures")
    made = {}
    for mode, ms in (("data", "60"), ("event", "200")):
        path = folder / f"{mode}.pcap"
        run(skinbox_bin, "sim", "--fidelity", "reference", "--mode", mode,
            "--duration-ms", ms, "--pcap", str(path))
        made[mode] = path
    box2 = folder / "box2.pcap"
    _rewrite_box_id(made["event"], box2, 2)
    two = folder / "two_boxes.pcap"
    run(shutil.which("mergecap") or "mergecap", "-F", "pcap", "-w", str(two),
        str(made["event"]), str(box2))
    made["two_boxes"] = two
    gaps = folder / "gaps.pcap"
    run(shutil.which("editcap") or "editcap", str(made["event"]), str(gaps), "20-25", "90", "200-203")
    made["gaps"] = gaps
    return made


@pytest.fixture(scope="session")
def typestore():
    """A rosbags type store that knows only what the `.msg` files say."""
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    store = get_typestore(Stores.EMPTY)
    types = {}
    for path in sorted(MSG_DIR.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"skinbox_msgs/msg/{path.stem}"))
    types.update(get_types_from_msg("int32 sec\nuint32 nanosec\n", "builtin_interfaces/msg/Time"))
    store.register(types)
    return store


def free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def emulated_box(skinbox_bin):
    """`skinbox emulate` on loopback for the test's length: its command address."""
    port = free_udp_port()
    box = subprocess.Popen(
        [skinbox_bin, "emulate", "--listen", f"127.0.0.1:{port}", "--run-ms", "20000"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    box.stderr.readline()  # "emulating box ..." once it listens
    yield f"127.0.0.1:{port}"
    box.terminate()
    box.wait(timeout=10)
