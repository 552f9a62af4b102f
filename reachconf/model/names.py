"""Checks of the names a model's expressions use, before sympy reads meaning into them.

Two ways a model can silently mean something else than its author wrote:

* in text (``dynamics=["-E*x"]``) an undeclared name that sympy knows is read as sympy's: ``E`` as Euler's
  number, ``I`` as the imaginary unit, ``beta`` or ``gamma`` as functions;
* a symbol created with an assumption on its sign or kind (``sp.Symbol("x", positive=True)``) lets sympy simplify
  before the model sees the expression (``sqrt(x**2) -> x``), which is wrong where a reachable set holds x < 0.
"""

from __future__ import annotations

import re
import warnings
from functools import lru_cache

import sympy as sp

from reachconf.errors import ModelError

__all__ = ["model_expression", "call_with_symbols", "warn_unused_signals", "check_text_names", "check_assumptions"]

_IDENT = re.compile(r"(?<![\w.])([A-Za-z_]\w*)")
#: constants a model may use by their sympy names
_CONSTANTS = {"pi"}


def check_text_names(text: str, declared, where: str, model_name: str) -> None:
    """Refuse names in ``text`` that are not declared and that sympy would read as a constant or a function
    used without a call (``E``, ``I``, ``GoldenRatio``; ``beta`` in ``beta*x``).

    Raises
    ------
    ModelError
        Naming the model, the expression and the name.
    """
    for m in _IDENT.finditer(text):
        name = m.group(1)
        if name in declared or name in _CONSTANTS:
            continue
        meaning = _sympy_meaning(name)
        if meaning is None:
            continue  # not sympy's: the unknown-symbol check names it
        called = text[m.end() :].lstrip().startswith("(")
        if isinstance(meaning, sp.Symbol):
            continue  # an unknown symbol: named by the model's own check
        if callable(meaning) and not isinstance(meaning, sp.Basic):
            if called:
                continue  # a function call: sin(x), atan2(y, x)
            raise ModelError(f"model {model_name!r}: {where} uses {name!r} without a call, which sympy reads as its "
                             f"function {name}(); declare {name!r} as a state, input, disturbance or parameter")  # fmt: skip
        if isinstance(meaning, sp.Basic) and not called:
            raise ModelError(f"model {model_name!r}: {where} uses {name!r}, which sympy reads as {meaning!r}"
                             f"{f' = {float(meaning):.6g}' if meaning.is_real and meaning.is_finite else ''}; declare "
                             f"{name!r} as a state, input, disturbance or parameter"
                             + (" (or write exp(1))" if name == "E" else ""))  # fmt: skip


@lru_cache(maxsize=1024)
def _sympy_meaning(name: str):
    """What sympy reads ``name`` as, or None when it cannot (one parse per name and process)."""
    try:
        return sp.sympify(name)
    except (sp.SympifyError, TypeError, ValueError, SyntaxError, AttributeError):
        return None


def check_assumptions(sym: sp.Symbol, kind: str, where: str, model_name: str) -> None:
    """Refuse a look-alike of a state, input or disturbance created with assumptions beyond ``real``.

    Parameters are fixed numbers, and an assumption on them is the author's statement about their value.
    """
    if kind == "param":
        return
    real = sp.Symbol(sym.name, real=True).assumptions0
    if sym.assumptions0 not in (sp.Symbol(sym.name).assumptions0, real):
        extra = sorted(k for k, v in sym.assumptions0.items() if v and k not in real)
        raise ModelError(f"model {model_name!r}: {where} uses the {kind} {sym.name!r} created with assumptions "
                         f"({', '.join(extra) or sym.assumptions0}): sympy may already have simplified with them "
                         f"(sqrt({sym.name}**2) -> {sym.name}), which is wrong where a set holds other values; "
                         f"create it as sympy.Symbol({sym.name!r}, real=True) or use model.symbols")  # fmt: skip


def model_expression(expr, symbols: dict, param_names, where: str, model_name: str) -> sp.Expr:
    """``expr`` (text or sympy) as a finite scalar sympy expression in the model's own symbols.

    Parameters
    ----------
    symbols : dict name -> sympy.Symbol
        The model's symbols (states, inputs, disturbances, parameters).
    param_names : sequence of str
    where, model_name : str
        For the messages.

    Raises
    ------
    ModelError
        Text that is not an expression; names sympy would read as its own (:func:`check_text_names`);
        unknown symbols, undefined functions, unevaluated derivatives, non-finite numbers; look-alike
        symbols with assumptions (:func:`check_assumptions`).
    """
    if isinstance(expr, str):
        check_text_names(expr, symbols, where, model_name)
    try:
        expr = sp.sympify(expr, locals=dict(symbols))
    except (sp.SympifyError, TypeError) as exc:
        raise ModelError(f"model {model_name!r}: {where} is not a valid expression: {exc}") from None
    if not isinstance(expr, sp.Expr):
        raise ModelError(f"model {model_name!r}: {where} is not a scalar expression: {expr!r}")
    if expr.has(sp.nan, sp.oo, -sp.oo, sp.zoo) or any(abs(a) > 1.7976931348623157e308 for a in expr.atoms(sp.Number)):
        raise ModelError(f"model {model_name!r}: {where} is not finite (as float64): {expr}")
    undefined = sorted({str(f.func) for f in expr.atoms(sp.core.function.AppliedUndef)})
    if undefined:
        raise ModelError(f"model {model_name!r}: {where} uses the undefined function(s) {undefined}; "
                         f"write them out with +, -, *, /, powers and the usual elementary functions")  # fmt: skip
    if expr.has(sp.Derivative, sp.Integral):
        raise ModelError(f"model {model_name!r}: {where} holds an unevaluated derivative or integral: {expr}")
    # replace look-alike symbols (e.g. created without real=True) by the model's
    subs = {}
    for sym in expr.free_symbols:
        own = symbols.get(sym.name)
        if own is None:
            raise ModelError(f"model {model_name!r}: {where} uses the unknown symbol {sym.name!r}; declare it as a "
                             f"state, input, disturbance or parameter")  # fmt: skip
        if own is not sym:
            check_assumptions(sym, "param" if sym.name in param_names else "variable", where, model_name)
            subs[sym] = own
    return expr.xreplace(subs) if subs else expr


def call_with_symbols(fn, symbols, what: str, model_name: str):
    """``fn(symbols)`` for a model's ``dynamics`` or ``outputs`` function; what it raises on sympy symbols (numpy
    functions, comparisons, branches on a symbol) becomes a :class:`ModelError` naming the model."""
    try:
        return fn(symbols)
    except ModelError:
        raise
    except (TypeError, AttributeError, ValueError, NameError, KeyError) as exc:
        hint = ("use sympy's functions (sympy.sin, sympy.exp, ...), not numpy's or math's, and no Python if on a "
                "symbol (sympy.Min/Max/Abs instead)")  # fmt: skip
        raise ModelError(f"model {model_name!r}: {what}(symbols) raised {type(exc).__name__}: {exc}; {hint}"[:500]) from None


def warn_unused_signals(model) -> None:
    """A ``UserWarning`` for disturbances the dynamics do not use and inputs no expression uses: their sets
    mean nothing (a synthesized W gives such a channel width 0), which is most often a typo in a name."""
    in_f = set().union(*(e.free_symbols for e in model.f_expr))
    in_h = set().union(*(e.free_symbols for e in model.h_expr)) if model.h_expr else set()
    sym = dict(zip(model.state_names + model.input_names + model.disturbance_names, model.z_symbols))
    w = [n for n in model.disturbance_names if sym[n] not in in_f]
    u = [n for n in model.input_names if sym[n] not in in_f | in_h]
    if w or u:
        what = "; ".join(part for part in (f"disturbances {w} appear in no dynamics" if w else "",
                                           f"inputs {u} appear in no dynamics or output" if u else "") if part)
        warnings.warn(f"model {model.name!r}: {what} (their sets mean nothing: check the names)", UserWarning,
                      stacklevel=3)  # fmt: skip
