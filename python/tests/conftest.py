"""Fixtures of the package's tests: the `skinbox` command (the oracle of `read`) and
synthetic captures of the box's reference model with their truth."""

from __future__ import annotations

import json
import os
import struct
import subprocess
from pathlib import Path

import pytest

import skinbox

REPO = Path(__file__).resolve().parents[2]


def _find_skinbox() -> str:
    """The `skinbox` command: $SKINBOX_BIN, else the workspace's debug build (built when
    missing)."""
    given = os.environ.get("SKINBOX_BIN")
    if given:
        return given
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    binary = target / "debug" / "skinbox"
    if not binary.exists():
        subprocess.run(
            ["cargo", "build", "--bin", "skinbox"], cwd=REPO, check=True
        )
    return str(binary)


@pytest.fixture(scope="session")
def skinbox_bin() -> str:
    return _find_skinbox()


def decode_jsonl(skinbox_bin: str, path: Path, *extra: str) -> list:
    """Rows of `skinbox decode --jsonl`."""
    out = subprocess.run(
        [skinbox_bin, "decode", str(path), "--jsonl", *extra],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return [json.loads(line) for line in out.splitlines()]


def stats_json(skinbox_bin: str, path: Path) -> dict:
    """The report of `skinbox stats --json`."""
    out = subprocess.run(
        [skinbox_bin, "stats", str(path), "--json"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(out)


def pcap_to_pcapng(pcap: Path, pcapng: Path) -> None:
    """Rewrites a nanosecond pcap as pcapng (section header, one Ethernet interface with
    nanosecond timestamps, an enhanced packet block per frame): written here from the
    pcapng specification, independent of the reader under test."""
    data = pcap.read_bytes()
    magic, _, _, _, _, snaplen, linktype = struct.unpack_from("<IHHiIII", data, 0)
    assert magic == 0xA1B23C4D, "a nanosecond pcap"

    def block(kind: int, body: bytes) -> bytes:
        body += b"\0" * (-len(body) % 4)
        length = 12 + len(body)
        return struct.pack("<II", kind, length) + body + struct.pack("<I", length)

    out = bytearray()
    out += block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1))
    # option if_tsresol (9): 10^-9 s; then opt_endofopt
    options = struct.pack("<HHB", 9, 1, 9) + b"\0" * 3 + struct.pack("<HH", 0, 0)
    out += block(1, struct.pack("<HHI", linktype, 0, snaplen) + options)
    offset = 24
    while offset + 16 <= len(data):
        seconds, nanos, caplen, origlen = struct.unpack_from("<IIII", data, offset)
        frame = data[offset + 16 : offset + 16 + caplen]
        offset += 16 + caplen
        stamp = seconds * 1_000_000_000 + nanos
        out += block(
            6,
            struct.pack("<IIIII", 0, stamp >> 32, stamp & 0xFFFFFFFF, caplen, origlen)
            + frame,
        )
    pcapng.write_bytes(bytes(out))


CAPTURES = {
    "data": dict(event_every=0),
    "event": dict(event_every=1, walk_scale=4),
    "mixed": dict(event_every=2, walk_scale=2),
    "two_boxes": dict(event_every=2, boxes=2),
    "shared_id": dict(event_every=2, boxes=2, shared_box_id=True),
    "gaps": dict(event_every=2, drop_every=4),
}


@pytest.fixture(scope="session")
def captures(tmp_path_factory) -> dict:
    """Each synthetic capture by name: its path and truth; "pcapng" is "mixed" as pcapng."""
    folder = tmp_path_factory.mktemp("captures")
    made = {}
    for name, options in CAPTURES.items():
        path = folder / f"{name}.pcap"
        truth = skinbox.write_synthetic_capture(
            path, cells=48, samples_per_cell=40, seed=7, **options
        )
        made[name] = (path, truth)
    pcapng = folder / "mixed.pcapng"
    pcap_to_pcapng(made["mixed"][0], pcapng)
    made["pcapng"] = (pcapng, made["mixed"][1])
    return made
