"""`Reader` / `read_chunks`: the batches, joined, are `read`'s records field for field (and
`skinbox decode --jsonl`'s), in one buffer reused from batch to batch; bad input raises as
`read` does."""

from __future__ import annotations

import numpy as np
import pytest

import skinbox
from conftest import decode_jsonl
from test_read import assert_row_equals


def assert_same_records(got: np.ndarray, want: np.ndarray) -> None:
    assert got.dtype == want.dtype == skinbox.RECORD_DTYPE
    assert len(got) == len(want)
    for field in want.dtype.names:
        a, b = got[field], want[field]
        if a.dtype.kind == "f":
            # NaN where a value is absent: the same NaN positions, equal elsewhere
            assert np.array_equal(a, b, equal_nan=True), field
        else:
            assert np.array_equal(a, b), field


def concatenate(batches: list) -> np.ndarray:
    """The batches in one array of their dtype (np.concatenate would drop its padding)."""
    out = np.empty(sum(len(b) for b in batches), dtype=skinbox.RECORD_DTYPE)
    at = 0
    for batch in batches:
        assert batch.dtype == skinbox.RECORD_DTYPE
        out[at : at + len(batch)] = batch
        at += len(batch)
    return out


def joined(reader) -> np.ndarray:
    return concatenate([batch.copy() for batch in reader])


def without_cost(report: dict) -> dict:
    """The report less the CPU and wall time of the run."""
    return {k: v for k, v in report.items() if k != "host"}


@pytest.mark.parametrize(
    "name", ["data", "event", "mixed", "two_boxes", "shared_id", "gaps", "pcapng"]
)
@pytest.mark.parametrize(
    "options",
    [{}, {"sample_rate_hz": 125.0}, {"times": False}],
    ids=["learned_rate", "rate_given", "no_times"],
)
def test_batches_are_the_records_of_read(name, options, captures):
    path, _ = captures[name]
    records, report = skinbox.read(path, **options)
    for rows in (1, 997, len(records), len(records) + 1):
        reader = skinbox.read_chunks(path, rows, **options)
        sizes = []
        parts = []
        for batch in reader:
            sizes.append(len(batch))
            parts.append(batch.copy())
        assert sizes == [rows] * (len(records) // rows) + (
            [len(records) % rows] if len(records) % rows else []
        )
        assert_same_records(concatenate(parts), records)
        assert without_cost(reader.report) == without_cost(report)


def test_batches_equal_decode_jsonl(captures, skinbox_bin):
    path, _ = captures["mixed"]
    got = joined(skinbox.Reader(path, 100))
    want = decode_jsonl(skinbox_bin, path)
    assert len(got) == len(want) > 0
    for row, w in zip(got, want):
        assert_row_equals(row, w)


def test_every_batch_is_a_view_of_one_buffer(captures):
    path, _ = captures["mixed"]
    reader = skinbox.Reader(path, 64)
    addresses = set()
    first = None
    for batch in reader:
        addresses.add(batch.__array_interface__["data"][0])
        if first is None:
            first, kept = batch, batch.copy()
    assert len(addresses) == 1, "every batch starts at the buffer's first row"
    # the first batch's view now holds a later batch's rows
    assert not np.array_equal(first["tick"], kept["tick"])
    assert list(reader) == [], "exhausted"


def test_bad_input_raises_after_the_last_batch(captures, tmp_path):
    whole = captures["mixed"][0].read_bytes()
    path = tmp_path / "cut.pcap"
    path.write_bytes(whole[: len(whole) - 700])
    decoded, report = skinbox.read(path, strict=False)
    reader = skinbox.Reader(path, 256)
    parts = []
    with pytest.raises(skinbox.BadInputError, match="pcap: truncated") as raised:
        for batch in reader:
            parts.append(batch.copy())
    assert_same_records(concatenate(parts), decoded)
    assert raised.value.report["bad_input"]["total"] == 1
    lenient = skinbox.Reader(path, 256, strict=False)
    assert_same_records(joined(lenient), decoded)
    assert without_cost(lenient.report) == without_cost(report)


def test_files_and_options_raise_as_read_does(captures, tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.pcap"):
        skinbox.Reader(tmp_path / "nothing.pcap")
    text = tmp_path / "text.pcap"
    text.write_bytes(b"this is not a capture at all\n" * 4)
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        # with times the first pass finds it, without it the first batch
        skinbox.Reader(text)
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        list(skinbox.Reader(text, times=False))
    with pytest.raises(ValueError, match="rows"):
        skinbox.Reader(captures["data"][0], 0)
    with pytest.raises(ValueError, match="sample_rate_hz"):
        skinbox.Reader(captures["data"][0], sample_rate_hz=-1.0)


def test_a_reader_left_early_is_dropped_cleanly(captures):
    path, _ = captures["mixed"]
    for _ in range(20):
        reader = skinbox.Reader(path, 10)
        next(reader)
        del reader
    reader = skinbox.Reader(path, 10)
    del reader
    records, _ = skinbox.read(path)
    assert_same_records(joined(skinbox.Reader(path, 10)), records)


def test_a_reader_taken_from_two_threads_raises_instead_of_waiting(captures):
    """One thread waits for its batch without the GIL; another thread's `next` raises
    at once rather than wait for the reader with the GIL held."""
    import threading

    path, _ = captures["mixed"]
    records, _ = skinbox.read(path)
    reader = skinbox.Reader(path, 1)
    got, errors = [], []

    def take():
        while True:
            try:
                batch = next(reader)
            except StopIteration:
                return
            except RuntimeError as e:
                errors.append(str(e))
                continue
            got.append(batch.copy())

    threads = [threading.Thread(target=take) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert not any(t.is_alive() for t in threads), "no deadlock"
    assert all("another thread" in e for e in errors)
    assert len(got) == len(records)
