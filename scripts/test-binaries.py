#!/usr/bin/env python3
"""Runs the workspace's test binaries, already built, two at a time, longest first.

Reads the JSON messages of `cargo test --no-run --message-format=json` on stdin and runs each
test executable the way `cargo test` would (in its package's directory, with its package's
CARGO_* variables), so nothing is built again: `cargo test -p X` would resolve features for
X alone and rebuild X's dependencies. Each binary's output goes to LOG_DIR/<package>.<target>.log
and is printed when all are done; the exit status is 1 when any binary failed.

Usage: cargo test ... --no-run --message-format=json | scripts/test-binaries.py LOG_DIR [JOBS]
"""

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

# The binaries that took longest on a 2-core machine, longest first (a fresh clone has no
# durations of its own yet). Starting them first keeps both cores busy to the end.
LONGEST_FIRST = [
    "line_rate",
    "baud_mismatch",
    "reference",
    "report",
    "closed_loop",
    "sim",
    "scaling",
    "cache_processes",
    "downlink",
    "sample_clock_fits",
    "vcd",
    "scenes",
    "regressions",
    "dut",
    "calibrate",
]
DURATIONS_FILE = "durations.json"


def test_binaries(messages):
    """The test executables in cargo's messages, with their package's directory and name."""
    binaries = []
    for line in messages:
        line = line.strip()
        if not line.startswith("{"):
            continue
        message = json.loads(line)
        if message.get("reason") != "compiler-artifact":
            continue
        executable = message.get("executable")
        if not executable or not message["profile"].get("test"):
            continue
        package_dir = os.path.dirname(message["manifest_path"])
        package = os.path.basename(package_dir)
        target = message["target"]
        kind = target["kind"][0]
        name = target["name"] if kind not in ("lib", "bin") else f"{target['name']}-{kind}"
        binaries.append(
            {
                "label": f"{package}.{name}",
                "name": target["name"],
                "executable": executable,
                "dir": package_dir,
                "manifest": message["manifest_path"],
                "package_id": message["package_id"],
            }
        )
    return binaries


def package_env(binary):
    """The variables `cargo test` sets for a test binary of this package."""
    env = dict(os.environ)
    env["CARGO_MANIFEST_DIR"] = binary["dir"]
    env["CARGO_MANIFEST_PATH"] = binary["manifest"]
    # package_id is "path+file:///dir#name@version" or "path+file:///dir#version".
    fragment = binary["package_id"].rsplit("#", 1)[-1]
    name, _, version = fragment.rpartition("@")
    env["CARGO_PKG_NAME"] = name or os.path.basename(binary["dir"])
    env["CARGO_PKG_VERSION"] = version
    return env


def order(binaries, durations):
    """Longest first: by the last run's durations when known, else by LONGEST_FIRST."""
    def key(binary):
        if binary["label"] in durations:
            return (0, -durations[binary["label"]])
        if binary["name"] in LONGEST_FIRST:
            return (1, LONGEST_FIRST.index(binary["name"]))
        return (2, 0)

    return sorted(binaries, key=key)


def run(binary, log_dir):
    log = os.path.join(log_dir, binary["label"] + ".log")
    start = time.monotonic()
    with open(log, "w") as out:
        out.write(f"     Running {binary['label']} ({binary['executable']})\n")
        out.flush()
        status = subprocess.call(
            [binary["executable"]],
            cwd=binary["dir"],
            env=package_env(binary),
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    return binary, status, time.monotonic() - start, log


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    log_dir = sys.argv[1]
    jobs = int(sys.argv[2]) if len(sys.argv) == 3 else (os.cpu_count() or 2)
    os.makedirs(log_dir, exist_ok=True)
    binaries = test_binaries(sys.stdin)
    if not binaries:
        sys.exit("test-binaries: no test executables in cargo's messages")
    durations_path = os.path.join(log_dir, DURATIONS_FILE)
    try:
        with open(durations_path) as f:
            durations = json.load(f)
    except (OSError, ValueError):
        durations = {}
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        results = list(pool.map(lambda b: run(b, log_dir), order(binaries, durations)))
    failed = []
    for binary, status, seconds, log in sorted(results, key=lambda r: r[0]["label"]):
        with open(log) as f:
            sys.stdout.write(f.read())
        if status != 0:
            failed.append(binary["label"])
        durations[binary["label"]] = round(seconds, 1)
    with open(durations_path, "w") as f:
        json.dump(durations, f, indent=1, sort_keys=True)
    slowest = sorted(results, key=lambda r: -r[2])[:5]
    print("test binaries: %d run, %d jobs; slowest: %s" % (
        len(results), jobs, ", ".join(f"{r[0]['label']} {r[2]:.0f} s" for r in slowest)))
    if failed:
        print("test binaries failed: " + ", ".join(failed))
        sys.exit(1)


if __name__ == "__main__":
    main()
