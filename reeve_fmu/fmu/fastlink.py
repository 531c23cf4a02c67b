"""Tables a `ReeveSlave` shares with the FMU's native loader, so that setReal and getReal of the
exchanged values run without Python and doStep without pythonfmu's C++ layer.

The loader (reeve_fmu/fmu/native/fmu_loader.c, item 5 of its header; struct ReeveLink there has the
same layout as `_Link` here) puts a list into `sys` while pythonfmu constructs the slave; the slave
appends itself (`offer`), the loader calls its `_native_link()` and gets the address of `_Link`. All
tables are indexed by value reference:

* kind 1: a Real input without a user setter. The loader writes a value within [lo, hi] into `val`
  and sets `dirty`; the slave pulls dirty values into `self.values` before it uses them (`pull`).
* kind 2: a Real output that step() writes every step (`ReeveSlave.set_eager_outputs`); the slave
  copies it into `val` after every step and every restore (`publish`), the loader reads it there.
* state[0]: the loader may set inputs (step mode, no rejected input pending); state[1]: it may read
  the kind-2 outputs (step mode, initialized); state[2]: some input is dirty.

Anything else goes through pythonfmu to the slave's Python methods, unchanged. The buffers are
bytearrays (fixed addresses: they are never resized) read from Python through memoryviews.
Setting REEVE_FMU_FAST_PATH=0 in the environment makes the slave decline the link.
"""
from __future__ import annotations

import ctypes
import os
import sys

__all__ = ["BOX", "ENV", "VERSION", "FastLink", "offer", "enabled"]

VERSION = 1                       # REEVE_LINK_VERSION in fmu_loader.c
BOX = "_reeve_fmu_link_box"       # LINK_BOX in fmu_loader.c
ENV = "REEVE_FMU_FAST_PATH"


class _Link(ctypes.Structure):
    _fields_ = [("version", ctypes.c_int), ("n_vr", ctypes.c_int)] + [
        (name, ctypes.c_void_p) for name in ("state", "kind", "lo", "hi", "val", "dirty")]


def enabled() -> bool:
    return os.environ.get(ENV, "1").strip() != "0"


def offer(slave) -> None:
    """Called at the end of the slave's constructor: hand it to a loader that is constructing it."""
    box = getattr(sys, BOX, None)
    if type(box) is list:
        box.append(slave)


class _Table:
    """A bytearray with a fixed address and a typed memoryview of it."""

    def __init__(self, fmt: str, n: int, fill=0):
        size = {"i": ctypes.sizeof(ctypes.c_int), "d": ctypes.sizeof(ctypes.c_double)}[fmt]
        self.raw = bytearray(size * max(n, 1))
        self.view = memoryview(self.raw).cast(fmt)
        for i in range(n):
            self.view[i] = fill
        self._anchor = ctypes.c_char.from_buffer(self.raw)   # keeps the bytearray from resizing
        self.address = ctypes.addressof(self._anchor)


class FastLink:
    """The shared tables of one slave instance (see the module doc)."""

    def __init__(self, n_vr: int, inputs, dbl_max: float):
        """inputs: [(vr, name, lo or None, hi or None)] of the Real inputs without a user setter."""
        self.n_vr = n_vr
        self._state = _Table("i", 3)
        self._kind = _Table("i", n_vr)
        self._lo = _Table("d", n_vr, -dbl_max)
        self._hi = _Table("d", n_vr, dbl_max)
        self._val = _Table("d", n_vr)
        self._dirty = _Table("i", n_vr)
        self.state, self.val, self.dirty = self._state.view, self._val.view, self._dirty.view
        self.inputs = [(vr, name) for vr, name, _, _ in inputs]
        for vr, _, lo, hi in inputs:
            self._kind.view[vr] = 1
            if lo is not None:
                self._lo.view[vr] = float(lo)
            if hi is not None:
                self._hi.view[vr] = float(hi)
        self.outputs: list = []
        self._struct = _Link(VERSION, n_vr, self._state.address, self._kind.address, self._lo.address,
                             self._hi.address, self._val.address, self._dirty.address)
        self.address = ctypes.addressof(self._struct)

    def set_outputs(self, outputs) -> None:
        """outputs: [(vr, name)] the slave keeps current in the table from now on."""
        kind = self._kind.view
        self.state[1] = 0
        for vr, _ in self.outputs:
            kind[vr] = 0
        self.outputs = list(outputs)
        for vr, _ in self.outputs:
            kind[vr] = 2

    def pull(self, values: dict) -> None:
        """Inputs the loader wrote into self.values (call before using any input)."""
        val, dirty = self.val, self.dirty
        self.state[2] = 0
        for vr, name in self.inputs:
            if dirty[vr]:
                dirty[vr] = 0
                values[name] = val[vr]

    def publish(self, values: dict) -> bool:
        """Copy the kind-2 outputs from self.values into the table; False (and the loader reads them
        through Python) when one is not a number."""
        val = self.val
        try:
            for vr, name in self.outputs:
                val[vr] = values[name]
        except TypeError:
            try:
                for vr, name in self.outputs:
                    val[vr] = float(values[name])
            except (TypeError, ValueError):
                return False
        return True
