"""`samples` against the generator's truth: every cell's state after each of its packets,
rebuilt here from the records the generator sent (the captures are lossless)."""

from __future__ import annotations

import ipaddress

import numpy as np
import pytest

import skinbox
from conftest import decode_jsonl


def truth_samples(truth: dict) -> dict:
    """(box_id, source_ip, source_port, cell_id) -> (ticks, values (n, 9) in units, known
    masks, updated masks)."""
    lsb = np.asarray(skinbox.UNITS_PER_LSB)
    state = {}
    out = {}
    for i in range(len(truth["tick"])):
        key = (
            int(truth["box_id"][i]),
            int(truth["source_ip"][i]),
            int(truth["source_port"][i]),
            int(truth["cell_id"][i]),
        )
        raw, known = state.get(key, (np.zeros(9, dtype=np.int64), 0))
        raw = raw.copy()
        mask = int(truth["mask"][i])
        for c in range(9):
            if mask >> c & 1:
                raw[c] = truth["raw"][i][c]
        known |= mask
        state[key] = (raw, known)
        ticks, values, knowns, updated = out.setdefault(key, ([], [], [], []))
        ticks.append(int(truth["tick"][i]))
        values.append(raw * lsb)
        knowns.append(known)
        updated.append(mask)
    return out


@pytest.mark.parametrize(
    "name", ["data", "event", "mixed", "two_boxes", "shared_id", "pcapng"]
)
def test_samples_equal_the_truth(name, captures):
    path, truth = captures[name]
    cells = skinbox.samples(path)
    want = truth_samples(truth)
    assert set(cells) == set(want)
    for key, rows in cells.items():
        ticks, values, known, updated = want[key]
        assert rows.dtype == skinbox.SAMPLE_DTYPE
        assert rows["values"].shape == (len(ticks), 9)
        assert np.array_equal(rows["tick"], ticks)
        assert np.array_equal(rows["values"], np.asarray(values)), key
        assert np.array_equal(rows["known"], known)
        assert np.array_equal(rows["updated"], updated)
        assert not rows["stale"].any(), "a lossless capture has nothing stale"
        assert isinstance(key, skinbox.CellKey)
        assert np.all(rows["box_id"] == key.box_id)
        assert np.all(rows["source_ip"] == key.source_ip)
        assert np.all(rows["source_port"] == key.source_port)
        assert np.all(rows["cell_id"] == key.cell_id)
        # on the cell's sample clock; a split sample's two packets share one sample
        assert np.all(np.diff(rows["sample_index"]) >= 0)


def test_samples_carry_the_record_times(captures):
    path, _ = captures["mixed"]
    records, _ = skinbox.read(path)
    cells = skinbox.samples(path)
    for (box_id, ip, port, cell_id), rows in cells.items():
        mine = records[
            (records["box_id"] == box_id)
            & (records["source_ip"] == ip)
            & (records["source_port"] == port)
            & (records["cell_id"] == cell_id)
        ]
        for field in (
            "tick",
            "sample_box_time_ns",
            "host_time_ns",
            "sample_index",
            "source_ip",
            "source_port",
        ):
            assert np.array_equal(rows[field], mine[field]), field


def test_gaps_mark_channels_stale(captures):
    path, _ = captures["gaps"]
    cells = skinbox.samples(path)
    assert any(rows["stale"].any() for rows in cells.values())


def test_boxes_sharing_an_id_keep_their_own_samples(captures, skinbox_bin):
    """Two boxes with one box id from two addresses: each box's cells are its own, equal
    to the generator's truth and to `skinbox decode --samples --jsonl` of that source."""
    path, truth = captures["shared_id"]
    assert len(set(truth["box_id"].tolist())) == 1
    sources = set(zip(truth["source_ip"].tolist(), truth["source_port"].tolist()))
    assert len(sources) == 2
    cells = skinbox.samples(path)
    assert {(k.source_ip, k.source_port) for k in cells} == sources
    # the same cell ids on both boxes, each box's rows only from its own source
    for ip, port in sources:
        ids = {k.cell_id for k in cells if (k.source_ip, k.source_port) == (ip, port)}
        assert len(ids) == 48
    # against the decoder's own samples, per source, in decoding order
    want = {}
    for line in decode_jsonl(skinbox_bin, path, "--samples"):
        ip, port = line["source"].rsplit(":", 1)
        key = (line["box_id"], int(ipaddress.IPv4Address(ip)), int(port), line["cell_id"])
        want.setdefault(key, []).append(line)
    assert set(cells) == set(want)
    for key, rows in cells.items():
        lines = want[key]
        assert key.source == lines[0]["source"]
        assert len(rows) == len(lines)
        assert np.array_equal(rows["tick"], [w["tick"] for w in lines])
        for i, name in enumerate(skinbox.CHANNELS):
            assert np.array_equal(rows["values"][:, i], [w["values"][name] for w in lines])
        for mask in ("updated", "known", "stale"):
            bits = [
                sum(1 << skinbox.CHANNELS.index(c) for c in w[mask]) for w in lines
            ]
            assert np.array_equal(rows[mask], bits), mask
        assert np.array_equal(rows["sample_index"], [w["sample_index"] for w in lines])
    # merged by box id alone, the two boxes' states would mix: the keys must differ
    by_id = {(k.box_id, k.cell_id) for k in cells}
    assert len(by_id) * 2 == len(cells)
