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


def pcap_into_numpy(path: Path, rounds: int, **options) -> dict:
    """The fastest of `rounds` reads of the whole pcap into one record array: wall time
    and this process's CPU time."""
    best_wall = best_cpu = float("inf")
    n = 0
    for _ in range(rounds):
        wall, cpu = time.perf_counter(), time.process_time()
        records, _ = skinbox.read(path, **options)
        best_wall = min(best_wall, time.perf_counter() - wall)
        best_cpu = min(best_cpu, time.process_time() - cpu)
        n = len(records)
        del records
    return {
        "options": options,
        "records": n,
        "records_per_s": n / best_wall,
        "ns_per_record": best_wall / n * 1e9,
        "cpu_ns_per_record": best_cpu / n * 1e9,
    }


def pcap_in_batches(path: Path, rounds: int, rows: int, **options) -> dict:
    """The fastest of `rounds` passes of a Reader over the whole pcap, `rows` a batch into
    its one reused buffer (each batch taken, nothing done with it)."""
    best_wall = best_cpu = float("inf")
    n = 0
    for _ in range(rounds):
        wall, cpu = time.perf_counter(), time.process_time()
        n = 0
        for batch in skinbox.Reader(path, rows, **options):
            n += len(batch)
        best_wall = min(best_wall, time.perf_counter() - wall)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    return {
        "options": dict(options, rows=rows),
        "records": n,
        "records_per_s": n / best_wall,
        "ns_per_record": best_wall / n * 1e9,
        "cpu_ns_per_record": best_cpu / n * 1e9,
    }


def live_into_numpy(path: Path, rate: float, records_in_file: int, times: bool) -> dict:
    """The pcap's datagrams go at `rate` records/s, in bursts of 32 as `skinbox bench live`
    sends them, to a Capture on loopback; the Python side takes every batch and sums a
    column of it."""
    datagrams_per_s = rate / 55.0
    capture = skinbox.Capture(listen="127.0.0.1:0", batch_ms=50, times=times)
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
    sent = skinbox._native.replay_capture(path, capture.address, datagrams_per_s)
    wall = time.perf_counter() - start
    deadline = time.monotonic() + 5
    while got < records_in_file and time.monotonic() < deadline:
        time.sleep(0.05)
    capture.close()
    consumer.join()
    report = capture.report
    cpu_s = report["capture"]["cpu_s"]
    return {
        "times": times,
        "target_records_per_s": rate,
        "sent": json.loads(sent),
        "replay_wall_s": wall,
        "records_received": got,
        "records_in_file": records_in_file,
        "datagrams_missing": report["report"]["losses"]["datagrams_missing"],
        "lossless": got == records_in_file,
        "receiver_cpu_ns_per_record": cpu_s * 1e9 / max(got, 1),
        "timing_cpu_ns_per_record": report.get("timing_cpu_s", 0.0) * 1e9 / max(got, 1),
        "received_records_per_s": got / wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skinbox", required=True, help="the skinbox command (a release build)")
    parser.add_argument("--packets", type=int, default=4_000_000)
    parser.add_argument("--rate", type=float, default=4.5e6, help="live records/s")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--rows", type=int, default=65536, help="rows of a Reader's batch")
    parser.add_argument("--no-live", action="store_true", help="files only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.pcap"
        packets = skinbox.write_bench_capture(path, args.packets)
        # read() and the Reader alternate, each variant beside its counterpart
        pcaps, chunked = [], []
        for options in ({}, {"sample_rate_hz": 125.0}, {"times": False}):
            pcaps.append(pcap_into_numpy(path, args.rounds, **options))
            chunked.append(pcap_in_batches(path, args.rounds, args.rows, **options))
        rust_decode = json.loads(
            subprocess.run(
                [args.skinbox, "bench", "decode", "--packets", str(args.packets), "--json"],
                check=True, capture_output=True, text=True,
            ).stdout
        )
        lives, rust_live = [], None
        if not args.no_live:
            lives = [
                live_into_numpy(path, args.rate, packets, times=True),
                live_into_numpy(path, args.rate, packets, times=False),
            ]
            rust_live = json.loads(
                subprocess.run(
                    [args.skinbox, "bench", "live", "--rates", str(args.rate), "--batches", "64", "--coalesce-us", "0", "--json"],
                    check=True, capture_output=True, text=True,
                ).stdout
            )
    print(json.dumps({"pcap_into_numpy": pcaps, "pcap_in_batches": chunked, "bench_decode": rust_decode, "live_into_numpy": lives, "bench_live": rust_live}, indent=1), file=sys.stderr)
    for pcap, batches, name in zip(pcaps, chunked, ["two passes, times", "rate given: one pass, times", "times=False: one pass"]):
        print(f"pcap -> numpy, skinbox.read ({name}): {pcap['records_per_s'] / 1e6:6.2f} M records/s, "
              f"{pcap['ns_per_record']:6.1f} ns/record wall, {pcap['cpu_ns_per_record']:6.1f} ns CPU ({pcap['records']} records)")
        print(f"pcap -> numpy, skinbox.Reader rows={args.rows} ({name}): {batches['records_per_s'] / 1e6:6.2f} M records/s, "
              f"{batches['ns_per_record']:6.1f} ns/record wall, {batches['cpu_ns_per_record']:6.1f} ns CPU ({batches['records']} records)")
    print(f"skinbox bench decode (decoder only, Rust):  {rust_decode['packets_per_second'] / 1e6:6.2f} M records/s, {rust_decode['ns_per_packet']:5.1f} ns/record")
    if rust_live is None:
        return
    step = rust_live["steps"][0]
    for live in lives:
        print(f"live -> numpy at {args.rate / 1e6:.1f} M records/s (Capture, times={live['times']}):  {live['records_received']} of {live['records_in_file']} records, "
              f"{live['datagrams_missing']} datagrams missing, sent at {live['records_in_file'] / live['sent']['wall_s'] / 1e6:.2f} M records/s, receiver {live['receiver_cpu_ns_per_record']:.1f} ns CPU/record, timing thread {live['timing_cpu_ns_per_record']:.1f} ns CPU/record")
    print(f"skinbox bench live at {step['target_records_per_second'] / 1e6:.1f} M records/s (Rust):  {step['records_received']} records, "
          f"{step['datagrams_missing']} datagrams missing, sent at {step['sent_records_per_second'] / 1e6:.2f} M records/s, lossless {step['lossless']}, receiver {step['receiver_cpu_ns_per_record']:.1f} ns CPU/record")


if __name__ == "__main__":
    main()
