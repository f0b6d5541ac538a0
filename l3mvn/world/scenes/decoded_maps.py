"""A decoded copy of each SemExp map file in the cache folder: reading it back costs a small part of
decoding the file again.

A split's ``.pbz2`` is bzip2 over a pickle, and every process that loads the split (each eval worker,
the dashboard, each command) decodes all of it before its first episode: for the 25 Gibson train
houses that is most of a short command's start-up. The decoded value is kept as plain arrays under
``cache_root()/maps/<SHA-256 of the file>.npz``, so a file that was edited or replaced is never read
from an old copy, and ``np.load`` reads it without pickle: nothing in the cache runs. Arrays that hold
only 0 and 1 (the category maps) are kept as bits. Small files (a few houses) decode in a blink and
get no copy. A value the cache could not give back exactly (anything but nested dicts of arrays,
numbers and strings) is not kept; a copy that cannot be written (a full disk, a read-only home) costs
only the decoding, with one warning line, and a copy that cannot be read is decoded again and
rewritten.
"""

from __future__ import annotations

import json
import warnings
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import cache_root, file_sha256
from l3mvn.core.writing import make_folder, replacing

_VERSION = 1  # of the layout below: a copy in another layout is decoded again
_MANIFEST = "manifest"
# Decoded values smaller than this decode in well under a tenth of a second: no copy is worth keeping.
_MIN_BYTES = 32 << 20


class _Unfit(Exception):
    """The value holds something the cache could not give back exactly."""


def cache_file(path: Path) -> Path:
    """Where the decoded copy of the map file ``path`` is kept."""
    return cache_root() / "maps" / f"{file_sha256(path)}.npz"


def decoded(path: Path, decode: Callable[[], Any]) -> Any:
    """The decoded value of the map file ``path``: its cached copy, or ``decode()`` (kept for next time)."""
    target = cache_file(path)
    kept = _read(target)
    if kept is not None:
        return kept
    value = decode()
    if _nbytes(value) < _MIN_BYTES:
        return value
    arrays: dict[str, Any] = {}
    try:
        manifest = {"version": _VERSION, "value": _encode(value, arrays)}
    except _Unfit:
        return value
    arrays[_MANIFEST] = np.frombuffer(json.dumps(manifest).encode(), np.uint8)
    try:
        make_folder(target.parent, "the folder of decoded maps")
        with replacing(target, "a decoded copy of a map file") as fh:
            np.savez(fh, **arrays)
    except L3MVNError as exc:
        warnings.warn(f"{exc}: {path} will be decoded again next time", RuntimeWarning, stacklevel=2)
    return value


def _read(target: Path) -> Any | None:
    """The value kept in ``target``, or None when there is none (or it is unreadable or foreign)."""
    try:
        with np.load(target, allow_pickle=False) as stored:
            manifest = json.loads(stored[_MANIFEST].tobytes())
            if not isinstance(manifest, dict) or manifest.get("version") != _VERSION:
                return None
            return _decode(manifest["value"], stored)
    except (OSError, ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile):
        return None  # absent, truncated, another layout: decoded again and rewritten


def _encode(value: Any, arrays: dict[str, Any]) -> Any:
    """A JSON description of ``value``, its arrays added to ``arrays``."""
    if type(value) is dict:
        return {"dict": [[_key(k), _encode(v, arrays)] for k, v in value.items()]}
    if type(value) is np.ndarray:
        if value.dtype.hasobject or value.dtype.kind not in "biuf":
            raise _Unfit
        name = f"a{len(arrays)}"
        bits = value.size > 0 and bool(np.array_equal(value, value.astype(bool)))
        if bits and value.dtype.kind == "f":
            bits = not np.signbit(value).any()  # -0.0 is not 0.0 to a reader of bits
        arrays[name] = np.packbits(value.astype(bool).ravel()) if bits else value
        return {"array": name, "bits": bits, "dtype": value.dtype.str, "shape": list(value.shape)}
    for kind in (bool, int, float, str):
        if type(value) is kind:
            return {kind.__name__: value}
    raise _Unfit


def _nbytes(value: Any) -> int:
    """The bytes of the arrays in ``value``'s dicts."""
    if type(value) is dict:
        return sum(_nbytes(v) for v in value.values())
    return value.nbytes if type(value) is np.ndarray else 0


def _key(key: Any) -> list[Any]:
    if type(key) is str:
        return ["str", key]
    if type(key) is int:
        return ["int", key]
    raise _Unfit


def _decode(spec: dict, stored: Any) -> Any:
    if "dict" in spec:
        return {(str(k) if kind == "str" else int(k)): _decode(v, stored) for (kind, k), v in spec["dict"]}
    if "array" in spec:
        data, dtype, shape = stored[spec["array"]], np.dtype(spec["dtype"]), tuple(spec["shape"])
        if not spec["bits"]:
            if data.dtype != dtype or data.shape != shape:
                raise ValueError("a kept array does not match its description")
            return data
        size = int(np.prod(shape))
        return np.unpackbits(data, count=size).reshape(shape).astype(dtype)
    (kind, value), *rest = spec.items()
    if rest or kind not in ("bool", "int", "float", "str"):
        raise ValueError(f"unknown kind of value {kind!r}")
    return value
