"""Bad input raises a Python exception with the decoder's reason; nothing is dropped
silently."""

from __future__ import annotations

import struct

import pytest

import skinbox


def test_a_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.pcap"):
        skinbox.read(tmp_path / "nothing.pcap")


def test_a_file_that_is_no_pcap_says_so(tmp_path):
    path = tmp_path / "text.pcap"
    path.write_bytes(b"this is not a capture at all\n" * 4)
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        skinbox.read(path)
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        skinbox.samples(path)


def test_a_truncated_capture_raises_with_its_reason(captures, tmp_path):
    whole = captures["mixed"][0].read_bytes()
    path = tmp_path / "cut.pcap"
    path.write_bytes(whole[: len(whole) - 700])
    with pytest.raises(skinbox.BadInputError, match="pcap") as raised:
        skinbox.read(path)
    # what was decoded before the cut is there, and counted
    assert len(raised.value.rows) > 0
    assert raised.value.report["bad_input"]["total"] == 1
    records, report = skinbox.read(path, strict=False)
    assert len(records) == len(raised.value.rows)
    assert report["bad_input"]["total"] == 1


def test_a_corrupted_frame_raises_bad_checksum(captures, tmp_path):
    data = bytearray(captures["data"][0].read_bytes())
    # first frame: pcap header 24 bytes, record header 16; flip a byte of its first record
    frame = 24 + 16
    data[frame + 14 + 20 + 8 + 24 + 10] ^= 0xFF
    path = tmp_path / "flipped.pcap"
    path.write_bytes(bytes(data))
    with pytest.raises(skinbox.BadInputError, match="UDP checksum"):
        skinbox.read(path)
    with pytest.raises(skinbox.BadInputError, match="UDP checksum"):
        skinbox.samples(path)


def test_a_bad_record_rejects_only_itself(captures, tmp_path):
    data = bytearray(captures["data"][0].read_bytes())
    # the first records frame: walk the frames; break its first record's port, then zero
    # the UDP checksum (none over IPv4) so the frame reaches the decoder
    offset = 24
    while True:
        caplen = struct.unpack_from("<I", data, offset + 8)[0]
        udp = offset + 16 + 14 + 20
        payload = udp + 8
        if data[payload + 3] == 1:  # records datagram
            break
        offset += 16 + caplen
    data[udp + 6 : udp + 8] = b"\0\0"
    data[payload + 24] = 0xFF  # port of the first record: beyond the box's ports
    path = tmp_path / "bad_port.pcap"
    path.write_bytes(bytes(data))
    with pytest.raises(skinbox.BadInputError, match="port out of range"):
        skinbox.read(path)
    records, report = skinbox.read(path, strict=False)
    whole, _ = skinbox.read(captures["data"][0])
    assert len(records) == len(whole) - 1
    assert report["bad_input"]["by_reason"] == {"record: port out of range": 1}


def test_an_empty_file_or_a_folder_raises_with_the_reason(tmp_path):
    empty = tmp_path / "empty.pcap"
    empty.write_bytes(b"")
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        skinbox.read(empty)
    with pytest.raises(skinbox.CaptureFileError, match="not a pcap or pcapng"):
        list(skinbox.Reader(empty, times=False))
    with pytest.raises(OSError, match="Is a directory"):
        skinbox.read(tmp_path)
    with pytest.raises(OSError, match="Is a directory"):
        skinbox.Reader(tmp_path)
