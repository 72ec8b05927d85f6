#!/usr/bin/env python3
"""Decodes a candump -l log written by can-gateway (classic and CAN FD frames) with
cantools and the DBC, checks every message's CRC-8 SAE J1850 independently, and compares the decoded physical values
with the expected ones (JSON lines: {"frame": i, "signals": {name: value}}), within
half a resolution step. Exit 0 on success, 1 with a message on the first mismatch."""
import json
import sys

import cantools


def crc8_j1850(data: bytes, crc: int = 0xFF) -> int:
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


FRAMES_PER_KIND = {}  # kind code -> frames per message, read from the DBC (frames_per_kind)
FD_INDEX, FD_SECURED_INDEX = 15, 14  # a whole message in one CAN FD frame (+ SecOC trailer)
FD_LENGTHS = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64]
TRAILER_LEN = 6


def frames_per_kind(db):
    """Classic frames per message kind, as the DBC lays them out (its identifiers: PDU
    specific = kind code x 16 + frame index; indexes 14 and 15 are CAN FD)."""
    counts = {}
    for msg in db.messages:
        ps = (msg.frame_id >> 8) & 0xFF
        if ps & 0x0F < FD_SECURED_INDEX:
            counts[ps >> 4] = counts.get(ps >> 4, 0) + 1
    return counts


def load_dbc(dbc_path):
    """The DBC as cantools reads it; the frames per kind taken from it for reassembly."""
    db = cantools.database.load_file(dbc_path, frame_id_mask=0x1FFFFF00)
    FRAMES_PER_KIND.clear()
    FRAMES_PER_KIND.update(frames_per_kind(db))
    return db


def check_crc(sa, kind, counter, body):
    want = crc8_j1850(bytes([kind, sa, counter]) + body[:-1]) ^ 0xFF
    if want != body[-1]:
        raise ValueError(
            f"CRC mismatch in message kind {kind} from {sa}: {body[-1]:#04x} != {want:#04x}")


def whole_fd(kind, index, sa, data):
    """The message body of a CAN FD frame (index 15, or 14 with a trailer), checked."""
    n = FRAMES_PER_KIND.get(kind, 1)
    used = 1 + 7 * n + (TRAILER_LEN if index == FD_SECURED_INDEX else 0)
    want = next(l for l in FD_LENGTHS if l >= used)
    if len(data) != want or any(data[used:]) or data[0] >> 4 != index:
        raise ValueError(f"malformed CAN FD frame of kind {kind} from {sa}: {data.hex()}")
    body = data[1:1 + 7 * n]
    check_crc(sa, kind, data[0] & 0x0F, body)
    return body


def reassemble(frames):
    """Reassembles (can_id, data) frames per sender and kind. Returns the whole messages
    as (sa, kind, counter, body, parts) — parts: the frames' indexes — and the (sa, kind)
    of messages left incomplete. Raises ValueError on a continuation without its first
    frame or a CRC mismatch."""
    pending = {}
    messages = []
    for i, (can_id, data) in enumerate(frames):
        kind, index, sa = (can_id >> 12) & 0x0F, (can_id >> 8) & 0x0F, can_id & 0xFF
        key = (sa, kind)
        if index in (FD_INDEX, FD_SECURED_INDEX):
            body = whole_fd(kind, index, sa, data)
            messages.append((sa, kind, data[0] & 0x0F, body, [i]))
            continue
        if index == 0:
            pending[key] = (b"", [])
        if key not in pending:
            raise ValueError(f"frame {index} of kind {kind} from {sa} without its first frame")
        body, parts = pending[key]
        pending[key] = (body + data[1:], parts + [i])
        if index == FRAMES_PER_KIND.get(kind, 1) - 1:
            body, parts = pending.pop(key)
            counter = data[0] & 0x0F
            check_crc(sa, kind, counter, body)
            messages.append((sa, kind, counter, body, parts))
    return messages, sorted(pending)


def main(dbc_path: str, log_path: str, expected_path: str) -> int:
    db = load_dbc(dbc_path)
    frames = []
    for line in open(log_path):
        line = line.strip()
        if not line:
            continue
        _ts, _iface, frame = line.split()
        can_id, data = frame.split("#", 1)
        if data.startswith("#"):  # CAN FD: ID##<flags nibble><data>
            data = data[2:]
        frames.append((int(can_id, 16), bytes.fromhex(data)))
    expected = [json.loads(l) for l in open(expected_path) if l.strip()]
    # Reassemble messages per sender, kind and counter to check their CRC.
    try:
        reassemble(frames)
    except ValueError as err:
        print(err)
        return 1
    checked = 0
    for exp in expected:
        can_id, data = frames[exp["frame"]]
        msg = db.get_message_by_frame_id(can_id)
        got = msg.decode(data, decode_choices=False)
        for name, value in exp["signals"].items():
            sig = msg.get_signal_by_name(name)
            if abs(got[name] - value) > sig.scale / 2 + 1e-9:
                print(f"frame {exp['frame']} {msg.name}.{name}: cantools {got[name]} != {value}")
                return 1
            checked += 1
    print(f"cantools decoded {len(frames)} frames; {checked} signals match")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
