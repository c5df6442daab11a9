"""Skin data of the skinbox interface box in numpy.

Records and full samples from pcap and pcapng captures (:func:`read`, :func:`samples`),
live capture as batches of records (:class:`Capture`), the box's commands (:class:`Box`)
and an emulated box for notebooks and tests (:func:`emulate`). Every record comes from
the same decoder as the ``skinbox`` command's; see docs/python.md.
"""

from __future__ import annotations

import ipaddress
import os
from typing import Dict, NamedTuple, Optional, Union

import numpy as np

from ._native import (
    CHANNEL_UNITS,
    CHANNELS,
    HOST_TIME_EXCHANGES,
    HOST_TIME_NONE,
    HOST_TIME_RECEIVE_STAMPS,
    KIND_DATA,
    KIND_EVENT,
    RECORD_DTYPE,
    SAMPLE_DTYPE,
    UNITS_PER_LSB,
    BadInputError,
    Box,
    BoxError,
    BoxRefusedError,
    Capture,
    CaptureError,
    CaptureFileError,
    Emulator,
    EmulatorError,
    SkinboxError,
    write_bench_capture,
    write_synthetic_capture,
)
from . import _native

__all__ = [
    "CHANNELS",
    "CHANNEL_UNITS",
    "UNITS_PER_LSB",
    "KIND_DATA",
    "KIND_EVENT",
    "HOST_TIME_NONE",
    "HOST_TIME_RECEIVE_STAMPS",
    "HOST_TIME_EXCHANGES",
    "RECORD_DTYPE",
    "SAMPLE_DTYPE",
    "Decoded",
    "CellKey",
    "read",
    "Reader",
    "read_chunks",
    "samples",
    "Capture",
    "Box",
    "Emulator",
    "emulate",
    "SkinboxError",
    "CaptureFileError",
    "BadInputError",
    "BoxError",
    "BoxRefusedError",
    "CaptureError",
    "EmulatorError",
    "write_synthetic_capture",
    "write_bench_capture",
]

PathLike = Union[str, "os.PathLike[str]"]


class Decoded(NamedTuple):
    """The records of a capture and its report."""

    records: np.ndarray
    """One row per record (cell packet) in decoding order, dtype :data:`RECORD_DTYPE`."""
    report: dict
    """Losses per box, box counters, bad input by reason, rates, host times."""


class CellKey(NamedTuple):
    """A cell of :func:`samples`: its box (box id and source address: two boxes that share
    an id are two boxes) and its cell id. A plain tuple
    ``(box_id, source_ip, source_port, cell_id)`` finds the same entry."""

    box_id: int
    source_ip: int
    """The box's IPv4 source address as an integer (0 where unknown), as in the rows."""
    source_port: int
    """The box's UDP source port (0 where unknown)."""
    cell_id: int

    @property
    def source(self) -> str:
        """The box's source address as ``"IP:port"`` (as ``skinbox decode`` prints it)."""
        return f"{ipaddress.IPv4Address(self.source_ip)}:{self.source_port}"


def _bad_input(report: dict) -> Optional[str]:
    bad = report.get("bad_input", {})
    if not bad.get("total"):
        return None
    reasons = ", ".join(f"{reason}: {n}" for reason, n in sorted(bad["by_reason"].items()))
    examples = "; ".join(bad.get("examples", [])[:3])
    return f"{bad['total']} bad input ({reasons}); first: {examples}"


def _strict(kind: str, rows: np.ndarray, report: dict, strict: bool) -> None:
    reason = _bad_input(report) if strict else None
    if reason is not None:
        error = BadInputError(f"{kind}: {reason}")
        error.rows = rows
        error.report = report
        raise error


def read(
    path: PathLike,
    *,
    sample_rate_hz: Optional[float] = None,
    udp_port: Optional[int] = None,
    cells_per_bus: Optional[int] = None,
    synced: bool = False,
    times: bool = True,
    strict: bool = True,
) -> Decoded:
    """Every record of a pcap or pcapng capture, and its report.

    ``records`` is one structured array (:data:`RECORD_DTYPE`): box id, port, cell id,
    kind (:data:`KIND_DATA` or :data:`KIND_EVENT`), box tick and box time, the sample's
    box time, host time with its error bound and source, sample index, the nine channels
    in physical units (``values``, NaN where an event packet has none; ``mask`` says which
    are present), the cell's event sequence number and the datagram's. ``report`` is the
    report of ``skinbox stats --json`` as plain Python objects, with ``host_times``.

    ``sample_rate_hz``: the cells' rate (default: learned from the stamps);
    ``udp_port``: only datagrams from or to this port; ``cells_per_bus`` and ``synced``:
    where the cells sit and whether they sample on the box's grid, for the sample times;
    ``times=False``: no sample and host times (``sample_box_time_ns`` NaN,
    ``sample_index`` -1, no host time), which saves most of the decoding time. With the
    rate given (or no times) the file is decoded in one pass, else in two (the first
    learns the rate), as ``skinbox decode`` does.

    Raises ``FileNotFoundError``/``OSError`` for a file that cannot be read,
    :class:`CaptureFileError` for one that is no pcap or pcapng, and, with ``strict``,
    :class:`BadInputError` when the decoder rejected anything (its ``rows`` and ``report``
    hold what was decoded); without ``strict`` the report counts the rejections.
    """
    rows, report_json = _native.read_records(
        os.fspath(path), sample_rate_hz, udp_port, cells_per_bus, synced, times
    )
    import json

    report = json.loads(report_json)
    _strict(os.fspath(path), rows, report, strict)
    return Decoded(rows, report)


class Reader:
    """The records of a pcap or pcapng in batches written into one reused buffer.

    Iterate it for record arrays (:data:`RECORD_DTYPE`, the rows of :func:`read` in the
    same order, at most ``rows`` a batch). Each batch is a view of the reader's buffer and
    the next batch overwrites it: copy what you keep (``batch.copy()``). Rewriting rows
    that were touched before spares the cost of fresh memory, about half of :func:`read`'s
    time without times. After the last batch :attr:`report` holds the report of
    :func:`read`. Options and errors as :func:`read`; with ``strict`` the
    :class:`BadInputError` comes after the last batch (its ``rows`` empty). Take the
    batches in one thread: ``next`` while another thread takes one raises ``RuntimeError``.
    """

    def __init__(
        self,
        path: PathLike,
        rows: int = 65536,
        *,
        sample_rate_hz: Optional[float] = None,
        udp_port: Optional[int] = None,
        cells_per_bus: Optional[int] = None,
        synced: bool = False,
        times: bool = True,
        strict: bool = True,
    ) -> None:
        self._path = os.fspath(path)
        self._strict = strict
        self._native = _native.Reader(
            self._path, rows, sample_rate_hz, udp_port, cells_per_bus, synced, times
        )
        self.report: Optional[dict] = None
        """The report once every batch was taken, else None."""

    def __iter__(self) -> "Reader":
        return self

    def __next__(self) -> np.ndarray:
        batch = next(self._native, None)
        if batch is not None:
            return batch
        if self.report is None:
            import json

            self.report = json.loads(self._native.report_json)
            empty = np.empty(0, dtype=RECORD_DTYPE)
            _strict(self._path, empty, self.report, self._strict)
        raise StopIteration


read_chunks = Reader
"""Another name of :class:`Reader`: ``for batch in skinbox.read_chunks(path): ...``."""


def samples(
    path: PathLike,
    *,
    sample_rate_hz: Optional[float] = None,
    udp_port: Optional[int] = None,
    cells_per_bus: Optional[int] = None,
    synced: bool = False,
    times: bool = True,
    strict: bool = True,
) -> Dict[CellKey, np.ndarray]:
    """The full nine-channel samples of every cell of a capture (event to data).

    One sample per record: the cell's state after that packet. Returns a dict from
    :class:`CellKey` ``(box_id, source_ip, source_port, cell_id)`` (a box is its id and its
    source address, as the decoder and ``skinbox stats`` count boxes) to a structured array
    (:data:`SAMPLE_DTYPE`) in decoding order: ``values`` is ``(n, 9)`` in physical units,
    with the times of :func:`read` and the masks ``updated`` (channels the packet carried),
    ``stale`` (not refreshed since an event sequence gap) and ``known`` (received at least
    once; unknown channels read 0). Options and errors as :func:`read`.
    """
    rows, report_json = _native.read_samples(
        os.fspath(path), sample_rate_hz, udp_port, cells_per_bus, synced, times
    )
    import json

    report = json.loads(report_json)
    _strict(os.fspath(path), rows, report, strict)
    if len(rows) == 0:
        return {}
    box = (
        (rows["box_id"].astype(np.uint64) << np.uint64(48))
        | (rows["source_ip"].astype(np.uint64) << np.uint64(16))
        | rows["source_port"].astype(np.uint64)
    )
    cell = rows["cell_id"]
    order = np.lexsort((cell, box))  # stable: each cell's rows stay in decoding order
    box, cell = box[order], cell[order]
    starts = np.flatnonzero(np.r_[True, (box[1:] != box[:-1]) | (cell[1:] != cell[:-1])])
    ends = np.r_[starts[1:], len(order)]
    cells: Dict[CellKey, np.ndarray] = {}
    for start, end in zip(starts, ends):
        b = int(box[start])
        key = CellKey(b >> 48, (b >> 16) & 0xFFFFFFFF, b & 0xFFFF, int(cell[start]))
        cells[key] = rows[order[start:end]]
    return cells


def emulate(
    scene: Optional[str] = None,
    listen: str = "127.0.0.1:0",
    *,
    speed: float = 1.0,
    from_ms: float = 1000.0,
    duration_ms: float = 10000.0,
    buses: Optional[int] = None,
    cells: Optional[int] = None,
    flush_timeout_us: float = 100.0,
    status_period_ms: float = 100.0,
    box_id: int = 1,
) -> Emulator:
    """An emulated box (``skinbox emulate``) serving on ``listen`` in a thread.

    Use it as a context manager: ``with skinbox.emulate("moving_arm") as box:``; the box
    stops at the end of the block (or on ``box.stop()``). ``box.address`` is its command
    address, for :class:`Box` and ``Capture(claim=...)``. ``scene``: a built-in scene's
    name or a scene file (default stroking_upper_arm); the cells send for ``duration_ms``
    of scene time from ``from_ms`` on, played at ``speed`` times real time. Raises
    :class:`EmulatorError` when the scene or the socket cannot be had.
    """
    return Emulator(
        scene,
        listen,
        speed,
        from_ms,
        duration_ms,
        buses,
        cells,
        flush_timeout_us,
        status_period_ms,
        box_id,
    )
