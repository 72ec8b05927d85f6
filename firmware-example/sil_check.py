#!/usr/bin/env python3
"""The firmware's vehicle computer in the loop, driven by an independent client:
python-can's `slcan` interface on the board's UART, frames written and read with cantools
and the DBC (every CRC computed here), the vehicle's motion integrated here.

  sil_check.py ELF BOARD OUT      BOARD: an386, an500 or an505; OUT: the decoded defmt log
  sil_check.py --channel URL      a board already running the program, on a serial port
                                  (e.g. /dev/ttyUSB0@115200, or socket://HOST:PORT)

QEMU runs ELF (`-icount shift=3,sleep=off`) with its UART 0 on a local TCP port, which
python-can opens as `socket://127.0.0.1:PORT` (pyserial's URL handler): the same client
code drives a USB-CAN adapter or `slcand`'s pty. The world: a two-lane road, the vehicle
(id 2) at 15 m/s in lane 0 asked for lane 1, a stopped car (id 1, not cooperating, no
braking limit: a wall) 60 m ahead in its lane, and a car (id 3) 40 m ahead in lane 1 at
15 m/s. Each period: the vehicle's measured state (Ego) goes out and its V2V state must
come back; then the two cars' states and the tick (Sync), and its command must come back;
the command's f32 speed and yaw rate are integrated exactly (the unicycle (1)). Exit 0
only if the vehicle reached lane 1, never overlapped a car, every command was planned
(solved, reused or standing still), the firmware answered every message, and the
firmware itself exited 0 (every period within 10 ms of its virtual clock, nothing
refused)."""
import hashlib
import math
import struct
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import cantools

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "can-gateway" / "tools"))
from check_candump import crc8_j1850  # noqa: E402  (the DBC test's own CRC)

H = 0.01
CLOCK, EGO_ID = 0xF0, 2
LANE_W, LENGTH, WIDTH = 3.6, 4.5, 1.8
PERIODS = int(os.environ.get("SIL_PERIODS", "500"))
CPUS = {"an386": "cortex-m4", "an500": "cortex-m7", "an505": "cortex-m33"}
PLANNED = {0, 1, 3}  # solved, reused, standing behind a stopped vehicle (CommandStatus)


class Wire:
    """Messages of can-gateway's protocol as frames, from the DBC: the identifier's kind
    and index, byte 0's header, the signals, and the CRC-8 over the whole payload."""

    def __init__(self, dbc):
        self.db = cantools.database.load_file(dbc, frame_id_mask=0x1FFFFF00)

    def frames(self, name, sa, counter, frames):
        """`frames`: one signal dict per classic frame of message `name`."""
        n = len(frames)
        msgs = [self.db.get_message_by_name(f"{name}_F{i}" if n > 1 else name) for i in range(n)]
        kind = (msgs[0].frame_id >> 12) & 0x0F
        datas = []
        for i, (m, sig) in enumerate(zip(msgs, frames)):
            full = {s.name: 0 for s in m.signals}
            full.update(sig, AliveCounter=counter, FrameIndex=i)
            datas.append(bytearray(m.encode(full, scaling=True, strict=False)))
        payload = b"".join(bytes(d[1:]) for d in datas)
        datas[-1][7] = crc8_j1850(bytes([kind, sa, counter]) + payload[:-1]) ^ 0xFF
        return [can.Message(arbitration_id=(m.frame_id & 0x1FFFFF00) | sa, is_extended_id=True,
                            data=bytes(d)) for m, d in zip(msgs, datas)]

    def decode(self, frames):
        """Signals of a whole message's frames, its CRC checked."""
        sa = frames[0].arbitration_id & 0xFF
        kind = (frames[0].arbitration_id >> 12) & 0x0F
        payload = b"".join(bytes(f.data[1:]) for f in frames)
        counter = frames[0].data[0] & 0x0F
        if crc8_j1850(bytes([kind, sa, counter]) + payload[:-1]) ^ 0xFF != payload[-1]:
            raise ValueError(f"bad CRC from {sa:#x}")
        out = {}
        for f in frames:
            m = self.db.get_message_by_frame_id(f.arbitration_id & 0x1FFFFF00)
            out.update(m.decode(f.data, decode_choices=False))
        return out


def state(vid, x, y, v, lane, t, cooperative, brake=0.0, length=0.0, beta=15):
    """A State message's signals, frame by frame."""
    return [
        {"VehicleId": vid, "X": x, "Lane": lane, "LaneChangeTo": 15},
        {"Y": y, "Heading": 0.0, "Speed": v, "IntendedLane": beta,
         "NotCooperative": 0 if cooperative else 1},
        {"YawRate": 0.0, "Timestamp": t, "BrakeLimit": brake},
        {"Length": length},
    ]


def ego(q, v, w, lane, t):
    """An Ego message: the vehicle's measured pose, speed and yaw rate, road, mission."""
    x, y, th = q
    return [
        {"VehicleId": EGO_ID, "Segment": 0, "Lane": lane, "LaneChangeTo": 15, "IntendedLane": 1,
         "BrakeLimit": 0},
        {"X": x, "Y": y, "Length": 0},
        {"Heading": math.degrees(th), "Speed": v, "YawRate": math.degrees(w), "RoadLanes": 2},
        {"Timestamp": t, "VRef": 15.0},
    ]


def unicycle(q, v, w):
    """(1) over one period with constant v and w, exactly."""
    x, y, th = q
    if abs(w) < 1e-9:
        return x + v * H * math.cos(th), y + v * H * math.sin(th), th
    th2 = th + w * H
    return x + v / w * (math.sin(th2) - math.sin(th)), y - v / w * (math.cos(th2) - math.cos(th)), th2


def overlap(a, b):
    """Whether two headings-near-zero vehicles' rectangles (centre x, y) overlap."""
    return abs(a[0] - b[0]) < LENGTH and abs(a[1] - b[1]) < WIDTH


def receive(bus, n, kind):
    """The next `n` frames of message kind `kind` from the vehicle (2 s at most)."""
    got, deadline = [], time.monotonic() + 2.0
    while len(got) < n:
        m = bus.recv(timeout=max(0.0, deadline - time.monotonic()))
        if m is None:
            raise TimeoutError(f"no answer of kind {kind} from the firmware")
        if (m.arbitration_id >> 12) & 0x0F == kind and m.arbitration_id & 0xFF == EGO_ID:
            got.append(m)
    return got


def drive(bus, wire):
    """Plays the world; returns (periods, lane-1 reached at, smallest x gap, statuses, the
    commands' digest: SHA-256 over each period's f32 speed and yaw rate bits)."""
    q, v, w, lane = (0.0, 1.8, 0.0), 15.0, 0.0, 0
    digest = hashlib.sha256()
    reached, min_gap, statuses = None, math.inf, set()
    t0 = 3600.0  # the world's clock: an hour in, in seconds
    for k in range(PERIODS + 1):
        t = t0 + k * H
        car3 = (40.0 + 15.0 * H * k, 5.4)
        for f in wire.frames("Ego", CLOCK, k % 16, ego(q, v, w, lane, t)):
            bus.send(f)
        st = wire.decode(receive(bus, 4, 1))
        assert st["VehicleId"] == EGO_ID and abs(st["X"] - q[0]) < 0.006, st
        lane = int(st["Lane"])
        for f in wire.frames("VehicleState", 1, k % 16, state(1, 60.0, 1.8, 0.0, 0, t, False)):
            bus.send(f)
        for f in wire.frames("VehicleState", 3, k % 16,
                             state(3, car3[0], car3[1], 15.0, 1, t, True, 7.9, 4.5)):
            bus.send(f)
        last = k == PERIODS
        for f in wire.frames("Sync", CLOCK, k % 16, [{"Period": k, "Last": int(last)}]):
            bus.send(f)
        cmd = wire.decode(receive(bus, 2, 11))
        assert cmd["Period"] == k % 65536, cmd
        statuses.add(int(cmd["Status"]))
        v, w = float(cmd["Speed"]), float(cmd["YawRate"])
        digest.update(struct.pack("<Iff", k, v, w))
        q = unicycle(q, v, w)
        for other in ((60.0, 1.8), car3):
            if overlap((q[0], q[1]), other):
                raise AssertionError(f"period {k}: the vehicle at {q} overlaps a car at {other}")
        min_gap = min(min_gap, 60.0 - q[0] - LENGTH if abs(q[1] - 1.8) < WIDTH else math.inf)
        if reached is None and abs(q[1] - 5.4) < 0.1 and abs(q[2]) < 0.01:
            reached = k
    return PERIODS + 1, reached, min_gap, statuses, digest.hexdigest()


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def open_bus(url):
    """python-can's slcan interface on `url`. pyserial's socket:// leaves Nagle's
    algorithm on, so each frame line would wait for the last one's delayed ACK (40 ms); a
    serial port has no such delay."""
    bus = can.Bus(interface="slcan", channel=url, bitrate=500000, sleep_after_open=0)
    sock = getattr(bus.serialPortOrig, "_socket", None)
    if sock is not None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return bus


def on_board(url):
    """Drives a board already running the program (its log is its debug probe's)."""
    bus = open_bus(url)
    wire = Wire(str(HERE.parent / "can-gateway" / "can-gateway.dbc"))
    try:
        periods, reached, min_gap, statuses, digest = drive(bus, wire)
    finally:
        bus.shutdown()
    print(f"sil_check ({url}): {periods} periods, lane 1 reached at period {reached}, "
          f"smallest gap to the stopped car {min_gap:.2f} m, command statuses {sorted(statuses)}")
    print(f"sil_check: commands sha256 {digest}")
    return 0 if reached is not None and statuses <= PLANNED else 1


def one_core():
    """Confines QEMU (run in its child before exec) to one of the cores this process may
    use: the board's UART holds one byte, and QEMU's I/O and vCPU threads hand each byte
    to each other, which across two cores cost host-sim's runs 2.2 times the CPU
    (host-sim/src/firmware/affinity.rs). Under `taskset -c N` that core is N."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def main(argv):
    if len(argv) == 3 and argv[1] == "--channel":
        return on_board(argv[2])
    if len(argv) != 4 or argv[2] not in CPUS:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    elf, board, out = argv[1], argv[2], argv[3]
    port = free_port()
    raw = Path(out).with_suffix(".raw")
    qemu = subprocess.Popen(
        ["qemu-system-arm", "-machine", f"mps2-{board}", "-cpu", CPUS[board], "-nographic",
         "-monitor", "none", "-semihosting-config", "enable=on,target=native",
         "-icount", "shift=3,sleep=off",
         "-serial", f"tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on", "-kernel", elf],
        stdout=open(raw, "wb"), stderr=subprocess.PIPE, preexec_fn=one_core)
    bus = None
    for _ in range(100):  # QEMU listens once it has loaded the image
        try:
            bus = open_bus(f"socket://127.0.0.1:{port}")
            break
        except can.CanInitializationError:
            time.sleep(0.1)
    if bus is None:
        qemu.kill()
        print("sil_check: QEMU's UART socket never opened", file=sys.stderr)
        return 1
    wire = Wire(str(HERE.parent / "can-gateway" / "can-gateway.dbc"))
    start = time.monotonic()
    try:
        periods, reached, min_gap, statuses, digest = drive(bus, wire)
    finally:
        bus.shutdown()
    status = qemu.wait(timeout=60)
    with open(out, "w") as log:
        subprocess.run(["defmt-print", "-e", elf, "--log-format", "{s}"], stdin=open(raw, "rb"),
                       stdout=log, check=False)
    print(Path(out).read_text(), end="")
    print(f"sil_check ({board}): {periods} periods in {time.monotonic() - start:.1f} s, "
          f"lane 1 reached at period {reached}, smallest gap to the stopped car "
          f"{min_gap:.2f} m, command statuses {sorted(statuses)}, firmware exit {status}")
    print(f"sil_check: commands sha256 {digest}")
    ok = status == 0 and reached is not None and statuses <= PLANNED
    if not ok:
        print("sil_check: FAILED", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
