"""Reading a SemExp map pickle without trusting it: numbers, strings, containers and numeric arrays.

``pickle.load`` imports and calls any global a file names (``os.system`` included), and even numpy's
own constructors take state from the file: a dtype's flags can claim that an array holds Python
objects, whose "pointers" are then the file's bytes. These map files come from third-party mirrors,
so nothing numpy-made is built by numpy from the file's state. Each numpy global a map uses resolves
to a stand-in that records what the file says; the loader then builds every array itself, from a
plain numeric type code, a byte order, a shape and the raw bytes, all checked. Every pickle protocol
numpy and Python write is read: 0-4 (arrays as ``_reconstruct`` plus state, their bytes through
``_codecs.encode`` below protocol 3) and 5 (``_frombuffer``).
"""

from __future__ import annotations

import math
import pickle
from typing import Any, Literal, Protocol, cast

import numpy as np

NUMERIC_KINDS = "biuf"  # bool, signed and unsigned integers, floats: what a map's arrays hold
MAX_ELEMENTS = 1 << 31  # far beyond a house (2,000 x 2,000 cells x 16 channels is 2**26)
_BYTE_ORDERS = {"<": "<", ">": ">", "|": "|", "=": "="}
_ByteOrder = Literal["<", ">", "|", "="]
_Order = Literal["C", "F"]
_NUMPY_MODULES = ("numpy.core.multiarray", "numpy._core.multiarray")


class UnsafeMap(pickle.UnpicklingError):
    """The file names or builds something a SemExp map does not hold."""


class MapFile(Protocol):
    """What pickle reads a map from: an open binary file, plain or compressed."""

    def read(self, n: int, /) -> bytes: ...

    def readline(self) -> bytes: ...


class _Dtype:
    """``numpy.dtype(code, align, copy)`` and its state as the file gives them; ``build`` makes the
    dtype from the type code and byte order alone."""

    order: _ByteOrder

    def __init__(self, code: object = None, *flags: object) -> None:
        if not isinstance(code, str) or len(code) > 8 or any(not isinstance(f, (bool, int)) for f in flags):
            raise UnsafeMap(f"a dtype {code!r} that is not a plain type code")
        self.code, self.order = code, "|"

    def __setstate__(self, state: object) -> None:
        if not isinstance(state, tuple) or len(state) < 2 or state[1] not in _BYTE_ORDERS:
            raise UnsafeMap("a dtype state numpy never writes for a number")
        self.order = state[1]  # the rest (fields, sizes, flags) is never read: numbers need none

    def build(self) -> np.dtype:
        try:
            dtype = np.dtype(self.code)
        except TypeError:
            raise UnsafeMap(f"an unknown type code {self.code!r}") from None
        if dtype.kind not in NUMERIC_KINDS or dtype.fields is not None or dtype.subdtype is not None:
            raise UnsafeMap(f"an array of {dtype}: a SemExp map holds only numeric arrays")
        return dtype if self.order == "|" else dtype.newbyteorder(self.order)


class _Array:
    """An array as ``_reconstruct(ndarray, (0,), b'b')`` starts it and its state fills it in."""

    def __init__(self) -> None:
        self.array: np.ndarray | None = None

    def __setstate__(self, state: object) -> None:
        if not isinstance(state, tuple) or len(state) != 5:
            raise UnsafeMap("an array state numpy never writes")
        _, shape, dtype, fortran, data = state
        if not isinstance(dtype, _Dtype) or not isinstance(fortran, bool):
            raise UnsafeMap("an array state numpy never writes")
        self.array = _array(data, dtype.build(), shape, "F" if fortran else "C")


def _array(data: object, dtype: np.dtype, shape: object, order: _Order) -> np.ndarray:
    """A fresh array of ``shape`` from exactly the bytes it needs."""
    if (
        not isinstance(shape, tuple)
        or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape)
        or len(shape) > 8
    ):
        raise UnsafeMap(f"an array shape {shape!r}")
    count = math.prod(shape)
    if count > MAX_ELEMENTS:
        raise UnsafeMap(f"an array of {count} elements")
    if isinstance(data, pickle.PickleBuffer):
        data = data.raw().tobytes()
    if not isinstance(data, (bytes, bytearray)) or len(data) != count * dtype.itemsize:
        raise UnsafeMap(f"array bytes that do not fit its shape {shape} of {dtype}")
    return np.frombuffer(bytes(data), dtype=dtype).reshape(shape, order=order).copy()


def _reconstruct(cls: object, shape: object, code: object) -> _Array:
    if cls is not _NDARRAY:
        raise UnsafeMap("an array of a class other than numpy.ndarray")
    return _Array()


def _frombuffer(data: object, dtype: object, shape: object, order: object) -> np.ndarray:
    if not isinstance(dtype, _Dtype) or order not in ("C", "F"):
        raise UnsafeMap("a protocol-5 array numpy never writes")
    return _array(data, dtype.build(), shape, order)


def _scalar(dtype: object, data: object = None) -> np.generic:
    if not isinstance(dtype, _Dtype):
        raise UnsafeMap("a scalar of no numeric dtype")
    # numpy's stubs type ``a[()]`` as an array; on a 0-d array it is the scalar.
    return cast(np.generic, _array(data, dtype.build(), (), "C")[()])


def _latin1(text: object, encoding: object = "latin1") -> bytes:
    """``_codecs.encode``, as protocols 0-2 use it to carry bytes: latin-1 text to bytes, nothing else."""
    if not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
        raise UnsafeMap("a use of _codecs.encode other than carrying bytes")
    return text.encode("latin1")


_NDARRAY = object()  # stands for numpy.ndarray: only ever passed back to _reconstruct
_GLOBALS: dict[tuple[str, str], object] = {
    **{(m, "_reconstruct"): _reconstruct for m in _NUMPY_MODULES},
    **{(m, "scalar"): _scalar for m in _NUMPY_MODULES},
    **{(m.replace("multiarray", "numeric"), "_frombuffer"): _frombuffer for m in _NUMPY_MODULES},
    ("numpy", "ndarray"): _NDARRAY,
    ("numpy", "dtype"): _Dtype,
    ("_codecs", "encode"): _latin1,
}


class _MapUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> object:
        try:
            return _GLOBALS[(module, name)]
        except KeyError:
            raise UnsafeMap(
                f"refuses {module}.{name}: a SemExp map holds only dicts, numbers and numpy arrays"
            ) from None


def load_map_pickle(fh: MapFile) -> Any:
    """The value pickled in ``fh``, every array built by this module (UnsafeMap, or pickle's own
    errors for a damaged file, otherwise)."""
    return _materialised(_MapUnpickler(fh).load())


def _materialised(value: Any) -> Any:
    """``value`` with every stand-in replaced by what it stands for."""
    if isinstance(value, _Array):
        return _built(value)
    if isinstance(value, _Dtype):
        return value.build()
    if isinstance(value, dict):
        return {_materialised(k): _materialised(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_materialised(v) for v in value]
    if isinstance(value, tuple):
        return tuple(_materialised(v) for v in value)
    return value


def _built(spec: _Array) -> np.ndarray:
    if spec.array is None:
        raise UnsafeMap("an array without its state")
    return spec.array
