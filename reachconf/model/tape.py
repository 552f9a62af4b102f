"""Record sympy expressions as a tape for interval Taylor-mode evaluation.

:func:`build_tape` turns the right-hand side ``f`` of a model into the
operation list that :mod:`reachconf_kernels.taylor` evaluates in truncated
Taylor arithmetic with interval coefficients.  The tape bounds the Lagrange
remainders of conservative linearisation (order 2) and of tensor order 3
(order 3) — the terms of source report section 4.3.1 — without writing out
the Hessian or the third-order tensor symbolically: its length is the number
of distinct sub-expressions of ``f`` (shared sub-expressions are recorded
once), so building it takes milliseconds and nothing model-specific is
compiled.

Why this and not the alternatives (measured, see ``benchmarks/bench_codegen.py``):
the symbolic third-order tensor grows with ``nz^3`` and its interval code took
minutes to compile (12 min for the rate-limited steering actuator ``r tanh(k
e / r)``); common-subexpression elimination with lazy per-component
compilation still compiles code proportional to the tensor; the mean-value
form with the interval Hessian (``1/2 dz^T ([H] - H(p)) dz``) is about three
times looser than the third-order term.  Taylor mode along the direction ``d``
costs one pass over the expression graph and is, on the built-in models,
as tight as the tensor contraction or tighter (the direction box is used with
its signs, and univariate functions get exact derivative ranges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from reachconf.errors import ModelError
from reachconf.model.printers import integer_exponent, interval_constant
from reachconf_kernels import taylor as T

__all__ = ["Tape", "build_tape", "graph_size", "interval_bounds", "TENSOR_BUDGET"]

#: derivative entries of an output are recorded when their graph is at most this many times the output's (+ 64)
TENSOR_BUDGET = 4.0


def interval_bounds(value) -> tuple[float, float]:
    """Outward-rounded float bounds of an exact sympy number (or number symbol such as pi)."""
    lo, hi = interval_constant(value)
    return float(lo), float(hi)


@dataclass(frozen=True)
class Tape:
    """Operations of :mod:`reachconf_kernels.taylor` (see its docstring for the layout).

    Attributes
    ----------
    ops : ndarray of int64, shape (N, 7)
    consts : ndarray of float64, shape (C, 2)
    outs : ndarray of int64, shape (F, n)
        Node of each expression in each of the F recorded forms (all enclose
        the same function; the kernel keeps the tightest).
    tens : ndarray of int64, shape (E, 6)
        Recorded derivative-tensor entries ``[K, i, node, j, k, l]``.
    segments : ndarray of int64, shape (6 + 2 n,)
        Row ranges (Taylor rows, order-2 entries, order-3 entries), the
        per-output completeness flags and whether any affine node is flagged (see
        :func:`reachconf_kernels.taylor.lagrange_bound`).
    """

    ops: np.ndarray
    consts: np.ndarray
    outs: np.ndarray
    tens: np.ndarray
    segments: np.ndarray

    @property
    def size(self) -> int:
        """Number of operations."""
        return int(self.ops.shape[0])


_UNIVARIATE = {
    sp.exp: T.OP_EXP,
    sp.sin: T.OP_SIN,
    sp.cos: T.OP_COS,
    sp.atan: T.OP_ATAN,
    sp.tanh: T.OP_TANH,
}


class _Recorder:
    def __init__(self, z_symbols, p_symbols, guards, directional):
        self.z_index = {s: i for i, s in enumerate(z_symbols)}
        self.p_index = {s: i for i, s in enumerate(p_symbols)}
        self.directional = set(range(len(z_symbols))) if directional is None else set(directional)
        self.moving = tuple(s for s, i in self.z_index.items() if i in self.directional)
        self.grouped = False
        self.atoms: dict = {}  # placeholder symbol -> expression (see _Freezer)
        self.fixed = 0  # > 0: recording the derivative entries of that order (variables of degree 0, own nodes)
        self.guards = guards
        self.rows: list[list[int]] = []
        self.support: list[frozenset] = []
        self.consts: list[tuple[float, float]] = []
        self.const_index: dict = {}
        self.memo: dict = {}

    # ------------------------------------------------------------ helpers
    def deg(self, node: int) -> int:
        return self.rows[node][T.COL_DEG]

    def add_row(self, op, a=-1, b=-1, aux=0, deg=0, guard_text=None) -> int:
        guard = 0
        if guard_text is not None:
            self.guards.append(guard_text)
            guard = len(self.guards)
        deg = min(int(deg), T.MAX_ORDER)
        self.rows.append([op, a, b, aux, deg, guard, 0])
        # moving variables a node depends on; an affine node of two or more of them that feeds a nonlinear
        # node is flagged: the kernel then takes its range from the zonotope of the set (affine_ranges)
        support = {aux} if op == T.OP_VAR and deg == 1 else set()
        for operand in (a, b):
            if operand >= 0 and op != T.OP_CONST:
                support |= self.support[operand]
                if deg > 1 and self.rows[operand][T.COL_DEG] == 1 and len(self.support[operand]) > 1:
                    self.rows[operand][T.COL_FLAG] = 1
        self.support.append(frozenset(support))
        return len(self.rows) - 1

    def const_slot(self, lo: float, hi: float) -> int:
        """Append ``[lo, hi]`` to the constant table and return its index (taken at once, before anything else records)."""
        self.consts.append((lo, hi))
        return len(self.consts) - 1

    def const(self, lo: float, hi: float) -> int:
        key = (lo, hi, self.fixed)
        node = self.const_index.get(key)
        if node is None:
            node = self.add_row(T.OP_CONST, aux=self.const_slot(lo, hi))
            self.const_index[key] = node
        return node

    def binary(self, op, a, b) -> int:
        da, db = self.deg(a), self.deg(b)
        deg = da + db if op == T.OP_MUL else max(da, db)
        return self.add_row(op, a, b, deg=deg)

    def unary(self, op, a, guard_text=None, aux=0) -> int:
        return self.add_row(op, a, aux=aux, deg=0 if self.deg(a) == 0 else T.MAX_ORDER, guard_text=guard_text)

    # ------------------------------------------------------------ walk
    def emit(self, expr) -> int:
        key = (expr, self.grouped, self.fixed)
        node = self.memo.get(key)
        if node is None:
            node = self._emit(expr)
            self.memo[key] = node
        return node

    def _sum(self, terms) -> int:
        acc = self.emit(terms[0])
        for arg in terms[1:]:
            coeff, rest = arg.as_coeff_Mul()
            if coeff == -1:  # a - b rather than a + (-b)
                acc = self.binary(T.OP_SUB, acc, self.emit(rest))
            else:
                acc = self.binary(T.OP_ADD, acc, self.emit(arg))
        return acc

    def _grouped_sum(self, terms) -> int:
        """Terms with the same non-affine factor share it: ``sum_m phi_m(z) * (affine form in z)``.

        Cancellations between terms of one monomial (e.g. the front and rear
        tyre forces' ``v_y / v_x``) then happen in the exact coefficients,
        not between independent intervals.
        """
        groups: dict = {}  # non-affine factor -> {moving symbol or 1: [coefficients]}
        for term in terms:
            coeff, moving = term.as_independent(*self.moving, as_Add=False)
            lin, rest = sp.S.One, []
            for factor in sp.Mul.make_args(moving):
                if lin == 1 and factor.is_Symbol:
                    lin = factor
                else:
                    rest.append(factor)
            groups.setdefault(sp.Mul(*rest), {}).setdefault(lin, []).append(coeff)
        if sum(len(v) for v in groups.values()) == len(terms):
            return self._sum(terms)  # nothing to combine
        acc = None
        for rest, by_symbol in groups.items():
            cof = None
            for lin, coeffs in by_symbol.items():
                c = self._sum(coeffs) if len(coeffs) > 1 else self.emit(coeffs[0])
                node = c if lin == 1 else self.binary(T.OP_MUL, c, self.emit(lin))
                cof = node if cof is None else self.binary(T.OP_ADD, cof, node)
            node = cof if rest == 1 else self.binary(T.OP_MUL, cof, self.emit(rest))
            acc = node if acc is None else self.binary(T.OP_ADD, acc, node)
        return acc

    def _emit(self, expr) -> int:
        if expr.is_Number or isinstance(expr, sp.NumberSymbol):
            return self.const(*interval_bounds(expr))
        if expr.is_Symbol:
            if expr in self.z_index:
                j = self.z_index[expr]
                return self.add_row(T.OP_VAR, aux=j, deg=1 if j in self.directional and not self.fixed else 0)
            if expr in self.p_index:
                return self.add_row(T.OP_PARAM, aux=self.p_index[expr])
            if expr in self.atoms:
                return self.emit(self.atoms[expr])
            raise ModelError(f"internal error: symbol {expr} is neither a variable nor a parameter")
        if expr.is_Add:
            return self._grouped_sum(list(expr.args)) if self.grouped else self._sum(list(expr.args))
        if expr.is_Mul:
            coeff, rest = expr.as_coeff_Mul()
            if coeff == -1:
                a = self.emit(rest)
                return self.add_row(T.OP_NEG, a, deg=self.deg(a))
            args = list(expr.args)
            acc = self.emit(args[0])
            for arg in args[1:]:
                acc = self.binary(T.OP_MUL, acc, self.emit(arg))
            return acc
        if expr.is_Pow:
            return self._pow(expr)
        for cls, op in _UNIVARIATE.items():
            if isinstance(expr, cls):
                return self.unary(op, self.emit(expr.args[0]))
        if isinstance(expr, sp.log):
            if len(expr.args) != 1:
                raise ModelError(f"log with a base is not supported: {expr}")
            return self.unary(T.OP_LOG, self.emit(expr.args[0]), f"logarithm of a non-positive interval in {expr}")
        if isinstance(expr, sp.tan):
            return self.unary(T.OP_TAN, self.emit(expr.args[0]), f"tangent across a pole in {expr}")
        if isinstance(expr, sp.Abs):
            a = self.emit(expr.args[0])
            text = f"Abs of an interval containing 0 (not differentiable there) in {expr}"
            return self.add_row(T.OP_ABS, a, deg=self.deg(a), guard_text=text)
        if isinstance(expr, (sp.Min, sp.Max)):
            op = T.OP_MIN if isinstance(expr, sp.Min) else T.OP_MAX
            text = f"{type(expr).__name__} whose arguments cross inside the set (not differentiable there) in {expr}"
            args = list(expr.args)
            acc = self.emit(args[0])
            for arg in args[1:]:
                b = self.emit(arg)
                acc = self.add_row(op, acc, b, deg=max(self.deg(acc), self.deg(b)), guard_text=text)
            return acc
        raise ModelError(
            f"the interval code generator does not support {type(expr).__name__} (in {expr}); "
            f"rewrite the model with +, -, *, /, powers, sqrt, exp, log, sin, cos, tan, atan, tanh, Abs, Min, Max"
        )

    def _pow(self, expr) -> int:
        base, exp = expr.as_base_exp()
        exp = integer_exponent(exp)  # x**2.0 is x**2, defined for x <= 0 too
        if exp.is_Integer:
            k = int(exp)
            if k == 0:
                return self.const(1.0, 1.0)
            if k == 1:
                return self.emit(base)
            b = self.emit(base)
            if k > 0:
                return self.add_row(T.OP_POWI, b, aux=k, deg=k * self.deg(b))
            text = f"division by an interval containing 0 in {expr}"
            return self.unary(T.OP_POWI, b, text, aux=k)
        if exp == sp.Rational(1, 2):
            return self.unary(T.OP_SQRT, self.emit(base), f"square root of an interval reaching 0 or below in {expr}")
        text = f"power of a non-positive interval in {expr}"
        if exp.is_Number:
            b = self.emit(base)  # first: recording the base may append constant rows
            slot = self.const_slot(*interval_bounds(exp))  # exponent row, not a node
            return self.unary(T.OP_POWR, b, text, aux=slot)
        # x**y = exp(y log x)
        lg = self.unary(T.OP_LOG, self.emit(base), text)
        return self.unary(T.OP_EXP, self.binary(T.OP_MUL, self.emit(exp), lg))


def build_tape(exprs, z_symbols, p_symbols, guards: list, directional=None, grouped: bool = True,
               tensors: dict | None = None, tensor_budget: float = TENSOR_BUDGET) -> Tape:
    """Record ``exprs`` (functions of ``z_symbols`` and ``p_symbols``) as a :class:`Tape`.

    Parameters
    ----------
    exprs : sequence of sympy expressions
    z_symbols, p_symbols : sequences of sympy symbols
        The variables (index ``j`` reads ``zlo[j], zhi[j], dlo[j], dhi[j]``)
        and the parameters (read from ``p``).
    guards : list of str
        Messages of the guarded operations; each guard appends its message and
        the kernel returns its 1-based position on a domain error.
    directional : iterable of int, optional
        Indices of the variables whose direction can be non-zero (default:
        all).  The others are treated as fixed (their ``dlo, dhi`` are not
        read): the known inputs ``u`` of a reach step.
    grouped : bool, default True
        Also record each expression expanded, with the terms that share a
        non-affine factor grouped (``sum_m phi_m(z) * affine_m(z)``); the
        kernel takes, per expression, the tighter of the two enclosures.
    tensors : dict, optional
        ``{2: {(i, j, k): expr}, 3: {(i, j, k, l): expr}}``: the unique
        (``j <= k <= l``) non-zero second and third derivatives of ``exprs``.
        An output's entries are recorded too (their interval contraction
        encloses the same remainder; the kernel keeps the smaller bound) when
        their expression graph has at most ``tensor_budget`` times as many
        nodes as the output's own (plus 64): small tensors add tightness
        (they combine terms symbolically) at little cost, large ones (e.g.
        the third derivatives of ``tanh`` of a long sum) are left to Taylor
        mode.
    tensor_budget : float, default TENSOR_BUDGET

    Raises
    ------
    ModelError
        On a function the interval arithmetic does not support.
    """
    rec = _Recorder(tuple(z_symbols), tuple(p_symbols), guards, directional)
    exprs = [sp.sympify(e) for e in exprs]
    n = len(exprs)
    tensors = tensors or {}
    complete = np.zeros((2, n), dtype=np.int64)
    for order in (2, 3):
        for i in range(n):
            if order in tensors:
                mine = [e for key, e in tensors[order].items() if key[0] == i]
                # derivatives of Abs, Min, Max (sign, Heaviside, DiracDelta) are left to Taylor mode, whose guards
                # stop a set that crosses the kink; an output with such an entry has no tensor form at all
                smooth = not any(e.has(sp.DiracDelta, sp.Heaviside, sp.sign) for e in mine)
                complete[order - 2, i] = smooth and graph_size(mine) <= tensor_budget * graph_size([exprs[i]]) + 64
    outs = []
    if grouped:
        rec.grouped = True
        frozen = _Freezer(rec.moving, rec.atoms)
        outs.append([rec.emit(_expanded(frozen(e))) for e in exprs])
        rec.grouped = False
    # the expression as written: always without grouping; with it, where no tensor backs the grouped form up
    outs.append([rec.emit(e) if not grouped or not complete[:, i].all() else outs[0][i] for i, e in enumerate(exprs)])
    segments = [len(rec.rows)]
    tens = []
    for order in (2, 3):
        start = len(rec.rows)
        rec.fixed = order
        keys = [key for key in (tensors.get(order) or {}) if complete[order - 2, key[0]]
                and all(j in rec.directional for j in key[1:])]  # the direction of a fixed variable is 0
        if keys:
            # the forms the symbolic generator evaluated (sympy's cse with its "basic" preprocessing,
            # factor_terms); the cse symbols become placeholders of their sub-expressions
            reps, reduced = sp.cse([tensors[order][key] for key in keys], symbols=sp.numbered_symbols(cls=sp.Dummy),
                                   optimizations="basic")  # fmt: skip
            rec.atoms.update(reps)
            for key, e in zip(keys, reduced):
                tens.append([order, key[0], rec.emit(e), *key[1:], *([-1] if order == 2 else [])])
        rec.fixed = 0
        segments += [start, len(rec.rows)]
    ops = np.array(rec.rows, dtype=np.int64).reshape(-1, T.TAPE_COLUMNS)
    consts = np.array(rec.consts, dtype=np.float64).reshape(-1, 2)
    return Tape(ops=ops, consts=consts, outs=np.array(outs, dtype=np.int64).reshape(len(outs), n),
                tens=np.array(tens, dtype=np.int64).reshape(-1, 6),
                segments=np.concatenate([np.array(segments, dtype=np.int64), complete.ravel(),
                                         [int(ops[: segments[0], T.COL_FLAG].any())]]))


class _Freezer:
    """Replaces the parts of an expression free of moving variables by placeholder symbols.

    Within a product the fixed factors become one placeholder, within a sum
    the fixed terms; expanding the result then yields coefficients that are
    products of a few placeholders instead of long products of parameters.
    """

    def __init__(self, moving, atoms: dict):
        self.moving = set(moving)
        self.atoms = atoms  # placeholder -> expression
        self.known: dict = {}  # expression -> placeholder

    def placeholder(self, expr):
        if expr.is_Number or expr.is_Symbol:
            return expr
        sym = self.known.get(expr)
        if sym is None:
            sym = sp.Dummy("fixed", real=True)
            self.known[expr] = sym
            self.atoms[sym] = expr
        return sym

    def __call__(self, expr):
        if not (expr.free_symbols & self.moving):
            return self.placeholder(expr)
        if expr.is_Mul or expr.is_Add:
            fixed = [a for a in expr.args if not (a.free_symbols & self.moving)]
            rest = [self(a) for a in expr.args if a.free_symbols & self.moving]
            if len(fixed) > 1:
                fixed = [self.placeholder(expr.func(*fixed))]
            return expr.func(*fixed, *rest)
        if not expr.args:
            return expr
        return expr.func(*[self(a) for a in expr.args])


def graph_size(exprs) -> int:
    """Number of distinct sub-expressions of ``exprs`` (the nodes of their shared graph)."""
    seen: set = set()
    stack = list(exprs)
    while stack:
        e = stack.pop()
        if e not in seen:
            seen.add(e)
            stack.extend(e.args)
    return len(seen)


def _expanded(expr):
    """Products distributed over sums; powers of sums kept (so that ``(a - b)^3 / (a - b)`` cancels)."""
    return sp.expand(expr, deep=True, mul=True, multinomial=False, power_exp=False, power_base=False, log=False)
