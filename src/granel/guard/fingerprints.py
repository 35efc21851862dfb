"""Fingerprints of what a command reads, by content: a resumed run, sweep or study compares the
bytes of every input file, not only its name, so that an edited load table or granule file is
never mixed with results computed from the old one."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

_MEMO: dict = {}


def file_digest(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (remembered per process by its size, time stamp and inode);
    "missing" for a file that cannot be read."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError:
        return "missing"
    key = (str(path.absolute()), st.st_size, st.st_mtime_ns, st.st_ino)
    hit = _MEMO.get(key)
    if hit is not None:
        return hit
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return "missing"
    _MEMO[key] = digest = h.hexdigest()
    return digest


CRC_CHUNK = 1 << 24  # bytes per zlib.crc32 call


def file_crc32(path) -> tuple[int, int]:
    """(size in bytes, CRC-32) of the file at `path`, read through a memory map (no copy): the
    check of granel's own cache entries (cheaper than a SHA-256)."""
    import mmap
    import zlib

    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size == 0:
            return 0, 0
        crc = 0
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as m:
            view = memoryview(m)
            try:
                for start in range(0, size, CRC_CHUNK):
                    crc = zlib.crc32(view[start:start + CRC_CHUNK], crc)
            finally:
                view.release()
    return size, crc


def digests(named: dict) -> dict:
    """{name: digest} of {name: path}."""
    return {name: file_digest(path) for name, path in named.items()}


def text_digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def sparse_digest(matrices, key: str = "") -> str:
    """The SHA-256 of `key` and the CSR arrays (indptr, indices, data) of each sparse matrix, in
    order, after sorting a CSR matrix's indices in place: a solid's M and K name its mode-cache
    entries and are named in its result's record."""
    import numpy as np

    h = hashlib.sha256(key.encode())
    for A in matrices:
        A = A.tocsr()
        A.sort_indices()
        for arr in (A.indptr, A.indices, A.data):
            h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


def changed(held: dict, now: dict) -> list[str]:
    """The names whose digest differs between two {name: digest} records (or is in one only)."""
    return sorted(k for k in set(held) | set(now) if held.get(k) != now.get(k))


def encode(record: dict) -> str:
    return json.dumps(record, sort_keys=True)


def decode(text) -> dict:
    try:
        out = json.loads(text) if isinstance(text, str) else {}
    except ValueError:
        return {}
    return out if isinstance(out, dict) else {}
