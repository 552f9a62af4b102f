"""Measured test cases ⟨U, Y, T⟩ (source report section 3.1) in memory: :class:`TestCase`, :class:`TestSuite`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from reachconf.errors import DataError
from reachconf.io.segments import case_segments

__all__ = ["TestCase", "TestSuite", "check_signals", "case_arrays", "real_array", "suite_cases"]


def real_array(where: str, name: str, value) -> np.ndarray:
    """``value`` as a float array; complex, string, boolean or other non-numeric data is a DataError naming it.

    (``np.asarray(x, dtype=float)`` alone drops imaginary parts with only a
    warning and parses strings such as ``"1_0"``.)
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise DataError(f"{where}: {name} is not an array of numbers ({exc})") from None
    if arr.dtype.kind in "iuf":
        return arr.astype(float, copy=False)
    if arr.dtype.kind == "O":
        try:
            if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
                   for v in arr.flat):  # fmt: skip
                return arr.astype(float)
        except (TypeError, ValueError):
            pass
    kind = {"c": "complex numbers", "b": "booleans", "U": "strings", "S": "bytes", "O": "Python objects"}
    raise DataError(f"{where}: {name} must hold real numbers, got {kind.get(arr.dtype.kind, str(arr.dtype))}")


def check_signals(where: str, t, U, Y, input_names, output_names, first_row: int = 1, row_numbers=None):
    """Validate shapes and values (DataError naming ``where``, the row and the column).

    Sample ``i`` is called row ``i + first_row`` in messages, or
    ``row_numbers[i]`` if given (the line numbers of a CSV file, which skip
    blank lines).
    """

    def row(i):
        return int(row_numbers[i]) if row_numbers is not None else int(i) + first_row

    t, U, Y = (real_array(where, name, v) for name, v in (("t", t), ("U", U), ("Y", Y)))
    if t.ndim != 1:
        raise DataError(f"{where}: t must be 1-D, got shape {t.shape}")
    K = t.size
    if K < 2:
        raise DataError(f"{where}: a test case needs at least 2 samples, got {K}")
    if U.ndim == 1 and U.size == 0:
        U = U.reshape(K, 0)
    if U.ndim != 2 or U.shape[0] != K or U.shape[1] != len(input_names):
        raise DataError(f"{where}: U must have shape ({K}, {len(input_names)}), got {U.shape}")
    if Y.ndim != 2 or Y.shape[0] != K or Y.shape[1] != len(output_names):
        raise DataError(f"{where}: Y must have shape ({K}, {len(output_names)}), got {Y.shape}")
    for arr, names, kind in ((t[:, None], ("t",), "t"), (U, input_names, "U"), (Y, output_names, "Y")):
        bad = ~np.isfinite(arr)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise DataError(f"{where}: row {row(r)}, column {names[c]!r}: value is {arr[r, c]} "
                            "(NaN/inf not allowed)")  # fmt: skip
    dt = np.diff(t)
    if np.any(dt <= 0):
        r = int(np.argmax(dt <= 0))
        raise DataError(f"{where}: row {row(r + 1)}, column 't': time is not strictly increasing "
                        f"({t[r]} then {t[r + 1]})")  # fmt: skip
    return t, U, Y


def _frozen(arr: np.ndarray) -> np.ndarray:
    if arr.flags.writeable:
        arr = arr.copy()
        arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class TestCase:
    """One measured test case ⟨U, Y, T⟩ (section 3.1).

    Parameters
    ----------
    name, group : str
        Case name (file stem) and group (maneuver) it belongs to.
    t : ndarray (K,)
        Sample times, strictly increasing, seconds.
    U : ndarray (K, m)
        Known inputs, held constant between samples.
    Y : ndarray (K, p)
        Measured outputs.
    input_names, output_names : tuple of str
        Column names of ``U`` and ``Y``.
    extras : dict str -> ndarray (K,)
        Further measured signals (e.g. requested actuator values).
    """

    __test__ = False  # not a pytest test class

    name: str
    group: str
    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    input_names: tuple = ()
    output_names: tuple = ()
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or any(ch in self.name for ch in '/\\\0') \
                or self.name in (".", ".."):  # fmt: skip
            raise DataError(f"test case name must be a non-empty string without '/', '\\' or NUL (it names the "
                            f"case's file), got {self.name!r}")  # fmt: skip
        if not isinstance(self.group, str):
            raise DataError(f"test case {self.name!r}: group must be a string, got {self.group!r}")
        for label, names in (("input_names", self.input_names), ("output_names", self.output_names)):
            if isinstance(names, str) or not all(isinstance(n, str) for n in names):
                raise DataError(f"test case {self.name!r}: {label} must be a sequence of names (strings), "
                                f"got {names!r}")  # fmt: skip
        inputs, outputs = tuple(self.input_names), tuple(self.output_names)
        where = f"test case {self.name!r}"
        t, U, Y = check_signals(where, self.t, self.U, self.Y, inputs, outputs)
        extras = {}
        for key, val in dict(self.extras).items():
            arr = real_array(where, f"extra signal {key!r}", val)
            if arr.shape != t.shape:
                raise DataError(f"{where}: extra signal {key!r} has shape {arr.shape}, expected {t.shape}")
            if not np.all(np.isfinite(arr)):
                raise DataError(f"{where}: extra signal {key!r} contains NaN/inf")
            extras[key] = arr
        names = ("t",) + inputs + outputs + tuple(extras)
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise DataError(f"{where}: duplicate signal names {sorted(dup)}")
        # freeze copies: the caller's arrays stay theirs (and writeable); already frozen ones are shared
        t, U, Y = (_frozen(a) for a in (t, U, Y))
        extras = {k: _frozen(v) for k, v in extras.items()}
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "U", U)
        object.__setattr__(self, "Y", Y)
        object.__setattr__(self, "input_names", inputs)
        object.__setattr__(self, "output_names", outputs)
        object.__setattr__(self, "extras", extras)

    @classmethod
    def from_signals(cls, name, t, signals: dict, inputs, outputs, group="default"):
        """Build a case from a dict of named signals (each (K,)); unlisted signals become extras."""
        missing = [s for s in (*inputs, *outputs) if s not in signals]
        if missing:
            raise DataError(f"test case {name!r}: missing signals {missing}")
        K = np.size(t)
        U = np.column_stack([signals[s] for s in inputs]) if inputs else np.zeros((K, 0))
        Y = np.column_stack([signals[s] for s in outputs])
        extras = {k: v for k, v in signals.items() if k not in inputs and k not in outputs and k != "t"}
        return cls(name, group, t, U, Y, tuple(inputs), tuple(outputs), extras)

    @property
    def duration(self) -> float:
        """``t[-1] - t[0]`` (s)."""
        return float(self.t[-1] - self.t[0])

    @property
    def signals(self) -> dict:
        """All signals by name (inputs, outputs, extras)."""
        out = {n: self.U[:, i] for i, n in enumerate(self.input_names)}
        out.update({n: self.Y[:, i] for i, n in enumerate(self.output_names)})
        out.update(self.extras)
        return out

    def signal(self, name: str) -> np.ndarray:
        """One signal by name."""
        sig = self.signals
        if name == "t":
            return self.t
        if name not in sig:
            raise DataError(f"test case {self.name!r} has no signal {name!r}; it has {sorted(sig)}")
        return sig[name]

    def segment(self, t0: float, t1: float) -> "TestCase":
        """The samples with ``t0 <= t <= t1`` as a new case (at least 2 samples)."""
        keep = (self.t >= t0) & (self.t <= t1)
        if keep.sum() < 2:
            raise DataError(f"test case {self.name!r}: segment [{t0}, {t1}] holds fewer than 2 samples")
        return TestCase(f"{self.name}[{t0:g},{t1:g}]", self.group, self.t[keep], self.U[keep], self.Y[keep],
                        self.input_names, self.output_names, {k: v[keep] for k, v in self.extras.items()})  # fmt: skip

    def segments(self, length: float, partial: bool = True, step: float | None = None) -> list:
        """The case cut into segments of ``length`` seconds (section 4.3.3's shorter horizons).

        Segment ``k`` holds the samples with ``t0 + k step <= t <= t0 + k step + length`` (``step``
        defaults to ``length``: consecutive segments that share the sample on their boundary, so every
        sample lies in a segment; a smaller ``step`` gives overlapping, sliding windows).  Each is checked
        from its own first sample (eq. 67), as a test case of its own.  The report proposes this for long
        maneuvers ("reduce the horizons of the measurement data and search for conformant models on
        smaller segments within maneuvers"): a reach over a few seconds stays tight where one over a whole
        run explodes, at the price of a weaker claim — conformance over every ``length``-second stretch
        started from a measured state, not over the whole run.

        Parameters
        ----------
        length : float
            Segment length (s), positive and finite.
        partial : bool, default True
            Keep the last segment when it is shorter than ``length`` (False: drop it; with the default
            ``step`` its samples are then in no segment).
        step : float, optional
            Time between the starts of consecutive segments (s), positive and at most ``length``.

        Returns
        -------
        list of TestCase
            Named ``"{name}[{t_first},{t_last}]"`` by their first and last sample times (to the
            microsecond, trailing zeros dropped: ``run[2,4]``, ``run[1700000000.25,1700000002.25]``), in
            the case's group.  A case no longer than ``length`` gives itself (one segment, same name), or
            nothing if it is shorter and ``partial`` is False.
        """
        return case_segments(self, length, partial, step)

    def decimate(self, k: int) -> "TestCase":
        """Every ``k``-th sample (inputs stay piecewise constant on the coarser grid)."""
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise DataError(f"test case {self.name!r}: decimation factor must be an integer >= 1, got {k!r}")
        k = int(k)
        if k == 1:
            return self
        sl = slice(None, None, k)
        return TestCase(self.name, self.group, self.t[sl], self.U[sl], self.Y[sl], self.input_names,
                        self.output_names, {key: v[sl] for key, v in self.extras.items()})  # fmt: skip

    def select(self, inputs, outputs) -> "TestCase":
        """Re-arrange the case to the given input/output names (signals may swap roles, e.g. extras -> inputs)."""
        sig = self.signals
        missing = [s for s in (*inputs, *outputs) if s not in sig]
        if missing:
            raise DataError(f"test case {self.name!r}: missing signals {missing}; it has {sorted(sig)}")
        return TestCase.from_signals(self.name, self.t, sig, tuple(inputs), tuple(outputs), self.group)

    def case_arrays(self, model):
        """``(t, U, Y)`` in the model's input and output order, as writeable float64 copies.

        Parameters
        ----------
        model : reachconf.Model
            Supplies ``input_names`` and ``output_names`` (and ``m``, ``p``).

        Returns
        -------
        t : ndarray (K,)
        U : ndarray (K, m)
        Y : ndarray (K, p)

        Raises
        ------
        DataError
            Naming the case, the model and the signals the case lacks.
        """
        if self.input_names == model.input_names and self.output_names == model.output_names:
            t, U, Y = self.t, self.U, self.Y
        else:
            try:
                sel = self.select(model.input_names, model.output_names)
            except DataError as exc:
                raise DataError(f"test case {self.name!r} does not fit model {model.name!r}: {exc}") from None
            t, U, Y = sel.t, sel.U, sel.Y
        # writeable contiguous copies: the compiled kernels take mutable arrays
        t = np.array(t, dtype=float)
        U = np.array(np.asarray(U, dtype=float).reshape(t.size, model.m), order="C")
        Y = np.array(np.asarray(Y, dtype=float).reshape(t.size, model.p), order="C")
        return t, U, Y

    def with_requests(self, maps=None, inputs=None, suffix: str = "_req") -> "TestCase":
        """The case driven by the requested instead of the measured actuator signals.

        Every input ``u`` (default: each input with a signal ``u + suffix``)
        becomes ``a * u_req + b`` with ``(a, b) = maps[u]`` (default ``(1, 0)``:
        the request itself); the request signals are consumed, other extras kept.

        Parameters
        ----------
        maps : dict input name -> (a, b), optional
            Affine maps from the request to the input's unit (e.g. a steering
            ratio, or a fit of the measured against the requested signal).
        inputs : sequence of str, optional
        suffix : str, default "_req"

        Returns
        -------
        TestCase

        Raises
        ------
        DataError
            If an input has no request signal.
        """
        sig = dict(self.signals)
        inputs = [u for u in self.input_names if u + suffix in sig] if inputs is None else list(inputs)
        missing = [u + suffix for u in inputs if u + suffix not in sig]
        if missing:
            raise DataError(f"test case {self.name!r} has no request signals {missing}")
        maps = dict(maps or {})
        for u in inputs:
            sig[u] = np.polyval(maps.get(u, (1.0, 0.0)), sig.pop(u + suffix))
        return TestCase.from_signals(self.name, self.t, sig, self.input_names, self.output_names, self.group)

    def rename(self, mapping: dict) -> "TestCase":
        """The case with signals renamed (``mapping``: old name -> new name)."""
        sig = {mapping.get(k, k): v for k, v in self.signals.items()}
        ins = tuple(mapping.get(n, n) for n in self.input_names)
        outs = tuple(mapping.get(n, n) for n in self.output_names)
        return TestCase.from_signals(self.name, self.t, sig, ins, outs, self.group)

    def __repr__(self):
        return (f"TestCase({self.name!r}, group={self.group!r}, K={self.t.size}, "
                f"t=[{self.t[0]:g}, {self.t[-1]:g}], inputs={self.input_names}, outputs={self.output_names})")  # fmt: skip


class CaseNotFound(DataError, KeyError):
    """``suite["name"]`` of a case the suite does not hold (a :class:`DataError` and a ``KeyError``)."""

    def __str__(self):  # KeyError would print the message in quotes
        return str(self.args[0]) if self.args else ""


class CaseIndexError(DataError, IndexError):
    """No test case at that position of a suite (an :class:`IndexError` too)."""


class TestSuite:
    """An ordered collection of :class:`TestCase` (iterable, indexable by position or name)."""

    __test__ = False

    def __init__(self, cases, name: str = "suite"):
        if isinstance(cases, TestCase):
            raise DataError(f"test suite {name!r}: cases must be a list of TestCase, got a single TestCase "
                            f"(write TestSuite([case]))")  # fmt: skip
        try:
            self.cases = list(cases)
        except TypeError:
            raise DataError(f"test suite {name!r}: cases must be a list of TestCase, got {type(cases).__name__}") from None
        self.name = name
        if not self.cases:
            raise DataError(f"test suite {name!r} is empty")
        for i, c in enumerate(self.cases):
            if not isinstance(c, TestCase):
                raise DataError(f"test suite {name!r}: cases must be TestCase objects, item {i} is a {type(c).__name__}")
        names = [c.name for c in self.cases]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise DataError(f"test suite {name!r}: duplicate case names {sorted(dup)}")

    def __iter__(self):
        return iter(self.cases)

    def __len__(self):
        return len(self.cases)

    def __getitem__(self, key):
        if isinstance(key, str):
            for c in self.cases:
                if c.name == key:
                    return c
            raise CaseNotFound(f"test suite {self.name!r} has no case {key!r}; cases: {[c.name for c in self.cases]}")
        try:
            return self.cases[key]
        except IndexError:
            raise CaseIndexError(f"test suite {self.name!r} has {len(self.cases)} cases: no case at index {key}") from None
        except TypeError:
            raise DataError(f"test suite {self.name!r}: index by position (int, slice) or case name (str), "
                            f"got {key!r}") from None  # fmt: skip

    def groups(self) -> dict:
        """Group name -> list of cases, in order of first appearance."""
        out: dict = {}
        for c in self.cases:
            out.setdefault(c.group, []).append(c)
        return out

    def select(self, group=None, names=None) -> "TestSuite":
        """Sub-suite of one group (or a list of groups) and/or the given case names."""
        cases = self.cases
        if group is not None:
            groups = {group} if isinstance(group, str) else set(group)
            unknown = groups - set(self.groups())
            if unknown:
                raise DataError(f"test suite {self.name!r} has no group {sorted(unknown)}; groups: {list(self.groups())}")
            cases = [c for c in cases if c.group in groups]
        if names is not None:
            names = set(names)
            cases = [c for c in cases if c.name in names]
        return TestSuite(cases, name=self.name)

    def filter(self, predicate) -> "TestSuite":
        """The cases for which ``predicate(case)`` is true, as a suite."""
        return TestSuite([c for c in self.cases if predicate(c)], name=self.name)

    def segments(self, length: float, partial: bool = True, step: float | None = None) -> "TestSuite":
        """Every case cut into segments of ``length`` seconds (:meth:`TestCase.segments`), as a suite."""
        segments = [s for c in self.cases for s in c.segments(length, partial, step)]
        if not segments:
            why = "every case is shorter than the segment length" if not partial else "no segment of two samples at"
            raise DataError(f"test suite {self.name!r}: {why} {length!r} s" + (" (partial=False keeps no segment)"
                                                                               if not partial else ""))  # fmt: skip
        return TestSuite(segments, name=self.name)

    def map(self, fn) -> "TestSuite":
        """``fn`` applied to every case, as a suite."""
        return TestSuite([fn(c) for c in self.cases], name=self.name)

    def __repr__(self):
        return f"TestSuite({self.name!r}, {len(self)} cases, groups={list(self.groups())})"


def case_arrays(model, case):
    """``case.case_arrays(model)`` for a case passed as an argument, checked to be a :class:`TestCase`.

    Parameters
    ----------
    model : reachconf.Model
    case : TestCase

    Returns
    -------
    t, U, Y : ndarray
        See :meth:`TestCase.case_arrays`.

    Raises
    ------
    DataError
        If ``case`` is not a TestCase (e.g. a whole suite) or lacks the model's signals.
    """
    if not isinstance(case, TestCase):
        hint = "; pass one case of the suite (suite[0])" if isinstance(case, TestSuite) else ""
        raise DataError(f"case must be a reachconf TestCase, got {type(case).__name__}{hint}")
    return case.case_arrays(model)


def suite_cases(suite, where: str) -> list:
    """The cases of ``suite`` (a TestSuite or a sequence of TestCase) as a list; never empty.

    Raises
    ------
    DataError
        ``suite`` is empty, not iterable, or holds something other than
        TestCase (the message starts with ``where``, e.g. ``"synthesize_W"``).
    """
    if isinstance(suite, TestCase):
        raise DataError(f"{where}: suite must be a TestSuite or a list of TestCase, got one TestCase; "
                        "pass TestSuite([case])")  # fmt: skip
    if isinstance(suite, (str, bytes)) or not hasattr(suite, "__iter__"):
        raise DataError(f"{where}: suite must be a TestSuite or a list of TestCase, got {type(suite).__name__}")
    cases = list(suite)
    if not cases:
        raise DataError(f"{where}: the suite is empty (no test cases)")
    bad = [type(c).__name__ for c in cases if not isinstance(c, TestCase)]
    if bad:
        raise DataError(f"{where}: suite must hold TestCase objects, got {bad[0]}")
    return cases
