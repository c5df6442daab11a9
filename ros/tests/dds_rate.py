"""Live ROS 2 over DDS at a rate: `skinbox emulate` streams a scene (by default 260 cells on
8 buses in data mode at 500 Hz, 130,000 samples/s), `skinbox capture --claim --ros2
--pcap` publishes it, and a Cyclone DDS subscriber (Python, the types declared from the
`.msg` files) counts what arrives. The capture's own pcap is the truth: every records
datagram from the first one the subscriber received on must arrive with all its samples
(in parts: at most as many samples a message as fit one RTPS datagram).

As a script it prints the figures (docs/ros2.md):

    python ros/tests/dds_rate.py [--seconds 5] [--buses 8] [--rate-hz 500] [--best-effort]

`test_dds.py` runs `measure` at a moderate rate."""



import argparse
import json
import os
import random
import re
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import sequence, uint8, uint16, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from test_dds import Time_

REPO = Path(__file__).resolve().parents[2]


@dataclass
class CountedBatch_(IdlStruct, typename="skinbox_msgs::msg::dds_::CellSampleBatch_"):
    """`CellSampleBatch` with its samples declared as bytes: the sequence's length is the
    number of samples, and Python does not decode each (0.4 ms a message with the full
    type, which would bound the rate measured here)."""
    stamp: Time_
    box_id: uint16
    box_address: str
    datagram_sequence: uint32
    samples: sequence[uint8]


def scene_file(folder: Path, buses: int, mode: str, rate_hz: float) -> Path:
    """The idle scene (260 cells) with another bus count, mode and sample rate."""
    text = (REPO / "cosim" / "scenes" / "idle.toml").read_text()
    text = re.sub(r"(?m)^buses = .*$", f"buses = {buses}", text, count=1)
    text = re.sub(r'(?m)^mode = .*$', f'mode = "{mode}"', text, count=1)
    text = re.sub(r"(?m)^sample_rate_hz = .*$", f"sample_rate_hz = {rate_hz}", text, count=1)
    path = folder / f"idle_{buses}_{mode}_{rate_hz:g}.toml"
    path.write_text(text)
    return path


def records_datagrams(pcap: Path) -> dict:
    """Sequence number to record count of every records datagram of a nanosecond
    Ethernet/IPv4/UDP pcap (docs/wire-format.md: "SK", kind 1, big-endian)."""
    data = pcap.read_bytes()
    out = {}
    at = 24
    while at + 16 <= len(data):
        caplen = struct.unpack_from("<I", data, at + 8)[0]
        frame = at + 16
        if struct.unpack_from(">H", data, frame + 12)[0] == 0x0800:
            payload = frame + 14 + (data[frame + 14] & 0x0F) * 4 + 8
            if data[payload:payload + 2] == b"SK" and data[payload + 3] == 1:
                seq = struct.unpack_from(">I", data, payload + 8)[0]
                out[seq] = struct.unpack_from(">H", data, payload + 20)[0]
        at = frame + caplen
    return out


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# The subscriber's Cyclone DDS configuration without multicast for data (discovery still
# multicast): the writer then sends to the reader's unicast address, which on the same
# host the kernel delivers through loopback; with multicast data every datagram also
# leaves through the network interface. A receive buffer of up to 4 MB (as much as
# net.core.rmem_max allows; 4 MB here) rides out the moments the subscriber's receive
# thread waits for a core.
UNICAST_DATA = ("<General><AllowMulticast>spdp</AllowMulticast></General>"
                '<Internal><SocketReceiveBufferSize max="4MB"/></Internal>')


def measure(skinbox_bin: str, folder: Path, seconds: float = 5.0, buses: int = 8,
            mode: str = "data", rate_hz: float = 500.0, best_effort: bool = False,
            scene: "Path | None" = None, multicast_data: bool = False) -> dict:
    """Runs emulator, capture and subscriber for `seconds`; returns the figures."""
    domain = random.randint(100, 200)
    scene = scene or scene_file(folder, buses, mode, rate_hz)
    port = _free_udp_port()
    run_ms = int(seconds * 1000)
    box = subprocess.Popen(
        [skinbox_bin, "emulate", str(scene), "--listen", f"127.0.0.1:{port}",
         "--run-ms", str(run_ms + 20000)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        box.stderr.readline()  # "emulating box ..." once it listens
        saved = os.environ.pop("CYCLONEDDS_URI", None)
        if not multicast_data:
            os.environ["CYCLONEDDS_URI"] = UNICAST_DATA
        try:
            participant = DomainParticipant(domain)
        finally:
            os.environ.pop("CYCLONEDDS_URI", None)
            if saved is not None:
                os.environ["CYCLONEDDS_URI"] = saved
        reliability = (Policy.Reliability.BestEffort if best_effort
                       else Policy.Reliability.Reliable(duration(seconds=1)))
        # Room for the whole run: Python's take never drops what it has not read yet.
        qos = Qos(reliability, Policy.Durability.Volatile, Policy.History.KeepLast(1_000_000))
        reader = DataReader(participant, Topic(participant, "rt/skinbox/samples", CountedBatch_),
                            qos=qos)
        pcap = folder / f"dds_rate_{port}.pcap"
        args = [skinbox_bin, "capture", "--listen", "127.0.0.1:0", "--claim",
                f"127.0.0.1:{port}", "--duration-ms", str(run_ms), "--ros2", "--pcap", str(pcap)]
        if best_effort:
            args.append("--ros2-best-effort")
        capture = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, env={**os.environ, "ROS_DOMAIN_ID": str(domain)})
        got = []  # (datagram_sequence, samples, stamp in ns, take time - stamp in ns)
        # Until the capture has ended and nothing more came for a second (the reader's
        # history holds what Python has not taken yet).
        last = time.monotonic()
        end = last + seconds + 30.0
        while time.monotonic() < end:
            batch = reader.take(N=5000)
            now = time.time_ns()
            for m in batch:
                if isinstance(m, CountedBatch_):
                    stamp = m.stamp.sec * 1_000_000_000 + m.stamp.nanosec
                    got.append((m.datagram_sequence, len(m.samples), stamp, now - stamp))
            if batch:
                last = time.monotonic()
            elif capture.poll() is not None and time.monotonic() - last > 1.0:
                break
            else:
                time.sleep(0.001)
        out, err = capture.communicate(timeout=30)
    finally:
        box.terminate()
        box.wait(timeout=10)
    if capture.returncode != 0:
        raise RuntimeError(err)
    dds = next(line for line in err.splitlines() if line.startswith("ROS 2 over DDS:"))
    nums = lambda pattern: [float(x) for x in re.search(pattern, dds).groups()]  # noqa: E731
    written, failed = nums(r"(\d+) samples messages.* (\d+) writes failed")
    p50, p99, pmax = nums(r"p50 (\S+) us, p99 (\S+) us, max (\S+) us")
    sink = re.search(r"ROS 2: (\d+) samples in (\d+) messages", out)
    truth = records_datagrams(pcap)
    pcap.unlink()
    received = {}
    t_of = {}
    for seq, n, stamp, _ in got:
        t_of.setdefault(seq, stamp)
        received[seq] = received.get(seq, 0) + n
    first = got[0][0] if got else None
    window = {s: n for s, n in truth.items() if first is not None and s >= first}
    missing = {s: n - received.get(s, 0) for s, n in window.items() if received.get(s, 0) != n}
    # Volatile durability: while the reader has only begun to follow the writer (its first
    # heartbeat), messages may be missed; from half a second after the first one, none.
    settled = next((seq for seq, _, t, _ in got if t >= t_of[first] + 500_000_000), None)
    after = {s: n for s, n in window.items() if settled is not None and s >= settled}
    lost_after = sum(n - received.get(s, 0) for s, n in after.items())
    delays = sorted(d for _, _, _, d in got)
    pick = lambda q: delays[round((len(delays) - 1) * q)] / 1e3 if delays else None  # noqa: E731
    return {
        "seconds": seconds,
        "samples_topic": "best effort" if best_effort else "reliable",
        "subscriber_data": "multicast" if multicast_data else "unicast",
        "samples_published": int(sink.group(1)) if sink else None,
        "datagrams_published": int(sink.group(2)) if sink else None,
        "samples_per_second_published": int(sink.group(1)) / seconds if sink else None,
        "dds_messages_written": int(written),
        "dds_writes_failed": int(failed),
        "messages_received": len(got),
        "samples_received": sum(n for _, n, _, _ in got),
        "datagrams_in_pcap": len(truth),
        "samples_in_pcap": sum(truth.values()),
        "first_sequence_received": first,
        "samples_expected_from_first": sum(window.values()),
        "samples_missing_from_first": sum(missing.values()),
        "datagrams_short_from_first": len(missing),
        "short_datagram_range": [min(missing, default=None), max(missing, default=None)],
        "last_sequence_in_pcap": max(truth, default=None),
        "last_sequence_received": max(received, default=None),
        "settled_sequence": settled,
        "samples_expected_settled": sum(after.values()),
        "samples_lost_settled": lost_after,
        "extra_samples": sum(n for s, n in received.items() if n > truth.get(s, 0)),
        "receive_to_publish_us": {"p50": p50, "p99": p99, "max": pmax},
        "stamp_to_python_take_us": {"p50": pick(0.5), "p99": pick(0.99), "max": pick(1.0)},
        "capture_stderr_dds": dds,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skinbox", default=os.environ.get("SKINBOX_BIN", str(
        Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "release" / "skinbox")))
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--buses", type=int, default=8)
    ap.add_argument("--mode", default="data")
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--best-effort", action="store_true")
    ap.add_argument("--scene", type=Path, help="a scene file instead of the idle one changed")
    ap.add_argument("--multicast-data", action="store_true",
                    help="the subscriber takes data by multicast too (Cyclone's default)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        r = measure(a.skinbox, Path(d), a.seconds, a.buses, a.mode, a.rate_hz, a.best_effort,
                    a.scene, a.multicast_data)
    r["load_average"] = os.getloadavg()
    json.dump(r, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
