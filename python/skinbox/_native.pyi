"""Type stubs of the extension module (Rust, PyO3): see the package's docstrings."""

from os import PathLike
from typing import Any, Dict, Iterator, List, Optional, Tuple, Union

import numpy as np

_Path = Union[str, "PathLike[str]"]

RECORD_DTYPE: np.dtype
"""One record (cell packet): tick, box_time_ns, sample_box_time_ns, host_time_ns,
host_time_bound_ns, sample_index, values (9 channels, units), datagram_sequence,
event_sequence, source_ip (the box's IPv4 source address as an integer, 0 where unknown),
box_id, cell_id, mask, event_packets_missing_before, source_port (0 where unknown), port,
kind, flags, second_part, host_time_source."""
SAMPLE_DTYPE: np.dtype
"""One full sample: tick, box_time_ns, sample_box_time_ns, host_time_ns,
host_time_bound_ns, sample_index, values (9 channels, units), source_ip, box_id, cell_id,
updated, stale, known, source_port, host_time_source."""
CHANNELS: List[str]
"""The nine channel names, in the order of ``values``."""
CHANNEL_UNITS: List[str]
"""The unit of each channel."""
UNITS_PER_LSB: List[float]
"""One raw step of each channel in its unit."""
KIND_DATA: int
KIND_EVENT: int
HOST_TIME_NONE: int
HOST_TIME_RECEIVE_STAMPS: int
HOST_TIME_EXCHANGES: int

class SkinboxError(Exception): ...
class CaptureFileError(SkinboxError): ...
class BadInputError(SkinboxError):
    rows: np.ndarray
    report: Dict[str, Any]
class BoxError(SkinboxError): ...
class BoxRefusedError(BoxError): ...
class EmulatorError(SkinboxError): ...
class CaptureError(SkinboxError): ...

def read_records(
    path: _Path,
    sample_rate_hz: Optional[float] = None,
    udp_port: Optional[int] = None,
    cells_per_bus: Optional[int] = None,
    synced: bool = False,
    times: bool = True,
) -> Tuple[np.ndarray, str]:
    """Every record of a capture (RECORD_DTYPE) and the report as JSON text."""

def read_samples(
    path: _Path,
    sample_rate_hz: Optional[float] = None,
    udp_port: Optional[int] = None,
    cells_per_bus: Optional[int] = None,
    synced: bool = False,
    times: bool = True,
) -> Tuple[np.ndarray, str]:
    """The sample after every record of a capture (SAMPLE_DTYPE) and the report as JSON."""

class Reader:
    """A capture decoded in batches into one reused buffer: iterate it for views of the
    buffer (RECORD_DTYPE), each overwritten by the next."""

    def __init__(
        self,
        path: _Path,
        rows: int = 65536,
        sample_rate_hz: Optional[float] = None,
        udp_port: Optional[int] = None,
        cells_per_bus: Optional[int] = None,
        synced: bool = False,
        times: bool = True,
    ) -> None: ...
    @property
    def rows(self) -> int: ...
    @property
    def report_json(self) -> Optional[str]:
        """The report as JSON text once every batch was taken, else None."""
    def __iter__(self) -> Iterator[np.ndarray]: ...
    def __next__(self) -> np.ndarray: ...

def write_synthetic_capture(
    path: _Path,
    cells: int = 64,
    ports: int = 8,
    sample_rate_hz: float = 125.0,
    samples_per_cell: int = 50,
    event_every: int = 2,
    seed: int = 1,
    box_id: int = 1,
    boxes: int = 1,
    first_sequence: int = 0,
    walk_scale: int = 1,
    flush_timeout_ticks: int = 12500,
    drop_every: int = 0,
    shared_box_id: bool = False,
) -> Dict[str, np.ndarray]:
    """A pcap of the box's reference model batching synthetic cells (``boxes`` boxes from
    10.0.0.2, 10.0.0.3, ...; ids from ``box_id`` up, or all ``box_id`` with
    ``shared_box_id``); returns the truth of every record written (box_id, source_ip,
    source_port, datagram_sequence, tick, port, cell_id, kind, mask, event_sequence,
    raw (n, 9))."""

def write_bench_capture(path: _Path, packets: int = 1000000, seed: int = 1) -> int:
    """The capture of ``skinbox bench decode`` as a pcap; returns its cell packets."""

class Box:
    """A box (or an emulated box) at its command address; each command returns its
    acknowledgement as a dict, raises BoxRefusedError when refused and BoxError when
    unanswered."""

    def __init__(
        self,
        address: str,
        timeout_ms: int = 250,
        retries: int = 3,
        box_id: Optional[int] = None,
        bind: str = "0.0.0.0:0",
    ) -> None: ...
    @property
    def address(self) -> str: ...
    @property
    def local_address(self) -> str: ...
    def status(self) -> Dict[str, Any]: ...
    def stream_to(
        self, to: Optional[str] = None, mac: str = "ff:ff:ff:ff:ff:ff"
    ) -> Dict[str, Any]: ...
    def set(self, parameter: str, value: float) -> Dict[str, Any]: ...
    def time(self) -> Dict[str, Any]: ...
    def ping(self, count: int = 4) -> List[Dict[str, Any]]: ...
    def cell_command(self, packet: bytes, port: Optional[int] = None) -> Dict[str, Any]: ...
    def cells_mode(
        self, mode: str, port: Optional[int] = None, cell: Optional[int] = None
    ) -> Dict[str, Any]: ...
    def cells_rate(
        self, hz: float, port: Optional[int] = None, cell: Optional[int] = None
    ) -> Dict[str, Any]: ...
    def cells_thresholds(
        self,
        accel_g: float = 0.02,
        force: float = 0.001,
        proximity: float = 0.0001,
        temperature_c: float = 0.5,
        port: Optional[int] = None,
        cell: Optional[int] = None,
    ) -> Dict[str, Any]: ...
    def cells_enable(
        self, channels: List[str], port: Optional[int] = None, cell: Optional[int] = None
    ) -> Dict[str, Any]: ...
    def cells_sync(
        self, tick: int, port: Optional[int] = None, cell: Optional[int] = None
    ) -> Dict[str, Any]: ...

class Emulator:
    """An emulated box serving in a thread; a context manager that stops it."""

    def __init__(
        self,
        scene: Optional[str] = None,
        listen: str = "127.0.0.1:0",
        speed: float = 1.0,
        from_ms: float = 1000.0,
        duration_ms: float = 10000.0,
        buses: Optional[int] = None,
        cells: Optional[int] = None,
        flush_timeout_us: float = 100.0,
        status_period_ms: float = 100.0,
        box_id: int = 1,
    ) -> None: ...
    @property
    def address(self) -> str: ...
    @property
    def scene(self) -> str: ...
    @property
    def ports(self) -> int: ...
    def stats(self) -> Dict[str, Any]: ...
    def stop(self) -> Dict[str, Any]: ...
    def __enter__(self) -> "Emulator": ...
    def __exit__(self, *args: Any) -> bool: ...

class Capture:
    """A live capture: iterate it for record arrays (RECORD_DTYPE)."""

    def __init__(
        self,
        listen: str = "0.0.0.0:54091",
        claim: Optional[str] = None,
        batch_records: int = 65536,
        batch_ms: int = 100,
        sample_rate_hz: Optional[float] = None,
        recv_buffer: int = 67108864,
        exchange_ms: int = 100,
        duration_ms: Optional[int] = None,
        count: Optional[int] = None,
        pcap: Optional[_Path] = None,
        cells_per_bus: Optional[int] = None,
        synced: bool = False,
        times: bool = True,
    ) -> None: ...
    @property
    def address(self) -> str: ...
    @property
    def report(self) -> Optional[Dict[str, Any]]: ...
    def __iter__(self) -> Iterator[np.ndarray]: ...
    def __next__(self) -> np.ndarray: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Capture": ...
    def __exit__(self, *args: Any) -> bool: ...

def replay_capture(
    path: _Path, to: str, datagrams_per_second: float, burst: int = 32
) -> str:
    """Sends a pcap's UDP payloads to ``to`` in bursts at a rate (as ``skinbox bench live``);
    returns what the sender did as JSON text."""
