"""BIWI Walking Pedestrians (ETH and Hotel sequences): reader and prediction test cases.

``obsmat.txt`` has 8 whitespace-separated columns per row: frame, pedestrian
ID, pos_x, pos_z (always 0), pos_y, v_x, v_z (always 0), v_y; positions in
metres on the ground plane, one annotation every 0.4 s (see the data
folder's README).  The velocity columns are central differences of the
positions, so at inner rows they contain half a step of *future* position:
:func:`prediction_cases` offers backward differences instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reachconf.checks import is_number_text, require_file
from reachconf.errors import DataError

__all__ = ["Track", "read_obsmat", "read_sequence", "PredictionCases", "prediction_cases", "ANNOTATION_DT"]

#: annotation interval of both sequences (s)
ANNOTATION_DT = 0.4
#: frames per annotation step
FRAMES_PER_STEP = {"eth": 6, "hotel": 10}


@dataclass(frozen=True)
class Track:
    """One pedestrian: times (s), positions (n, 2) and the file's velocities (n, 2)."""

    sequence: str
    pid: int
    t: np.ndarray
    p: np.ndarray
    v: np.ndarray


def read_obsmat(path, sequence=None) -> list[Track]:
    """Read one ``obsmat.txt`` into tracks (DataError naming file, row and column on bad input)."""
    path = Path(path)
    require_file(path)
    sequence = sequence or path.parent.name
    step = FRAMES_PER_STEP.get(sequence)
    rows = []
    with open(path, encoding="utf-8") as fh:
        for r, line in enumerate(fh, start=1):
            cells = line.split()
            if not cells:
                continue
            if len(cells) != 8:
                raise DataError(f"{path}: row {r}: {len(cells)} columns, expected 8")
            try:
                vals = [float(c) for c in cells]
            except ValueError:
                bad = next(i for i, c in enumerate(cells) if not is_number_text(c))
                raise DataError(f"{path}: row {r}, column {bad + 1}: not a number: {cells[bad]!r}") from None
            if not all(np.isfinite(vals)):
                bad = next(i for i, v in enumerate(vals) if not np.isfinite(v))
                raise DataError(f"{path}: row {r}, column {bad + 1}: NaN/inf not allowed")
            for col, what in ((0, "frame number"), (1, "pedestrian id")):
                if vals[col] != int(vals[col]):
                    raise DataError(f"{path}: row {r}, column {col + 1}: the {what} must be a whole number, "
                                    f"got {cells[col]!r}")  # fmt: skip
            rows.append(vals)
    if not rows:
        raise DataError(f"{path}: file is empty")
    A = np.array(rows)
    if step is None:  # unknown sequence: infer the frame step from the within-track gaps
        gaps = np.concatenate([np.diff(A[A[:, 1] == i, 0]) for i in np.unique(A[:, 1])])
        step = float(np.median(gaps[gaps > 0])) if gaps.size else 1.0
    tracks = []
    for pid in np.unique(A[:, 1]):
        sel = A[A[:, 1] == pid]
        sel = sel[np.argsort(sel[:, 0])]
        if np.any(np.diff(sel[:, 0]) <= 0):
            raise DataError(f"{path}: pedestrian {int(pid)} has repeated frame numbers")
        t = sel[:, 0] / step * ANNOTATION_DT
        tracks.append(Track(sequence, int(pid), t, sel[:, [2, 4]].copy(), sel[:, [5, 7]].copy()))
    return tracks


def read_sequence(data_dir, name) -> list[Track]:
    """Tracks of ``data_dir/name/obsmat.txt`` (``name`` is "eth" or "hotel")."""
    return read_obsmat(Path(data_dir) / name / "obsmat.txt", sequence=name)


@dataclass
class PredictionCases:
    """All prediction test cases at once (arrays over cases).

    Attributes
    ----------
    p0, v0 : (N, 2)
        Position and velocity estimate at the start time.
    future : (N, H, 2)
        True positions at the horizon offsets ``offsets`` (s).
    pid : (N,) pedestrian index (sequence-unique ids ``"seq:id"`` in ``ids``).
    """

    p0: np.ndarray
    v0: np.ndarray
    future: np.ndarray
    offsets: np.ndarray
    pid: np.ndarray
    ids: list

    def __len__(self):
        return self.p0.shape[0]


def prediction_cases(tracks, horizon=1.6, start_step=0.4, velocity="backward", future_step=ANNOTATION_DT):
    """Test cases: one per pedestrian and start time with a full ``horizon`` of annotated future.

    Parameters
    ----------
    start_step : float
        Spacing of the start times; finer than 0.4 s resamples the track by
        linear interpolation of the positions, so that a start between two
        annotations takes its position (and a "backward" velocity) partly from
        the next one, up to 0.3 s ahead: not what a predictor could know.  The
        default, 0.4 s, starts on the annotations only.
    velocity : {"backward", "file"}
        ``"backward"``: ``(p(t0) - p(t0 - 0.4)) / 0.4`` from the past only (needs
        0.4 s of history); ``"file"``: the file's central differences
        (interpolated), which see half a step into the future.
    future_step : float
        Spacing of the checked future positions (0.4 s: the annotation times
        when ``start_step`` is 0.4).
    """
    if velocity not in ("backward", "file"):
        raise DataError(f"velocity must be 'backward' or 'file', got {velocity!r}")
    offsets = np.arange(1, int(round(horizon / future_step)) + 1) * future_step
    P0, V0, F, PID, ids = [], [], [], [], []
    for k, tr in enumerate(tracks):
        t = tr.t
        first = t[0] + (ANNOTATION_DT if velocity == "backward" else 0.0)
        last = t[-1] - horizon
        if last < first - 1e-9:
            continue
        n = int(np.floor((last - first) / start_step + 1e-9)) + 1
        t0 = first + start_step * np.arange(n)
        px = np.interp(t0, t, tr.p[:, 0])
        py = np.interp(t0, t, tr.p[:, 1])
        if velocity == "backward":
            vx = (px - np.interp(t0 - ANNOTATION_DT, t, tr.p[:, 0])) / ANNOTATION_DT
            vy = (py - np.interp(t0 - ANNOTATION_DT, t, tr.p[:, 1])) / ANNOTATION_DT
        else:
            vx = np.interp(t0, t, tr.v[:, 0])
            vy = np.interp(t0, t, tr.v[:, 1])
        tf = t0[:, None] + offsets[None, :]
        fx = np.interp(tf, t, tr.p[:, 0])
        fy = np.interp(tf, t, tr.p[:, 1])
        P0.append(np.column_stack([px, py]))
        V0.append(np.column_stack([vx, vy]))
        F.append(np.stack([fx, fy], axis=-1))
        PID.append(np.full(n, len(ids)))
        ids.append(f"{tr.sequence}:{tr.pid}")
    if not P0:
        raise DataError("no pedestrian has a full horizon of annotated future")
    return PredictionCases(np.vstack(P0), np.vstack(V0), np.concatenate(F), offsets, np.concatenate(PID), ids)
