"""The bench's CAN protocol: CiA 402 constants, the DBC/EDS files, and a fast frame codec built from the DBC.

Source of truth for frame layouts is `reeve_fmu/data/reeve_drive.dbc` (read with cantools); the drive's
object dictionary and default PDO mapping is `reeve_fmu/data/reeve_drive.eds` (read with canopen). The
two describe the same bytes: RPDO1 = TorqueCmd, RPDO2 = VelocityCmd, TPDO1 = DriveStatus,
TPDO2 = DriveFeedback, TPDO3 = PlantStatus (tests/hil/test_hil.py checks the EDS mapping against the DBC).

cantools' general encoder and decoder cost a large share of a 1 kHz cycle that moves 6-7 frames, so
`FrameCodec` compiles each DBC message into shifts and masks on one Python int (little-endian signals
only, several times faster). Its results equal cantools' bit for bit (same scaling formula
`raw * scale + offset`, same round-half-even on encode), which the tests check on random values.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
DBC_PATH = DATA_DIR / "reeve_drive.dbc"
EDS_PATH = DATA_DIR / "reeve_drive.eds"

# --- node ids and COB-IDs (CiA 301 predefined connection set) -------------------------------------
DRIVE_NODE_ID = 1
CONTROLLER_NODE_ID = 0x10
COB_NMT = 0x000
COB_SYNC = 0x080
COB_EMCY = 0x080 + DRIVE_NODE_ID
COB_TPDO1 = 0x180 + DRIVE_NODE_ID       # DriveStatus
COB_TPDO2 = 0x280 + DRIVE_NODE_ID       # DriveFeedback
COB_TPDO3 = 0x380 + DRIVE_NODE_ID       # PlantStatus
COB_RPDO1 = 0x200 + DRIVE_NODE_ID       # TorqueCmd
COB_RPDO2 = 0x300 + DRIVE_NODE_ID       # VelocityCmd
COB_SDO_TX = 0x580 + DRIVE_NODE_ID      # drive -> client
COB_SDO_RX = 0x600 + DRIVE_NODE_ID      # client -> drive
COB_HB_DRIVE = 0x700 + DRIVE_NODE_ID
COB_HB_CONTROLLER = 0x700 + CONTROLLER_NODE_ID

#: frames the bench sends (it ignores them when a transport echoes its own frames, e.g. udp_multicast)
BENCH_TX = frozenset({COB_SYNC, COB_EMCY, COB_TPDO1, COB_TPDO2, COB_TPDO3, COB_SDO_TX, COB_HB_DRIVE})

# --- units of the default object dictionary ---------------------------------------------------------
INC_PER_REV = 1 << 20                    # 0x608F: encoder increments per motor revolution
RAD_PER_INC = 2.0 * math.pi / INC_PER_REV
RATED_TORQUE = 550.0                     # 0x6076 = 550000 mN m (R1 machine, docs/reference-sets.md §1)
NM_PER_PERMILLE = RATED_TORQUE / 1000.0  # 0.55 N m per unit of 0x6071/0x6077
SYNC_COUNTER_MAX = 240                   # 0x1019

# --- NMT ----------------------------------------------------------------------------------------------
NMT_START, NMT_STOP, NMT_PREOP, NMT_RESET_NODE, NMT_RESET_COMM = 0x01, 0x02, 0x80, 0x81, 0x82
NMT_STATE_BOOT, NMT_STATE_STOPPED, NMT_STATE_OPERATIONAL, NMT_STATE_PREOP = 0x00, 0x04, 0x05, 0x7F

# --- CiA 402 ------------------------------------------------------------------------------------------
MODE_CSV = 9
MODE_CST = 10
SUPPORTED_MODES = (MODE_CSV, MODE_CST)

# FSA states (codes also used in the EMCY manufacturer data and the results.csv `hil.state` column)
(S_NOT_READY, S_SWITCH_ON_DISABLED, S_READY_TO_SWITCH_ON, S_SWITCHED_ON, S_OPERATION_ENABLED,
 S_QUICK_STOP_ACTIVE, S_FAULT_REACTION_ACTIVE, S_FAULT) = range(8)
STATE_NAMES = ("NOT READY TO SWITCH ON", "SWITCH ON DISABLED", "READY TO SWITCH ON", "SWITCHED ON",
               "OPERATION ENABLED", "QUICK STOP ACTIVE", "FAULT REACTION ACTIVE", "FAULT")
# statusword bits 0-6 of each state (bit 4 "voltage enabled" with the DC link on)
STATE_SW = (0x0000, 0x0040, 0x0031, 0x0033, 0x0037, 0x0017, 0x001F, 0x0008)
SW_WARNING = 0x0080
SW_BRAKE_RELEASED = 0x0100              # manufacturer-specific bit 8
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_FOLLOWING = 0x1000                   # CSx: the drive follows the command value

CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_FAULT_RESET = 0x0080

# EMCY error codes (CiA 301 / 402)
ERR_NONE = 0x0000
ERR_RPDO_TIMEOUT = 0x8250
ERR_HEARTBEAT = 0x8130
ERR_PLANT = 0x5000
ERR_SYNC = 0x8100                        # communication, generic: SYNC from the controller lost


def state_from_statusword(sw: int) -> int:
    """FSA state code from a statusword (the masks of CiA 402 / canopen's State402)."""
    if sw & 0x4F == 0x40:
        return S_SWITCH_ON_DISABLED
    if sw & 0x4F == 0x08:
        return S_FAULT
    if sw & 0x4F == 0x0F:
        return S_FAULT_REACTION_ACTIVE
    if sw & 0x4F == 0x00:
        return S_NOT_READY
    low = sw & 0x6F
    return {0x21: S_READY_TO_SWITCH_ON, 0x23: S_SWITCHED_ON, 0x27: S_OPERATION_ENABLED,
            0x07: S_QUICK_STOP_ACTIVE}.get(low, S_NOT_READY)


def controlword_for(state: int, target: int = S_OPERATION_ENABLED) -> int:
    """The controlword that moves a drive from `state` one step towards `target` (enable or disable)."""
    if target == S_OPERATION_ENABLED:
        return {S_SWITCH_ON_DISABLED: CW_SHUTDOWN, S_READY_TO_SWITCH_ON: CW_SWITCH_ON,
                S_SWITCHED_ON: CW_ENABLE_OPERATION, S_OPERATION_ENABLED: CW_ENABLE_OPERATION,
                S_QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE}.get(state, CW_DISABLE_VOLTAGE)
    return CW_DISABLE_VOLTAGE


def sync_counter(k: int) -> int:
    """SYNC counter of cycle k (k = 0, 1, ...): 1..240, wrapping."""
    return k % SYNC_COUNTER_MAX + 1


# --- codec -------------------------------------------------------------------------------------------
class CodecError(ValueError):
    """A frame cannot be encoded (value out of the DBC range) or decoded (wrong length)."""


class FrameCodec:
    """Encode/decode one DBC message; values are sequences in the DBC's signal order.

    The DBC layout is compiled into straight-line Python around one `struct` format: signals that are
    byte-aligned with 8/16/32/64 bits become struct fields, signals inside a single byte (flags) are
    shifted out of that byte. Other layouts are refused (the bench's DBC has none)."""

    def __init__(self, message):
        import struct

        self.name = message.name
        self.frame_id = message.frame_id
        self.length = message.length
        self.names = tuple(s.name for s in message.signals)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.scales = tuple(s.scale for s in message.signals)
        self.offsets = tuple(s.offset for s in message.signals)
        limits, type_limits = [], []
        fields = {}        # byte offset -> (struct char, [(signal index, bit shift, length)])
        for i, s in enumerate(message.signals):
            if s.byte_order != "little_endian" or s.is_float:
                raise ValueError(f"{message.name}.{s.name}: only little-endian integer signals are supported")
            lo_t = -(1 << (s.length - 1)) if s.is_signed else 0
            hi_t = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
            lo, hi = lo_t, hi_t
            if s.minimum is not None:
                lo = max(lo, math.ceil((s.minimum - s.offset) / s.scale - 1e-9))
            if s.maximum is not None:
                hi = min(hi, math.floor((s.maximum - s.offset) / s.scale + 1e-9))
            limits.append((lo, hi))
            type_limits.append((lo_t, hi_t))
            b0, b1 = s.start // 8, (s.start + s.length - 1) // 8
            if s.start % 8 == 0 and s.length in (8, 16, 32, 64):
                ch = {8: "b", 16: "h", 32: "i", 64: "q"}[s.length]
                fields[b0] = (ch if s.is_signed else ch.upper(), [(i, 0, s.length)])
            elif b0 == b1:
                ch, members = fields.setdefault(b0, ("B", []))
                if ch != "B":
                    raise ValueError(f"{message.name}.{s.name}: overlaps another signal")
                members.append((i, s.start % 8, s.length))
            else:
                raise ValueError(f"{message.name}.{s.name}: layout not supported by FrameCodec")
        self.limits = tuple(limits)
        self.type_limits = tuple(type_limits)
        fmt, order, pos = "<", [], 0
        for b0 in sorted(fields):
            if b0 < pos:
                raise ValueError(f"{message.name}: overlapping signals at byte {b0}")
            fmt += "x" * (b0 - pos)
            ch, members = fields[b0]
            fmt += ch
            pos = b0 + struct.calcsize("<" + ch)
            order.append((ch, members))
        fmt += "x" * (self.length - pos)
        if struct.calcsize(fmt) != self.length:
            raise ValueError(f"{message.name}: layout does not fill {self.length} bytes")
        signed = [s.is_signed for s in message.signals]
        n = len(self.names)
        # ---- generated code
        enc = ["def encode(v, strict=True):"]
        for i in range(n):
            sc, off = self.scales[i], self.offsets[i]
            expr = f"v[{i}]" if off == 0 else f"(v[{i}] - {off!r})"
            enc.append(f"    r{i} = round({expr})" if sc == 1 else f"    r{i} = round({expr} / {sc!r})")
            lo, hi = limits[i]
            lo_t, hi_t = type_limits[i]
            if (lo, hi) == (lo_t, hi_t):
                enc.append(f"    if r{i} < {lo} or r{i} > {hi}:")
            else:
                enc.append(f"    if r{i} < {lo_t} or r{i} > {hi_t} or (strict and (r{i} < {lo} or r{i} > {hi})):")
            enc.append(f"        raise CodecError('{self.name}.{self.names[i]} = %r is outside the DBC range' % (v[{i}],))")
        packs = []
        for j, (ch, members) in enumerate(order):
            if len(members) == 1 and members[0][1] == 0 and ch != "B" or (ch == "B" and len(members) == 1
                                                                         and members[0][2] == 8):
                packs.append(f"r{members[0][0]}")
            else:
                packs.append("(" + " | ".join(f"((r{i} & {(1 << ln) - 1}) << {sh})" for i, sh, ln in members) + ")")
        enc.append(f"    return _pack({', '.join(packs)})")
        dec = ["def decode_raw(data):",
               f"    if len(data) != {self.length}:",
               f"        raise CodecError('{self.name}: %d data bytes, expected {self.length}' % len(data))",
               f"    {''.join(f'f{j}, ' for j in range(len(order)))}= _unpack(data)"]
        outs = [None] * n
        for j, (ch, members) in enumerate(order):
            for i, sh, ln in members:
                if ch != "B" or ln == 8:
                    outs[i] = f"f{j}"
                else:
                    e = f"((f{j} >> {sh}) & {(1 << ln) - 1})"
                    if signed[i]:
                        e = f"({e} - ({e} >> {ln - 1} << {ln}))"
                    outs[i] = e
        dec.append(f"    return [{', '.join(outs)}]")
        phys = []
        for i in range(n):
            sc, off = self.scales[i], self.offsets[i]
            if sc == 1 and off == 0 and isinstance(sc, int) and isinstance(off, int):
                phys.append(f"r[{i}]")
            else:
                phys.append(f"r[{i}] * {sc!r} + {off!r}")
        dec += ["def decode(data):", "    r = decode_raw(data)", f"    return [{', '.join(phys)}]"]
        ns = {"_pack": struct.Struct(fmt).pack, "_unpack": struct.Struct(fmt).unpack, "CodecError": CodecError}
        self.source = "\n".join(enc + dec) + "\n"
        exec(compile(self.source, f"<FrameCodec {self.name}>", "exec"), ns)
        self.encode = ns["encode"]
        self.decode_raw = ns["decode_raw"]
        self.decode = ns["decode"]

    def physical(self, raws: Sequence[int]) -> list:
        return [r * s + o if not (s == 1 and o == 0) else r for r, s, o in zip(raws, self.scales, self.offsets)]

    def in_range(self, raws: Sequence[int]) -> str | None:
        """None if every raw value lies in the DBC [min|max], else the first offending signal's name."""
        for r, (lo, hi), name in zip(raws, self.limits, self.names):
            if r < lo or r > hi:
                return name
        return None

    def raw_limits(self, name: str) -> tuple[int, int]:
        return self.limits[self.index[name]]


class Protocol:
    """The DBC loaded through cantools plus a FrameCodec per message (attributes by message name)."""

    def __init__(self, dbc_path: str | Path = DBC_PATH):
        import cantools

        self.db = cantools.database.load_file(str(dbc_path))
        self.codecs = {m.name: FrameCodec(m) for m in self.db.messages}
        self.by_id = {c.frame_id: c for c in self.codecs.values()}
        for name, c in self.codecs.items():
            setattr(self, name, c)


_PROTOCOL: Protocol | None = None


def protocol() -> Protocol:
    """The shared Protocol of the packaged DBC (loaded once per process)."""
    global _PROTOCOL
    if _PROTOCOL is None:
        _PROTOCOL = Protocol()
    return _PROTOCOL


def load_eds(node_id: int = DRIVE_NODE_ID):
    """The drive's object dictionary from the packaged EDS (canopen ObjectDictionary)."""
    import canopen

    return canopen.import_od(str(EDS_PATH), node_id=node_id)
