"""Rotor performance table of the NREL 5-MW turbine and the polynomial aero maps of eq. 78.

The table (``Cp_Ct_Cq.NREL5MW.txt``, written by the ROSCO toolbox) holds the
power, thrust and torque coefficients on a grid of tip-speed ratios (rows)
and blade pitch angles in degrees (columns).  Layout::

    # comment lines ...
    # Pitch angle vector ...            -> next non-comment line: pitch [deg]
    # TSR vector ...                    -> next non-comment line: TSR [-]
    # Wind speed vector ...             -> next non-comment line: wind speed [m/s]
    # Power coefficient                 -> len(TSR) rows x len(pitch) columns
    # Thrust coefficient                -> idem
    # Torque coefficient                -> idem

:func:`fit_aero` fits the polynomial forms of eq. 78 (theta in radians) by
linear least squares over a region of the (TSR, pitch) grid — by default the
whole table, better the region a data set actually visits
(:func:`operating_region`).  The coefficients plug into
:func:`reachconf.models.windturbine.wind_turbine` as keyword parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reachconf.checks import require_file
from reachconf.errors import DataError

__all__ = ["PerformanceTable", "AeroFit", "read_performance_table", "fit_aero", "operating_region",
           "cp_poly", "ct_poly", "CP_TERMS", "CT_TERMS"]  # fmt: skip

#: eq. 78a terms: name -> (power of lambda, power of theta)
CP_TERMS = {"p21": (2, 1), "p20": (2, 0), "p12": (1, 2), "p11": (1, 1), "p10": (1, 0),
            "p02": (0, 2), "p01": (0, 1), "p00": (0, 0)}  # fmt: skip
#: eq. 78b terms
CT_TERMS = {"t21": (2, 1), "t20": (2, 0), "t11": (1, 1), "t10": (1, 0), "t01": (0, 1), "t00": (0, 0)}


@dataclass
class PerformanceTable:
    """Cp, Ct, Cq on the grid ``tsr`` (rows) x ``pitch_deg`` (columns)."""

    path: Path
    pitch_deg: np.ndarray
    tsr: np.ndarray
    wind_speed: np.ndarray
    cp: np.ndarray
    ct: np.ndarray
    cq: np.ndarray

    def interpolate(self, name: str, tsr, pitch_rad) -> np.ndarray:
        """Bilinear interpolation of ``cp``/``ct``/``cq`` (clamped at the table's edges)."""
        table = getattr(self, name)
        x = np.clip(np.asarray(tsr, float), self.tsr[0], self.tsr[-1])
        y = np.clip(np.degrees(np.asarray(pitch_rad, float)), self.pitch_deg[0], self.pitch_deg[-1])
        i = np.clip(np.searchsorted(self.tsr, x) - 1, 0, self.tsr.size - 2)
        j = np.clip(np.searchsorted(self.pitch_deg, y) - 1, 0, self.pitch_deg.size - 2)
        a = (x - self.tsr[i]) / (self.tsr[i + 1] - self.tsr[i])
        b = (y - self.pitch_deg[j]) / (self.pitch_deg[j + 1] - self.pitch_deg[j])
        return ((1 - a) * (1 - b) * table[i, j] + a * (1 - b) * table[i + 1, j]
                + (1 - a) * b * table[i, j + 1] + a * b * table[i + 1, j + 1])  # fmt: skip


def _numbers(path, lineno, line):
    try:
        values = np.array([float(v) for v in line.split()])
    except ValueError:
        raise DataError(f"{path}: line {lineno}: expected numbers, got {line.strip()[:60]!r}") from None
    if not np.all(np.isfinite(values)):
        raise DataError(f"{path}: line {lineno}: NaN or inf among the numbers {line.strip()[:60]!r}")
    return values


def read_performance_table(path) -> PerformanceTable:
    """Read a ROSCO-style ``Cp_Ct_Cq`` text file (DataError naming the file and the problem)."""
    path = Path(path)
    require_file(path)
    lines = path.read_text(encoding="latin-1").splitlines()
    vectors, blocks, current = {}, {}, None
    for no, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            low = s.lower()
            for key, word in (("pitch", "pitch angle"), ("tsr", "tsr vector"), ("wind", "wind speed")):
                if word in low:
                    current = ("vec", key)
                    break
            else:
                for key, word in (("cp", "power coef"), ("ct", "thrust coef"), ("cq", "torque coef")):
                    if word in low:
                        current = ("blk", key)
                        blocks[key] = []
                        break
            continue
        if current is None:
            raise DataError(f"{path}: line {no}: numbers before any section header")
        kind, key = current
        if kind == "vec":
            vectors[key] = _numbers(path, no, s)
            current = None
        else:
            blocks[key].append(_numbers(path, no, s))
    for key in ("pitch", "tsr"):
        if key not in vectors:
            raise DataError(f"{path}: no {'pitch angle' if key == 'pitch' else 'TSR'} vector")
    shape = (vectors["tsr"].size, vectors["pitch"].size)
    out = {}
    for key in ("cp", "ct", "cq"):
        rows = blocks.get(key)
        if not rows:
            raise DataError(f"{path}: no {key.upper()} block")
        if any(r.size != shape[1] for r in rows) or len(rows) != shape[0]:
            raise DataError(f"{path}: {key.upper()} block is not {shape[0]} x {shape[1]} (TSR x pitch)")
        out[key] = np.vstack(rows)
    if np.any(np.diff(vectors["tsr"]) <= 0) or np.any(np.diff(vectors["pitch"]) <= 0):
        raise DataError(f"{path}: TSR and pitch vectors must increase")
    return PerformanceTable(path, vectors["pitch"], vectors["tsr"], vectors.get("wind", np.array([])), **out)


def _design(terms, lam, th):
    return np.column_stack([lam**a * th**b for a, b in terms.values()])


def cp_poly(coef: dict, lam, theta):
    """eq. 78a."""
    return sum(coef[k] * lam**a * theta**b for k, (a, b) in CP_TERMS.items())


def ct_poly(coef: dict, lam, theta):
    """eq. 78b."""
    return sum(coef[k] * lam**a * theta**b for k, (a, b) in CT_TERMS.items())


@dataclass
class AeroFit:
    """Coefficients of eq. 78 and their fit errors over the region used."""

    cp: dict
    ct: dict
    rms_cp: float
    rms_ct: float
    max_cp: float
    max_ct: float
    tsr_range: tuple
    pitch_range_deg: tuple
    points: int

    @property
    def params(self) -> dict:
        """All coefficients, ready for ``wind_turbine(**fit.params)`` / ``model.with_params``."""
        return {**self.cp, **self.ct}

    def to_dict(self) -> dict:
        """The fit as JSON values."""
        return {
            "cp": {k: float(v) for k, v in self.cp.items()},
            "ct": {k: float(v) for k, v in self.ct.items()},
            "rms_cp": self.rms_cp,
            "rms_ct": self.rms_ct,
            "max_abs_error_cp": self.max_cp,
            "max_abs_error_ct": self.max_ct,
            "tsr_range": list(self.tsr_range),
            "pitch_range_deg": list(self.pitch_range_deg),
            "points": self.points,
        }


def fit_aero(table: PerformanceTable, tsr_range=(3.0, 12.0), pitch_range_deg=(0.0, 15.0), points=None,
             weights=None, clip_negative: bool = True) -> AeroFit:  # fmt: skip
    """Least-squares fit of eq. 78 (theta in radians).

    Without ``points`` the table's grid points inside ``tsr_range`` x
    ``pitch_range_deg`` are used.  With ``points = (tsr, pitch_rad)`` (e.g. the
    operating points a data set visits) the table is interpolated there and
    the fit is made on those points (optionally weighted).  Negative table
    entries (rotor in propeller/brake state) are set to 0 first, as in
    ``PERFORMANCE_TABLE.md``.
    """
    if points is None:
        L, P = np.meshgrid(table.tsr, table.pitch_deg, indexing="ij")
        sel = ((L >= tsr_range[0] - 1e-9) & (L <= tsr_range[1] + 1e-9)
               & (P >= pitch_range_deg[0] - 1e-9) & (P <= pitch_range_deg[1] + 1e-9))  # fmt: skip
        if sel.sum() < len(CP_TERMS):
            raise DataError(f"{table.path}: only {int(sel.sum())} table points in TSR {tsr_range}, "
                            f"pitch {pitch_range_deg} deg: too few for eq. 78")  # fmt: skip
        lam, th = L[sel], np.radians(P[sel])
        cp, ct = table.cp[sel], table.ct[sel]
    else:
        lam, th = (np.asarray(v, float).ravel() for v in points)
        cp, ct = table.interpolate("cp", lam, th), table.interpolate("ct", lam, th)
        tsr_range = (float(lam.min()), float(lam.max()))
        pitch_range_deg = (float(np.degrees(th.min())), float(np.degrees(th.max())))
    if clip_negative:
        cp, ct = np.maximum(cp, 0.0), np.maximum(ct, 0.0)
    w = np.ones_like(lam) if weights is None else np.sqrt(np.asarray(weights, float).ravel())
    res = {}
    for key, terms, target in (("cp", CP_TERMS, cp), ("ct", CT_TERMS, ct)):
        A = _design(terms, lam, th)
        c = np.linalg.lstsq(A * w[:, None], target * w, rcond=None)[0]
        err = A @ c - target
        res[key] = (dict(zip(terms, map(float, c))), float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err))))
    return AeroFit(res["cp"][0], res["ct"][0], res["cp"][1], res["ct"][1], res["cp"][2], res["ct"][2],
                   tuple(map(float, tsr_range)), tuple(map(float, pitch_range_deg)), int(lam.size))  # fmt: skip


def operating_region(Omega, v0, theta, R, quantiles=(0.0, 1.0)):
    """Tip-speed ratios and pitch angles (rad) visited: ``lambda = Omega R / v0``; plus their ranges."""
    lam = np.asarray(Omega, float) * R / np.asarray(v0, float)
    th = np.asarray(theta, float)
    lo, hi = quantiles
    return lam, th, (float(np.quantile(lam, lo)), float(np.quantile(lam, hi))), (
        float(np.degrees(np.quantile(th, lo))), float(np.degrees(np.quantile(th, hi))))
