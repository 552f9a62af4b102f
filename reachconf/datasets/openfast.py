"""OpenFAST output: a reader of the binary ``.outb`` format and of the CSV exports in the data folder.

Binary layout (as OpenFAST writes it; file IDs 1 = compressed with time,
2 = compressed without time, 3 = uncompressed without time, 4 = compressed
with time and a channel-name length field)::

    int16 FileID; [int16 LenName if FileID == 4]; int32 NumOutChans; int32 NT
    with time (1; 4 if the file size says so): float64 TimeScl, TimeOff   else: float64 TimeOut1, TimeIncr
    compressed (1, 2, 4): float32 ColScl[NumOutChans], ColOff[NumOutChans]
    int32 LenDesc; uint8 Desc[LenDesc]
    NumOutChans + 1 names and units (LenName characters each, LenName = 10 unless given; "Time" first)
    with time: int32 PackedTime[NT]
    compressed: int16 data[NT * NumOutChans] (row-major)   else: float64 data[...]
    value = (packed - ColOff) / ColScl,  time = (PackedTime - TimeOff) / TimeScl
"""

from __future__ import annotations

import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reachconf.errors import DataError

__all__ = ["OpenFASTOutput", "read_outb", "read_csv", "read_output"]


@dataclass
class OpenFASTOutput:
    """Channels (name -> array, including ``Time``), units and the file's description."""

    path: Path
    channels: dict
    units: dict
    description: str = ""

    def __getitem__(self, name):
        if name not in self.channels:
            raise DataError(f"{self.path}: unknown channel {name!r}; channels: {list(self.channels)}")
        return self.channels[name]

    @property
    def time(self):
        return self["Time"]


class _Buf:
    def __init__(self, path, data):
        self.path, self.data, self.off = path, data, 0

    def take(self, dtype, count=1):
        dt = np.dtype(dtype)
        n = dt.itemsize * count
        if self.off + n > len(self.data):
            raise DataError(f"{self.path}: truncated file (needed {n} bytes at offset {self.off}, "
                            f"{len(self.data) - self.off} left)")  # fmt: skip
        out = np.frombuffer(self.data, dtype=dt, count=count, offset=self.off)
        self.off += n
        return out


def read_outb(path) -> OpenFASTOutput:
    """Read an OpenFAST binary output file (``.outb``)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    buf = _Buf(path, path.read_bytes())
    file_id = int(buf.take("<i2")[0])
    if file_id not in (1, 2, 3, 4):
        raise DataError(f"{path}: unknown OpenFAST FileID {file_id} (expected 1-4)")
    len_name = int(buf.take("<i2")[0]) if file_id == 4 else 10
    n_ch, n_t = (int(v) for v in buf.take("<i4", 2))
    if n_ch <= 0 or n_t <= 0:
        raise DataError(f"{path}: invalid header (channels {n_ch}, time steps {n_t})")
    with_time = file_id in (1, 4)
    t_a, t_b = buf.take("<f8", 2)
    compressed = file_id != 3
    if compressed:
        scl = buf.take("<f4", n_ch).astype(float)
        off = buf.take("<f4", n_ch).astype(float)
    len_desc = int(buf.take("<i4")[0])
    desc = bytes(buf.take("u1", len_desc)).decode("latin-1").strip()
    names = [bytes(buf.take("u1", len_name)).decode("latin-1").strip() for _ in range(n_ch + 1)]
    units = [bytes(buf.take("u1", len_name)).decode("latin-1").strip().strip("()") for _ in range(n_ch + 1)]
    item = 2 if compressed else 8
    if file_id == 4:  # ID 4 files are written with or without packed times: the size tells
        remaining = len(buf.data) - buf.off
        with_time = remaining == n_t * 4 + n_t * n_ch * item
    packed_time = buf.take("<i4", n_t) if with_time else None
    raw = buf.take("<i2" if compressed else "<f8", n_t * n_ch).reshape(n_t, n_ch).astype(float)
    values = (raw - off) / scl if compressed else raw
    time = (packed_time - t_b) / t_a if with_time else t_a + t_b * np.arange(n_t)
    channels = {names[0]: time}
    channels.update({name: values[:, i] for i, name in enumerate(names[1:])})
    return OpenFASTOutput(path, channels, dict(zip(names, units)), desc)


def read_csv(path) -> OpenFASTOutput:
    """Read the data folder's CSV exports (``.csv`` or ``.csv.gz``): comment, names, units, rows."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8") as fh:
            lines = [ln for ln in fh.read().splitlines() if ln.strip()]
    except (OSError, EOFError) as exc:
        raise DataError(f"{path}: cannot read ({exc})") from None
    if lines and lines[0].startswith("#"):
        desc, lines = lines[0][1:].strip(), lines[1:]
    else:
        desc = ""
    if len(lines) < 3:
        raise DataError(f"{path}: needs a names row, a units row and data rows")
    names = [n.strip() for n in lines[0].split(",")]
    units = [u.strip().strip("()") for u in lines[1].split(",")]
    try:
        data = np.array([[float(v) for v in ln.split(",")] for ln in lines[2:]])
    except ValueError as exc:
        raise DataError(f"{path}: non-numeric cell ({exc})") from None
    if data.ndim != 2 or data.shape[1] != len(names):
        raise DataError(f"{path}: rows do not all have {len(names)} columns")
    if not np.all(np.isfinite(data)):
        r, c = np.argwhere(~np.isfinite(data))[0]
        raise DataError(f"{path}: row {r + 4}, column {names[c]!r}: NaN/inf not allowed")
    return OpenFASTOutput(path, {n: data[:, i] for i, n in enumerate(names)}, dict(zip(names, units)), desc)


def read_output(path) -> OpenFASTOutput:
    """``.outb`` or ``.csv(.gz)`` by suffix."""
    path = Path(path)
    return read_outb(path) if path.suffix == ".outb" else read_csv(path)
