"""An interpreter program of simulation/backends/vm.c as ctypes sees it, without numpy or
CasADi: sxcode.Program builds one from an SX Function, a prepared warm run
(simulation/warm_run.py) from the plain arrays it stored (``Program.arrays()``)."""
from __future__ import annotations

import ctypes
from array import array

_CI = ctypes.c_longlong


class _Prog(ctypes.Structure):
    _fields_ = [("ins", ctypes.POINTER(ctypes.c_int)), ("nins", _CI), ("consts", ctypes.POINTER(ctypes.c_double)),
                ("nconst", _CI), ("const_off", _CI), ("nin", ctypes.c_int), ("in_off", ctypes.POINTER(_CI)),
                ("in_nnz", ctypes.POINTER(_CI))]


def address(a) -> int | None:
    """The address of the first item of a contiguous buffer: a numpy array or an array.array
    (None when it is empty)."""
    if not len(a):
        return None
    return a.buffer_info()[0] if type(a) is array else a.ctypes.data


_AT = ctypes.c_char.from_buffer
_ADDRESSOF = ctypes.addressof


def data_address(a) -> int:
    """The address of a numpy array's first element (``a.ctypes.data``): through the buffer
    protocol when the array is writable, contiguous and not empty (0.7 us against 2 us of
    numpy's ctypes attribute, paid several times a warm run), else numpy's."""
    f = a.flags
    if f.c_contiguous and f.writeable and a.size:
        return _ADDRESSOF(_AT(a))
    return a.ctypes.data


def plain(a, code: str) -> array:
    """``a`` (a numpy array or an array.array) as an array.array of ``code`` (a copy)."""
    out = array(code)
    out.frombytes(memoryview(a).cast("B") if len(a) else b"")
    return out


class Program:
    """vm.c's program: ``prog`` (the ctypes record the interpreter reads; this object keeps its
    arrays alive), ``nreg`` (the work memory it needs, doubles), ``n_in``, ``n_out``.
    ``arrays``: (instructions (int32, 4 a step), constants (float64), inputs' offsets and sizes
    (int64), nreg, n_in, n_out): numpy arrays or array.arrays of those types."""

    def __init__(self, arrays):
        code, consts, in_off, in_nnz, nreg, self.n_in, self.n_out = arrays
        self.ins, self.consts, self.in_off, self.in_nnz, self.nreg = code, consts, in_off, in_nnz, nreg
        self.prog = _Prog(ctypes.cast(address(code), ctypes.POINTER(ctypes.c_int)), len(code) // 4,
                          ctypes.cast(address(consts), ctypes.POINTER(ctypes.c_double)), len(consts),
                          int(in_off[-1] + in_nnz[-1]) if len(in_nnz) else 0, self.n_in,
                          ctypes.cast(address(in_off), ctypes.POINTER(_CI)),
                          ctypes.cast(address(in_nnz), ctypes.POINTER(_CI)))

    def arrays(self) -> tuple:
        """What ``Program(arrays)`` rebuilds it from, as plain data (array.arrays: no numpy needed
        to read them back)."""
        return (plain(self.ins, "i"), plain(self.consts, "d"), plain(self.in_off, "q"), plain(self.in_nnz, "q"),
                int(self.nreg), int(self.n_in), int(self.n_out))
