#!/usr/bin/env python3
"""The CAN FD messages of can-gateway.dbc, derived from its classic ones.

A CAN FD frame carries a whole message (can_gateway::wire): byte 0 is the header (frame
index 15, or 14 with an authenticator, and the alive counter), then the payload chunks of
the classic frames back to back (7 bytes each, CRC last), then for a secured frame the
SecOC trailer (16-bit freshness value, 32-bit MAC), then zeros up to the CAN FD length.
So a signal at start bit b of classic frame i sits at b + 56 i in the FD frame.

  dbc_fd.py DBC            prints the FD messages' BO_ blocks, BA_ and SIG_VALTYPE_ lines
  dbc_fd.py DBC --check    exit 1 unless the DBC's FD messages are exactly these
"""
import re
import sys

PRIORITY_PF = 0x98FF0000  # extended flag, priority 6, PDU format 0xFF
FD_INDEX, FD_SECURED_INDEX = 15, 14
FD_LENGTHS = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64]
TRAILER = [("FreshnessValue", 16, "(1,0) [0|65535] \"\""), ("Mac", 32, "(1,0) [0|4294967295] \"\"")]


def fd_len(n):
    return next(l for l in FD_LENGTHS if l >= n)


def classic_messages(text):
    """{kind: [(index, name, sender, [(signal name, start, rest of the SG_ line)])]}"""
    kinds = {}
    for block in re.findall(r"^BO_ (\d+) (\w+): 8 (\w+)\n((?: SG_ .*\n)*)", text, re.M):
        raw, name, sender, sigs = int(block[0]), block[1], block[2], block[3]
        ps = (raw >> 8) & 0xFF
        kind, index = ps >> 4, ps & 0x0F
        if index in (FD_INDEX, FD_SECURED_INDEX):
            continue
        signals = []
        for m in re.finditer(r" SG_ (\w+) : (\d+)\|(\d+)(@.*)", sigs):
            signals.append((m.group(1), int(m.group(2)), int(m.group(3)), m.group(4)))
        kinds.setdefault(kind, []).append((index, name, sender, signals))
    return kinds


def float_signals(text):
    """{frame id: [signal name]} of the signals the DBC declares IEEE float (SIG_VALTYPE_)."""
    out = {}
    for raw, name in re.findall(r"^SIG_VALTYPE_ (\d+) (\w+) : 1;", text, re.M):
        out.setdefault(int(raw), []).append(name)
    return out


def fd_blocks(text):
    out, attrs = [], []
    floats = float_signals(text)
    for kind, frames in sorted(classic_messages(text).items()):
        frames.sort()
        n = len(frames)
        base = re.sub(r"_F0$", "", frames[0][1])
        sender = frames[0][2]
        for index, suffix, extra in ((FD_INDEX, "FD", 0), (FD_SECURED_INDEX, "FD_Secured", 6)):
            raw = PRIORITY_PF | (kind << 12) | (index << 8)
            lines = [f"BO_ {raw} {base}_{suffix}: {fd_len(1 + 7 * n + extra)} {sender}",
                     ' SG_ AliveCounter : 0|4@1+ (1,0) [0|15] "" Vector__XXX',
                     ' SG_ FrameIndex : 4|4@1+ (1,0) [0|15] "" Vector__XXX']
            for i, (_, _, _, signals) in enumerate(frames):
                for name, start, length, rest in signals:
                    if name in ("AliveCounter", "FrameIndex"):
                        continue
                    lines.append(f" SG_ {name} : {start + 56 * i}|{length}{rest}")
            if extra:
                at = 8 + 56 * n
                for name, length, scale in TRAILER:
                    lines.append(f" SG_ {name} : {at}|{length}@1+ {scale} Vector__XXX")
                    at += length
            out.append("\n".join(lines) + "\n")
            attrs.append(f'BA_ "VFrameFormat" BO_ {raw} 15;')
            # A float signal of a classic frame is a float in the FD frames too.
            for index_c, _, _, _ in frames:
                classic_raw = PRIORITY_PF | (kind << 12) | (index_c << 8)
                for name in floats.get(classic_raw, []):
                    attrs.append(f"SIG_VALTYPE_ {raw} {name} : 1;")
    return out, attrs


def main(argv):
    text = open(argv[1]).read()
    blocks, attrs = fd_blocks(text)
    if "--check" in argv:
        missing = [b.splitlines()[0] for b in blocks if b not in text]
        missing += [a for a in attrs if a not in text]
        if missing:
            print("can-gateway.dbc: CAN FD messages out of date (run tools/dbc_fd.py):")
            print("\n".join(missing))
            return 1
        print(f"can-gateway.dbc: {len(blocks)} CAN FD messages match their classic frames")
        return 0
    print("\n".join(blocks))
    print("\n".join(attrs))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
