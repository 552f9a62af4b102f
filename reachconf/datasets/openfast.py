"""OpenFAST output: a reader of the binary ``.outb`` format and of the CSV exports in the data folder.

Binary layout (little-endian, as OpenFAST's ``WrBinFAST`` writes it; FileID
1 = int16-compressed with packed int32 time, 2 = compressed with a constant
time step, 3 = uncompressed float64 with a constant time step, 4 = as 2 with
the channel-name length in the header)::

    int16 FileID
    int16 LenName                                  (FileID 4 only; else 10)
    int32 NumOutChans, NT
    float64 TimeScl, TimeOff                       (FileID 1)
    float64 TimeOut1, TimeIncr                     (FileID 2, 3, 4)
    float32 ColScl[NumOutChans], ColOff[NumOutChans]   (FileID 1, 2, 4)
    int32 LenDesc; uint8 Desc[LenDesc]
    uint8 names[NumOutChans + 1][LenName]          ("Time" first)
    uint8 units[NumOutChans + 1][LenName]          ("(s)" first)
    int32 PackedTime[NT]                           (FileID 1)
    int16 data[NT][NumOutChans]  (FileID 1, 2, 4)  or  float64 data[NT][NumOutChans]  (FileID 3)

    value = (packed - ColOff) / ColScl
    time  = (PackedTime - TimeOff) / TimeScl       or  TimeOut1 + k TimeIncr

The compressed formats keep 65 536 levels per channel: :attr:`OpenFASTOutput.step`
holds each channel's quantisation step ``1 / ColScl`` (the values are within
half a step of what OpenFAST computed).
"""

from __future__ import annotations

import gzip
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reachconf.checks import is_number_text, require_file
from reachconf.errors import DataError

__all__ = ["OpenFASTOutput", "read_outb", "read_csv", "read_output", "FILE_IDS"]

#: FileID -> (packed time, compressed)
FILE_IDS = {1: (True, True), 2: (False, True), 3: (False, False), 4: (False, True)}


@dataclass
class OpenFASTOutput:
    """Channels (name -> array, ``Time`` included), units, description and quantisation steps."""

    path: Path
    channels: dict
    units: dict
    description: str = ""
    file_id: int | None = None
    step: dict = field(default_factory=dict)

    def __getitem__(self, name):
        if name not in self.channels:
            raise DataError(f"{self.path}: unknown channel {name!r}; channels: {', '.join(self.channels)}")
        return self.channels[name]

    def __contains__(self, name):
        return name in self.channels

    @property
    def names(self) -> list:
        """Channel names in file order."""
        return list(self.channels)

    @property
    def time(self):
        """The ``Time`` channel (s)."""
        return self["Time"]

    def quantisation_step(self, name) -> float:
        """Quantisation step of a channel: ``1 / ColScl`` from a binary file, else range / 65535."""
        if name in self.step:
            return float(self.step[name])
        return float(np.ptp(self[name])) / 65535.0


class _Reader:
    """Sequential little-endian reads with 'truncated file' errors."""

    def __init__(self, path, data: bytes):
        self.path, self.data, self.off = path, data, 0

    def take(self, dtype, count=1, what=""):
        dt = np.dtype(dtype)
        n = dt.itemsize * int(count)
        if count < 0 or self.off + n > len(self.data):
            raise DataError(f"{self.path}: truncated file: {what or dtype} needs {n} bytes at offset {self.off}, "
                            f"{len(self.data) - self.off} left")  # fmt: skip
        out = np.frombuffer(self.data, dtype=dt, count=int(count), offset=self.off)
        self.off += n
        return out

    def text(self, n, what):
        return bytes(self.take("u1", n, what)).decode("latin-1").strip()


def read_outb(path) -> OpenFASTOutput:
    """Read an OpenFAST binary output file (``.outb``, FileID 1-4)."""
    path = Path(path)
    require_file(path)
    r = _Reader(path, path.read_bytes())
    file_id = int(r.take("<i2", 1, "FileID")[0])
    if file_id not in FILE_IDS:
        raise DataError(f"{path}: unknown OpenFAST FileID {file_id} (expected 1, 2, 3 or 4): not an .outb file?")
    packed_time, compressed = FILE_IDS[file_id]
    len_name = int(r.take("<i2", 1, "LenName")[0]) if file_id == 4 else 10
    n_ch, n_t = (int(v) for v in r.take("<i4", 2, "NumOutChans/NT"))
    if not (0 < len_name <= 1024 and 0 < n_ch < 100_000 and n_t > 0):
        raise DataError(f"{path}: invalid header (LenName {len_name}, channels {n_ch}, time steps {n_t})")
    t_a, t_b = (float(v) for v in r.take("<f8", 2, "time scaling"))
    if compressed:
        scl = r.take("<f4", n_ch, "ColScl").astype(float)
        off = r.take("<f4", n_ch, "ColOff").astype(float)
        if np.any(scl == 0) or not np.all(np.isfinite(scl)):
            raise DataError(f"{path}: a channel scale factor (ColScl) is zero or not finite")
    len_desc = int(r.take("<i4", 1, "LenDesc")[0])
    desc = r.text(len_desc, "description")
    names = [r.text(len_name, "channel names") for _ in range(n_ch + 1)]
    units = [r.text(len_name, "channel units").strip("()") for _ in range(n_ch + 1)]
    if packed_time:
        ptime = r.take("<i4", n_t, "packed time").astype(float)
    raw = r.take("<i2" if compressed else "<f8", n_t * n_ch, "channel data").reshape(n_t, n_ch).astype(float)
    if r.off != len(r.data):
        raise DataError(f"{path}: {len(r.data) - r.off} unexpected bytes after the channel data "
                        f"(FileID {file_id}, {n_ch} channels, {n_t} steps): corrupt or not this format")  # fmt: skip
    if packed_time:
        if t_a == 0:
            raise DataError(f"{path}: time scale factor (TimeScl) is zero")
        time = (ptime - t_b) / t_a
    else:
        time = t_a + t_b * np.arange(n_t)
    values = (raw - off) / scl if compressed else raw
    if len(set(names)) != len(names):
        raise DataError(f"{path}: repeated channel names")
    channels = {names[0]: time}
    channels.update({name: np.ascontiguousarray(values[:, i]) for i, name in enumerate(names[1:])})
    step = {name: 1.0 / abs(scl[i]) for i, name in enumerate(names[1:])} if compressed else {}
    return OpenFASTOutput(path, channels, dict(zip(names, units)), desc, file_id, step)


def read_csv(path) -> OpenFASTOutput:
    """Read the data folder's CSV exports (``.csv`` or ``.csv.gz``): ``# comment``, names, units, rows."""
    path = Path(path)
    require_file(path)
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read ({exc})") from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    desc = ""
    if lines and lines[0].startswith("#"):
        desc, lines = lines[0][1:].strip(), lines[1:]
    if len(lines) < 3:
        raise DataError(f"{path}: needs a names row, a units row and data rows")
    names = [n.strip() for n in lines[0].split(",")]
    raw_units = [u.strip() for u in lines[1].split(",")]
    if all(is_number_text(u) for u in raw_units):  # the units row is missing: it would eat the first data row
        raise DataError(f"{path}: the second row must give the channels' units, e.g. '(s)', got numbers "
                        f"{lines[1][:60]!r}")  # fmt: skip
    units = [u.strip("()") for u in raw_units]
    if len(units) != len(names) or len(set(names)) != len(names):
        raise DataError(f"{path}: the units row must match the {len(names)} (distinct) channel names")
    rows = [ln.split(",") for ln in lines[2:]]
    for r, cells in enumerate(rows):
        if len(cells) != len(names):
            raise DataError(f"{path}: row {r + 4} has {len(cells)} columns, expected {len(names)}")
    try:
        data = np.array(rows, dtype=float)
    except ValueError as exc:
        raise DataError(f"{path}: non-numeric cell ({exc})") from None
    if not np.all(np.isfinite(data)):
        r, c = np.argwhere(~np.isfinite(data))[0]
        raise DataError(f"{path}: row {r + 4}, column {names[c]!r}: NaN/inf not allowed")
    channels = {n: np.ascontiguousarray(data[:, i]) for i, n in enumerate(names)}
    return OpenFASTOutput(path, channels, dict(zip(names, units)), desc)


def read_output(path) -> OpenFASTOutput:
    """``.outb`` or ``.csv(.gz)`` by the file name."""
    path = Path(path)
    return read_outb(path) if path.suffix.lower() == ".outb" else read_csv(path)
