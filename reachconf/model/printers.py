"""Printers of the generated model code: point expressions and straight-line interval code.

:class:`PointPrinter` prints a sympy expression as plain Python over the
``math`` module (numba compiles it); :class:`IntervalEmitter` turns an
expression into straight-line calls of the outward-rounded interval kernel
:mod:`reachconf_kernels.interval` (``I.add``, ``I.mul``, ...), with guards for
operations that are undefined over some intervals (division by an interval
containing 0, logarithms and roots of non-positive intervals, tangents across
a pole).  Used by :mod:`reachconf.model.codegen`.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from reachconf.errors import ModelError

__all__ = ["PointPrinter", "point_code", "interval_constant", "IntervalEmitter", "real_diff", "integer_exponent"]


class _RealAbs(sp.Function):
    """``Abs`` of a real argument: its derivative is ``sign(arg) arg'`` (see :func:`real_diff`)."""

    is_extended_real = True

    def fdiff(self, argindex=1):
        return _RealSign(self.args[0])


class _RealSign(sp.Function):
    """``sign`` of a real argument: its derivative is ``2 DiracDelta(arg) arg'``."""

    is_extended_real = True

    def fdiff(self, argindex=1):
        return 2 * sp.DiracDelta(self.args[0])


def real_diff(expr, symbol):
    """``sp.diff(expr, symbol)`` for a real model expression.

    sympy differentiates ``Abs(g)`` of a ``g`` it cannot prove real (``log(x + 3)``,
    ``sqrt(x + 3)``, ``(x + 3) ** x``) as a complex modulus: ``re``, ``im``, ``arg``,
    ``atan2`` and unevaluated derivatives of ``sign``, which the printers cannot
    print (the model did not build) or which are 0/0 where ``g = 0``.  Every
    argument is real here (the interval code guards the domains), so ``Abs`` and
    ``sign`` are differentiated as real functions.
    """
    if not expr.has(sp.Abs, sp.sign):
        return sp.diff(expr, symbol)
    real = expr.replace(sp.Abs, _RealAbs).replace(sp.sign, _RealSign)
    return sp.diff(real, symbol).replace(_RealAbs, sp.Abs).replace(_RealSign, sp.sign)


def integer_exponent(exp):
    """``exp`` as a sympy Integer when it is a float with an integer value, else ``exp`` unchanged.

    ``x**2.0`` is ``x**2`` for every real ``x``; as a real power the interval
    code required ``x > 0`` (and sympy's derivatives of it hold ``x**1.0``).
    """
    if exp.is_Float and float(exp) == int(exp) and abs(int(exp)) <= 64:
        return sp.Integer(int(exp))
    return exp


class PointPrinter(PythonCodePrinter):
    """Plain-Python printer using the ``math`` module (numba compiles it)."""

    def _print_Rational(self, expr):
        return f"({float(expr.p)!r}/{float(expr.q)!r})"

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_Integer(self, expr):
        return f"{float(expr)!r}"

    def _print_Pow(self, expr, rational=False):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and abs(int(exp)) <= 8:
            k = int(exp)
            b = self.parenthesize(base, 100)
            if k == 0:
                return "1.0"
            prod = "*".join([b] * abs(k))
            return f"({prod})" if k > 0 else f"(1.0/({prod}))"
        if exp == sp.Rational(1, 2):
            return f"math.sqrt({self._print(base)})"
        if exp == sp.Rational(-1, 2):
            return f"(1.0/math.sqrt({self._print(base)}))"
        return f"math.pow({self._print(base)}, {self._print(exp)})"


    # Derivatives of Abs, Min, Max and sign (sympy: sign, Heaviside, DiracDelta) at a point: their values where the
    # function is differentiable.  Only the point Jacobian/Hessian (the expansion) use them; the remainder over a set
    # comes from the tape, whose guards stop a reach whose set crosses a kink (reachconf.model.tape).
    def _print_sign(self, expr):
        a = self._print(expr.args[0])
        return f"(0.0 if ({a}) == 0.0 else math.copysign(1.0, ({a})))"

    def _print_Heaviside(self, expr):
        a = self._print(expr.args[0])
        h0 = self._print(expr.args[1]) if len(expr.args) > 1 else "0.5"
        return f"(1.0 if ({a}) > 0.0 else (0.0 if ({a}) < 0.0 else {h0}))"

    def _print_DiracDelta(self, expr):
        return "0.0"


_POINT = PointPrinter({"fully_qualified_modules": True, "standard": "python3"})


def point_code(expr) -> str:
    """Python source of a point evaluation of ``expr`` (``math`` functions, float constants)."""
    return _POINT.doprint(expr)


def interval_constant(value) -> tuple[str, str]:
    """Outward-rounded float bounds of an exact sympy number."""
    if isinstance(value, (sp.Integer, sp.Rational)):
        frac = Fraction(int(value.p), int(value.q))
    elif isinstance(value, sp.Float):
        frac = Fraction(float(value))  # a sympy Float written by the user is taken as the double it denotes
    else:  # pi, E, ...: evaluate at high precision
        frac = Fraction(sp.Rational(sp.N(value, 40)).p, sp.Rational(sp.N(value, 40)).q)
        approx = float(frac)
        return repr(float(np.nextafter(approx, -np.inf))), repr(float(np.nextafter(approx, np.inf)))
    approx = float(frac)
    if Fraction(approx) == frac:
        return repr(approx), repr(approx)
    lo = approx if Fraction(approx) < frac else float(np.nextafter(approx, -np.inf))
    hi = approx if Fraction(approx) > frac else float(np.nextafter(approx, np.inf))
    return repr(lo), repr(hi)


class IntervalEmitter:
    """Turns sympy expressions into straight-line interval code (pairs of locals)."""

    def __init__(self, var_map: dict, guards: list, indent: str = "    "):
        self.var_map = dict(var_map)  # Symbol -> (lo, hi) code strings
        self.lines: list[str] = []
        self.guards = guards
        self.indent = indent
        self.counter = 0
        self.memo: dict = {}

    def _new(self) -> tuple[str, str]:
        self.counter += 1
        return f"v{self.counter}_lo", f"v{self.counter}_hi"

    def _call(self, fn: str, *args: str) -> tuple[str, str]:
        lo, hi = self._new()
        self.lines.append(f"{self.indent}{lo}, {hi} = I.{fn}({', '.join(args)})")
        return lo, hi

    def _guard(self, condition: str, what: str) -> None:
        self.guards.append(what)
        self.lines.append(f"{self.indent}if {condition}:")
        self.lines.append(f"{self.indent}    return {len(self.guards)}")

    def _step(self, expr) -> tuple[str, str]:
        """``sign`` or ``Heaviside`` over an interval: both are non-decreasing, so ``[phi(lo), phi(hi)]``.

        Over an interval across 0 this is ``[-1, 1]`` (``[0, 1]``), which holds
        the generalised gradients of ``Abs`` (``Min``, ``Max``) at the kink, so
        the mean-value form of :func:`reachconf.model.outputs.output_enclosure`
        stays an enclosure there.
        """
        a_lo, a_hi = self.emit(expr.args[0])
        if isinstance(expr, sp.sign):
            neg, zero, pos = "-1.0", "0.0", "1.0"
        else:
            h0 = expr.args[1] if len(expr.args) > 1 else sp.S.Half
            neg, zero, pos = "0.0", repr(float(h0)), "1.0"
        lo, hi = self._new()
        self.lines.append(f"{self.indent}{lo} = {neg} if {a_lo} < 0.0 else ({zero} if {a_lo} == 0.0 else {pos})")
        self.lines.append(f"{self.indent}{hi} = {pos} if {a_hi} > 0.0 else ({zero} if {a_hi} == 0.0 else {neg})")
        return lo, hi

    def emit(self, expr) -> tuple[str, str]:
        """``(lo, hi)`` code names of the interval value of ``expr`` (emitting the lines that compute it once)."""
        if expr in self.var_map:
            return self.var_map[expr]
        key = expr
        if key in self.memo:
            return self.memo[key]
        result = self._emit(expr)
        self.memo[key] = result
        return result

    def _emit(self, expr) -> tuple[str, str]:
        if expr.is_Number or isinstance(expr, sp.NumberSymbol):
            return interval_constant(expr)
        if expr.is_Symbol:
            raise ModelError(f"internal error: symbol {expr} has no interval value")
        if expr.is_Add:
            args = list(expr.args)
            acc = self.emit(args[0])
            for a in args[1:]:
                acc = self._call("add", *acc, *self.emit(a))
            return acc
        if expr.is_Mul:
            coeff, rest = expr.as_coeff_Mul()
            if coeff == -1:
                return self._call("neg", *self.emit(rest))
            args = list(expr.args)
            acc = self.emit(args[0])
            for a in args[1:]:
                acc = self._call("mul", *acc, *self.emit(a))
            return acc
        if expr.is_Pow:
            base, exp = expr.as_base_exp()
            exp = integer_exponent(exp)
            b = self.emit(base)
            if exp.is_Integer:
                k = int(exp)
                if k == 2:
                    return self._call("sqr", *b)
                if k < 0:
                    self._guard(f"{b[0]} <= 0.0 <= {b[1]}", f"division by an interval containing 0 in {expr}")
                    if k == -1:
                        return self._call("div", "1.0", "1.0", *b)
                return self._call("pow", *b, str(k))
            if exp == sp.Rational(1, 2):
                self._guard(f"{b[0]} < 0.0", f"square root of a negative interval in {expr}")
                return self._call("sqrt", *b)
            if exp == sp.Rational(-1, 2):
                self._guard(f"{b[0]} <= 0.0", f"square root of a non-positive interval in {expr}")
                s = self._call("sqrt", *b)
                return self._call("div", "1.0", "1.0", *s)
            self._guard(f"{b[0]} <= 0.0", f"power of a non-positive interval in {expr}")
            lg = self._call("log", *b)
            e = self.emit(exp)
            return self._call("exp", *self._call("mul", *e, *lg))
        if isinstance(expr, sp.exp):
            return self._call("exp", *self.emit(expr.args[0]))
        if isinstance(expr, sp.log):
            if len(expr.args) != 1:
                raise ModelError(f"log with a base is not supported: {expr}")
            a = self.emit(expr.args[0])
            self._guard(f"{a[0]} <= 0.0", f"logarithm of a non-positive interval in {expr}")
            return self._call("log", *a)
        if isinstance(expr, sp.sin):
            return self._call("sin", *self.emit(expr.args[0]))
        if isinstance(expr, sp.cos):
            return self._call("cos", *self.emit(expr.args[0]))
        if isinstance(expr, sp.tan):
            a = self.emit(expr.args[0])
            c = self._call("cos", *a)
            self._guard(f"{c[0]} <= 0.0 <= {c[1]}", f"tangent across a pole in {expr}")
            return self._call("div", *self._call("sin", *a), *c)
        if isinstance(expr, sp.atan):
            return self._call("atan", *self.emit(expr.args[0]))
        if isinstance(expr, sp.tanh):
            return self._call("tanh", *self.emit(expr.args[0]))
        if isinstance(expr, sp.Abs):
            return self._call("abs", *self.emit(expr.args[0]))
        if isinstance(expr, (sp.Min, sp.Max)):
            fn = "min" if isinstance(expr, sp.Min) else "max"
            args = list(expr.args)
            acc = self.emit(args[0])
            for a in args[1:]:
                acc = self._call(fn, *acc, *self.emit(a))
            return acc
        if isinstance(expr, (sp.sign, sp.Heaviside)):  # derivatives of Abs, Min, Max (in the Jacobian of h)
            return self._step(expr)
        if isinstance(expr, sp.DiracDelta):  # a second derivative of Abs, Min or Max: the legacy tensor path only
            raise ModelError(f"the interval code generator does not support {expr} (a derivative of sign or Heaviside, "
                             f"or a second derivative of Abs, Min or Max): write the model without sign and Heaviside; "
                             f"Abs, Min and Max need remainder='taylor' (the default)")  # fmt: skip
        raise ModelError(
            f"the interval code generator does not support {type(expr).__name__} (in {expr}); "
            f"rewrite the model with +, -, *, /, powers, sqrt, exp, log, sin, cos, tan, atan, tanh, Abs, Min, Max"
        )
