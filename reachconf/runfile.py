"""TOML run files for the command line: model, parameters, sets, options and the test suite.

Example::

    model = "bicycle_closed_loop"      # built-in name or "package.module:attribute"
    suite = "suite"                    # folder, relative to this file
    segment_length = 2.0               # optional: cut the cases into segments of this many seconds
    segment_step = 0.5                 # optional: a new segment every 0.5 s (overlapping); default the length
    workers = 2                        # optional: local worker processes (per case; diagnose: for its fits)
    [params]                           # optional parameter overrides
    c_f = 9.7
    [sets]                             # intervals as [lo, hi] per channel, in the model's order
    W = [[-0.05, 0.05], [-0.05, 0.05], [-0.01, 0.01], [-0.1, 0.1], [-0.1, 0.1], [-0.05, 0.05]]
    V = [[-0.02, 0.02], ...]
    X0 = [[...], ...]                  # optional; default eq. 67 (first sample minus V)
    [sets.X0]                          # or one initial set per case, by case name
    LC_1 = [[...], ...]
    [sets.unmeasured]                  # or eq. 67 for the states that are outputs, these bounds for the others
    v = [-0.5, 0.5]
    [reach]                            # ReachOptions fields
    time_step = 0.02
    [reach_fallback]                   # optional, ReachOptions fields: synth/pareto retry a failed reach with them
    algorithm = "lin"
    tensor_order = 3
    [trace]                            # TraceOptions fields, plus method = "auto" | "perstep" | "optctrl"
    method = "auto"
    [synthesis]                        # SynthesisOptions fields
    alpha_iterations = 10
    [diagnose]                         # reachconf diagnose: effects, holdout, fit_params, seed, reference + DiagnoseOptions
    effects = "all"                    # or a list of names, or of [name, target] pairs
    holdout = 0.3
    fit_params = ["J_m", "c_f"]        # or true / false
    window = 1.0

``segment_length`` (seconds; :meth:`reachconf.io.TestCase.segments`) makes ``reach``, ``conform``,
``synth`` and ``pareto`` check every consecutive stretch of that length from its own first sample (eq. 67)
instead of each whole case: the shorter horizons of the report's section 4.3.3, for recordings too long for
one reach; ``segment_step`` (at most the length) starts one every that many seconds instead (sliding
windows).  They need eq. 67's initial sets (no ``[sets] X0``); ``diagnose`` ignores them.

``[sets] unmeasured`` is for a model with states that are not outputs: each case (or segment) starts from its
first sample minus V for the measured states and from the given bounds for the others
(:func:`reachconf.conformance.initial_set`); with segments the bounds must hold at every segment's start.
``[sets.X0]`` as a table gives each case its own initial set (every checked case needs one).  Neither is used by
``diagnose``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from reachconf.checks import check_workers, require_file
from reachconf.conformance.alpha import missing_initial_sets
from reachconf.conformance.synthesis import SynthesisOptions
from reachconf.conformance.trace import METHODS, TraceOptions
from reachconf.diagnose.effects import EFFECTS
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.errors import DataError, ReachconfError
from reachconf.io.files import load_suite
from reachconf.model.core import Model
from reachconf.model.outputs import unmeasured_bounds
from reachconf.models import get_model
from reachconf.reach_options import ReachOptions
from reachconf.sets.core import Interval

__all__ = ["RunSpec", "load_run", "resolve_model", "diagnose_settings", "select_cases", "input_paths",
           "check_segment_length", "check_segment_step"]  # fmt: skip

_KEYS = {"model", "suite", "segment_length", "segment_step", "params", "sets", "reach", "reach_fallback", "trace",
         "synthesis", "description", "workers", "diagnose"}  # fmt: skip


@dataclass
class RunSpec:
    """A parsed run file."""

    path: Path
    model: object
    suite_path: Path
    W: Interval | None
    V: Interval | None
    X0: Interval | dict | None  # one box, or {case name: box} ([sets.X0] as a table)
    reach_options: object
    trace_method: str
    trace_options: object
    synthesis_options: object
    workers: int | None
    raw: dict
    segment_length: float | None = None
    segment_step: float | None = None
    unmeasured: dict | None = None

    def suite(self):
        """The test suite the run file names (loaded with the model's signal names)."""
        return load_suite(self.suite_path, model=self.model)

    def initial_sets(self, suite) -> dict | None:
        """Each case's initial set from ``[sets]``: ``{case name: set}``, or None for eq. 67 throughout.

        ``X0`` as one box is every case's; ``X0`` as a table must name every case of ``suite``;
        ``unmeasured`` gives eq. 67 for the measured states and its bounds for the others (needs V).
        """
        from reachconf.conformance.reachset import initial_set

        if isinstance(self.X0, Interval):
            return {case.name: self.X0 for case in suite}
        if isinstance(self.X0, dict):
            missing = missing_initial_sets(self.X0, suite)
            if missing:
                raise DataError(f"{self.path}: [sets.X0] has no initial set for the cases {missing} (one [lo, hi] list "
                                f"per case name)")  # fmt: skip
            return {case.name: self.X0[case.name] for case in suite}
        if self.unmeasured is not None:
            if self.V is None:
                raise DataError(f"{self.path}: [sets] unmeasured needs sets.V (eq. 67 for the measured states)")
            return {case.name: initial_set(self.model, case, self.V, self.unmeasured) for case in suite}
        return None

    def synthesis_options_for(self, suite):
        """:attr:`synthesis_options` with ``X0`` set for ``suite``'s cases (:meth:`initial_sets`)."""
        per_case = isinstance(self.X0, dict) or self.unmeasured is not None
        return dataclasses.replace(self.synthesis_options, X0=self.initial_sets(suite) if per_case else self.X0)


def resolve_model(name: str, params=None, where="model", base=None):
    """A built-in model by name or ``module:attribute`` (see :func:`reachconf.models.get_model`).

    ``base``: the run file's folder.  A ``module:attribute`` whose module is not importable but lies there
    (``base/module.py`` or a package ``base/module/``) is imported from there: the folder joins ``sys.path``
    for the rest of the process (the local worker processes inherit it).
    """
    if isinstance(name, str) and ":" in name and base is not None:
        _add_model_folder(name.split(":", 1)[0], Path(base))
    if not isinstance(name, str) or not name:
        raise DataError(f"{where}: model must be a non-empty string, got {name!r}")
    if params is not None and not isinstance(params, dict):
        raise DataError(f"{where}: [params] must be a table of parameter values, got {params!r}")
    for key, value in (params or {}).items():
        if not _is_number(value):
            raise DataError(f"{where}: [params] {key} must be a number, got {value!r}")
    try:
        model = get_model(name)
        if not isinstance(model, Model):
            raise DataError(f"{where}: {name!r} is not a reachconf.Model")
        if params:
            model = model.with_params(**params)
    except ReachconfError as exc:
        raise DataError(f"{where}: {exc}") from None
    return model


def _add_model_folder(module_name: str, base: Path) -> None:
    import importlib.util
    import sys

    top = module_name.split(".", 1)[0]
    if not top or not top.isidentifier():
        return
    try:
        if importlib.util.find_spec(top) is not None:
            return
    except (ImportError, ValueError):
        return
    if (base / f"{top}.py").is_file() or (base / top / "__init__.py").is_file():
        folder = str(base.resolve())
        if folder not in sys.path:
            sys.path.insert(0, folder)


def _folder(base: Path, name: str, where: str) -> Path:
    """``base / name`` resolved; a name no file system takes (a NUL character) is a DataError naming ``where``."""
    try:
        return (base / name).resolve()
    except (OSError, ValueError) as exc:
        raise DataError(f"{where}: {name!r} is not a usable folder name ({exc})") from None


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _interval(value, dim, where) -> Interval:
    ok = isinstance(value, list) and all(isinstance(p, list) and all(_is_number(v) for v in p) for p in value)
    if not ok:
        raise DataError(f"{where}: must be a list of [lo, hi] pairs of numbers, got {value!r}"[:300])
    try:  # the pairs' shape, lo <= hi, finite: Interval.from_list's checks, named with the file and key
        box = Interval.from_list(value)
    except ReachconfError as exc:
        raise DataError(f"{where}: {exc}") from None
    if box.dim != dim:
        raise DataError(f"{where}: has {box.dim} intervals, the model needs {dim}")
    return box


def _table(raw, key, where):
    value = raw.get(key, {})
    if not isinstance(value, dict):
        raise DataError(f"{where}: [{key}] must be a table, got {value!r}"[:300])
    return dict(value)


def _options(cls, table, where, drop=()):
    """``cls(**table)``; every error names the run file, the table and the key."""
    table = {k: v for k, v in dict(table or {}).items() if k not in drop}
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - fields)
    if unknown:
        raise DataError(f"{where}: unknown options {unknown}; allowed: {sorted(fields)}")
    try:
        return cls(**table)
    except (TypeError, ValueError) as exc:  # OptionsError is a ValueError: "ReachOptions.time_step must be ..."
        raise DataError(f"{where} {str(exc).replace(cls.__name__ + '.', '')}") from None


def load_run(path) -> RunSpec:
    """Parse and validate a run file (every error names the file and key)."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise DataError(f"load_run: path must be a run-file path (str or pathlib.Path), got {path!r}")
    path = Path(path)
    require_file(path, "run file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read the run file: {exc.strerror or exc}") from None
    unknown = sorted(set(raw) - _KEYS)
    if unknown:
        raise DataError(f"{path}: unknown keys {unknown}; allowed: {sorted(_KEYS)}")
    if "model" not in raw:
        raise DataError(f"{path}: missing key 'model'")
    model = resolve_model(raw["model"], raw.get("params"), where=f"{path}: model", base=path.parent)
    if "suite" not in raw:
        raise DataError(f"{path}: missing key 'suite' (folder of test cases)")
    if not isinstance(raw["suite"], str) or not raw["suite"]:
        raise DataError(f"{path}: suite must be a folder name (a string), got {raw['suite']!r}")
    if not isinstance(raw.get("description", ""), str):
        raise DataError(f"{path}: description must be a string")
    suite_path = _folder(path.parent, raw["suite"], f"{path}: suite")
    sets = _table(raw, "sets", str(path))
    unknown = sorted(set(sets) - {"W", "V", "X0", "unmeasured"})
    if unknown:
        raise DataError(f"{path}: [sets] unknown sets {unknown}; allowed: W, V, X0, unmeasured")
    W = _interval(sets["W"], model.q, f"{path}: sets.W") if "W" in sets else None
    V = _interval(sets["V"], model.p, f"{path}: sets.V") if "V" in sets else None
    X0 = _initial_sets(sets["X0"], model.n, f"{path}: sets.X0") if "X0" in sets else None
    unmeasured = _unmeasured(sets["unmeasured"], model, f"{path}: sets.unmeasured") if "unmeasured" in sets else None
    if X0 is not None and unmeasured is not None:
        raise DataError(f"{path}: [sets] gives both X0 and unmeasured; give one (unmeasured: eq. 67 for the "
                        f"measured states)")  # fmt: skip
    reach_opts = _reach_options(raw, "reach", path, model)
    fallback = _reach_options(raw, "reach_fallback", path, model) if "reach_fallback" in raw else None
    trace_tab = _table(raw, "trace", str(path))
    method = trace_tab.get("method", "auto")
    if not isinstance(method, str) or method not in METHODS:
        raise DataError(f"{path}: trace.method must be one of {METHODS}, got {method!r}")
    trace_opts = _options(TraceOptions, trace_tab, f"{path}: [trace]", drop=("method",))
    synth_tab = _table(raw, "synthesis", str(path))
    if {"reach", "reach_fallback", "trace", "X0"} & set(synth_tab):
        raise DataError(f"{path}: [synthesis] cannot hold 'reach'/'reach_fallback'/'trace'/'X0': use the [reach], "
                        f"[reach_fallback] and [trace] tables and [sets] X0")  # fmt: skip
    synth_opts = _options(SynthesisOptions, synth_tab, f"{path}: [synthesis]")
    synth_opts = dataclasses.replace(synth_opts, reach=reach_opts, trace=trace_opts, reach_fallback=fallback,
                                     X0=X0 if isinstance(X0, Interval) else None)  # per case: synthesis_options_for
    try:
        workers = check_workers(raw.get("workers"))
    except ReachconfError as exc:
        raise DataError(f"{path}: {exc}") from None
    _table(raw, "diagnose", str(path))
    length, step = raw.get("segment_length"), raw.get("segment_step")
    if length is not None:
        length = check_segment_length(length, f"{path}: segment_length", X0)
    if step is not None:
        step = check_segment_step(step, length, f"{path}: segment_step", "segment_length")
    return RunSpec(path, model, suite_path, W, V, X0, reach_opts, method, trace_opts, synth_opts, workers, raw,
                   length, step, unmeasured)  # fmt: skip


def _reach_options(raw, key, path, model) -> ReachOptions:
    """The ReachOptions of the table ``[key]`` (``reach`` or ``reach_fallback``), ``max_error`` sized to the model."""
    opts = _options(ReachOptions, _table(raw, key, str(path)), f"{path}: [{key}]")
    if isinstance(opts.max_error, (list, tuple)) and len(opts.max_error) not in (1, model.n):
        raise DataError(f"{path}: [{key}] max_error has {len(opts.max_error)} entries, model {model.name!r} has "
                        f"{model.n} states (give one per state, or one number for all)")  # fmt: skip
    return opts


def _initial_sets(value, dim, where):
    """``[sets] X0``: one list of [lo, hi] pairs, or a table of them by case name."""
    if not isinstance(value, dict):
        return _interval(value, dim, where)
    if not value:
        raise DataError(f"{where}: the table of per-case initial sets is empty")
    return {str(name): _interval(box, dim, f"{where}.{name}") for name, box in value.items()}


def _unmeasured(value, model, where) -> dict:
    """``[sets] unmeasured``: a table ``state = [lo, hi]`` of exactly the states that are not outputs."""
    if not isinstance(value, dict):
        raise DataError(f"{where}: must be a table of state = [lo, hi], got {value!r}"[:300])
    for name, pair in value.items():
        if not (isinstance(pair, list) and len(pair) == 2 and all(_is_number(v) for v in pair)):
            raise DataError(f"{where}.{name}: must be a pair [lo, hi] of numbers, got {pair!r}"[:300])
    try:
        bounds = unmeasured_bounds(model, value)
    except ReachconfError as exc:
        raise DataError(f"{where}: {exc}") from None
    return {model.state_names[j]: pair for j, pair in bounds.items()}


def check_segment_length(value, where: str, X0=None) -> float:
    """``value`` as a segment length in seconds (positive, finite); a DataError naming ``where`` if not, or
    if an explicit initial set ``X0`` is given too (it would start every segment from the same set)."""
    if not _is_number(value) or not math.isfinite(value) or value <= 0:
        raise DataError(f"{where} must be a positive number of seconds, got {value!r}")
    if X0 is not None:
        raise DataError(f"{where}: segments start from their own first sample (eq. 67); [sets] X0 would start "
                        f"every segment from the same set — remove one of the two")  # fmt: skip
    return float(value)


def check_segment_step(value, length, where: str, length_name: str) -> float:
    """``value`` as the time between segment starts: positive, at most ``length`` (which must be given)."""
    if length is None:
        raise DataError(f"{where} needs a segment length ({length_name})")
    step = check_segment_length(value, where)
    if step > length:
        raise DataError(f"{where} ({step:g} s) is longer than the segments ({length:g} s): samples between them "
                        f"would be in none")  # fmt: skip
    return step


def input_paths(path) -> tuple[list, list]:
    """``(files, folders)`` a run reads: the run file, and the suite folders it names (``suite``,
    ``[diagnose] reference``) — what no output may overwrite.  Read leniently: a run file that does not
    parse gives just itself (:func:`load_run` reports the problem)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return [path], []
    diag = raw.get("diagnose") if isinstance(raw.get("diagnose"), dict) else {}
    folders = [path.parent / v for v in (raw.get("suite"), diag.get("reference"))
               if isinstance(v, str) and v and "\x00" not in v]  # fmt: skip
    return [path], folders


def select_cases(suite, names, path):
    """The cases ``names`` of ``suite`` (all when ``names`` is empty); a missing name is a DataError naming ``path``."""
    if not names:
        return suite
    have = {c.name for c in suite}
    missing = [c for c in names if c not in have]
    if missing:
        raise DataError(f"{path}: no test case {missing}; cases: {sorted(have)}")
    return suite.select(names=names)


def diagnose_settings(spec: RunSpec, cases=None) -> dict:
    """Keyword arguments of :func:`reachconf.diagnose` from the run file's ``[diagnose]`` table.

    ``reference = "folder"`` (relative to the run file) loads the reference suite, restricted to the case
    names ``cases`` when given (the command line's ``--case`` selection).
    """
    where = f"{spec.path}: [diagnose]"
    table = _table(spec.raw, "diagnose", str(spec.path))
    kwargs = {}
    effects = table.pop("effects", "all")
    if isinstance(effects, list):
        items = []
        for e in effects:
            if isinstance(e, list) and len(e) == 2 and all(isinstance(x, str) for x in e):
                items.append(tuple(e))
            elif isinstance(e, str):
                items.append(e)
            else:
                raise DataError(f"{where}: effects entries must be names or [name, target] pairs, got {e!r}")
        effects = items
    for e in effects if isinstance(effects, list) else [effects]:
        name = e[0] if isinstance(e, tuple) else e
        if name != "all" and name not in EFFECTS:
            raise DataError(f"{where}: unknown effect {name!r}; known: {sorted(EFFECTS)}")
    try:  # each effect on its targets (e.g. a lag on an input the model does not have): named with the file
        from reachconf.diagnose.pipeline import resolve_effects

        candidates = resolve_effects(spec.model, effects)
    except ReachconfError as exc:
        raise DataError(f"{where}: {exc}") from None
    if not candidates:
        raise DataError(f"{where}: effects {effects!r}: no candidate effect applies to model {spec.model.name!r}")
    kwargs["effects"] = effects
    if "holdout" in table:
        h = table.pop("holdout")
        if not _is_number(h) or not 0 < h < 1:
            raise DataError(f"{where}: holdout must be a number in (0, 1), got {h!r}")
        kwargs["holdout"] = h
    if "seed" in table:
        s = table.pop("seed")
        if not isinstance(s, int) or isinstance(s, bool) or s < 0:
            raise DataError(f"{where}: seed must be a non-negative integer, got {s!r}")
        kwargs["seed"] = s
    if "fit_params" in table:
        fp = table.pop("fit_params")
        if not (isinstance(fp, bool) or (isinstance(fp, list) and all(isinstance(x, str) for x in fp))):
            raise DataError(f"{where}: fit_params must be true, false or a list of parameter names")
        unknown = sorted(set(fp) - set(spec.model.param_names)) if isinstance(fp, list) else []
        if unknown:
            raise DataError(f"{where}: fit_params: model has no parameters {unknown}")
        kwargs["fit_params"] = fp
    if "reference" in table:  # the same cases recorded without the change (rc.diagnose(..., reference=))
        ref = table.pop("reference")
        if not isinstance(ref, str):
            raise DataError(f"{where}: reference must be the path of a test-suite folder, got {ref!r}")
        path = _folder(spec.path.parent, ref, f"{where}: reference")
        kwargs["reference"] = select_cases(load_suite(path, model=spec.model), cases, path)
    kwargs["options"] = _options(DiagnoseOptions, table, where)
    return kwargs
