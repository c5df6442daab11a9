"""`samples` against the generator's truth: every cell's state after each of its packets,
rebuilt here from the records the generator sent (the captures are lossless)."""

from __future__ import annotations

import numpy as np
import pytest

import skinbox


def truth_samples(truth: dict) -> dict:
    """(box_id, cell_id) -> (ticks, values (n, 9) in units, known masks, updated masks)."""
    lsb = np.asarray(skinbox.UNITS_PER_LSB)
    state = {}
    out = {}
    for i in range(len(truth["tick"])):
        key = (int(truth["box_id"][i]), int(truth["cell_id"][i]))
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


@pytest.mark.parametrize("name", ["data", "event", "mixed", "two_boxes", "pcapng"])
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
        assert np.all(rows["box_id"] == key[0]) and np.all(rows["cell_id"] == key[1])
        # on the cell's sample clock; a split sample's two packets share one sample
        assert np.all(np.diff(rows["sample_index"]) >= 0)


def test_samples_carry_the_record_times(captures):
    path, _ = captures["mixed"]
    records, _ = skinbox.read(path)
    cells = skinbox.samples(path)
    for (box_id, cell_id), rows in cells.items():
        mine = records[(records["box_id"] == box_id) & (records["cell_id"] == cell_id)]
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
