"""Records per second into numpy, from a pcap and live on loopback, beside the Rust
figures of `skinbox bench decode` and `skinbox bench live` measured in the same run.

Usage: python bench.py --skinbox PATH/TO/skinbox [--packets N] [--rate R] [--seconds S]
(python/bench.sh builds both in release mode and runs this).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

import skinbox


def pcap_into_numpy(path: Path, rounds: int) -> dict:
    """The fastest of `rounds` reads of the whole pcap into one record array."""
    best = float("inf")
    n = 0
    for _ in range(rounds):
        start = time.perf_counter()
        records, _ = skinbox.read(path)
        best = min(best, time.perf_counter() - start)
        n = len(records)
        del records
    return {"records": n, "best_s": best, "records_per_s": n / best, "ns_per_record": best / n * 1e9}


def live_into_numpy(skinbox_bin: str, path: Path, rate: float, records_in_file: int) -> dict:
    """`skinbox replay` sends the pcap's datagrams at `rate` records/s to a Capture on
    loopback; the Python side takes every batch and sums a column of it."""
    datagrams_per_s = rate / 55.0
    capture = skinbox.Capture(listen="127.0.0.1:0", batch_ms=50)
    got = 0
    checksum = 0

    def consume():
        nonlocal got, checksum
        for batch in capture:
            got += len(batch)
            checksum += int(batch["cell_id"].sum())

    consumer = threading.Thread(target=consume)
    consumer.start()
    start = time.perf_counter()
    sent = subprocess.run(
        [skinbox_bin, "replay", str(path), "--to", capture.address, "--rate", str(datagrams_per_s), "--json"],
        check=True,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - start
    deadline = time.monotonic() + 5
    while got < records_in_file and time.monotonic() < deadline:
        time.sleep(0.05)
    capture.close()
    consumer.join()
    report = capture.report
    cpu_s = report["capture"]["cpu_s"]
    return {
        "target_records_per_s": rate,
        "sent": json.loads(sent.stdout),
        "replay_wall_s": wall,
        "records_received": got,
        "records_in_file": records_in_file,
        "datagrams_missing": report["report"]["losses"]["datagrams_missing"],
        "lossless": got == records_in_file,
        "receiver_cpu_ns_per_record": cpu_s * 1e9 / max(got, 1),
        "received_records_per_s": got / wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skinbox", required=True, help="the skinbox command (a release build)")
    parser.add_argument("--packets", type=int, default=4_000_000)
    parser.add_argument("--rate", type=float, default=4.5e6, help="live records/s")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.pcap"
        packets = skinbox.write_bench_capture(path, args.packets)
        pcap = pcap_into_numpy(path, args.rounds)
        rust_decode = json.loads(
            subprocess.run(
                [args.skinbox, "bench", "decode", "--packets", str(args.packets), "--json"],
                check=True, capture_output=True, text=True,
            ).stdout
        )
        live = live_into_numpy(args.skinbox, path, args.rate, packets)
        rust_live = json.loads(
            subprocess.run(
                [args.skinbox, "bench", "live", "--rates", str(args.rate), "--batches", "64", "--json"],
                check=True, capture_output=True, text=True,
            ).stdout
        )
    step = rust_live["steps"][0]
    print(json.dumps({"pcap_into_numpy": pcap, "bench_decode": rust_decode, "live_into_numpy": live, "bench_live": rust_live}, indent=1), file=sys.stderr)
    print(f"pcap -> numpy (skinbox.read, whole file):   {pcap['records_per_s'] / 1e6:6.2f} M records/s, {pcap['ns_per_record']:5.1f} ns/record ({pcap['records']} records)")
    print(f"skinbox bench decode (decoder only, Rust):  {rust_decode['packets_per_second'] / 1e6:6.2f} M records/s, {rust_decode['ns_per_packet']:5.1f} ns/record")
    print(f"live -> numpy at {args.rate / 1e6:.1f} M records/s (Capture):  {live['records_received']} of {live['records_in_file']} records, "
          f"{live['datagrams_missing']} datagrams missing, receiver {live['receiver_cpu_ns_per_record']:.1f} ns CPU/record")
    print(f"skinbox bench live at {step['target_records_per_second'] / 1e6:.1f} M records/s (Rust):  {step['records_received']} records, "
          f"{step['datagrams_missing']} datagrams missing, lossless {step['lossless']}, receiver {step['receiver_cpu_ns_per_record']:.1f} ns CPU/record")


if __name__ == "__main__":
    main()
