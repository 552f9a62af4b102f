"""Random compositions of every supported function: interval enclosures, remainders and derivatives.

A seeded generator writes random expressions over 2-4 variables and a parameter with +, -, *, /, integer,
rational, real and symbolic powers, sqrt, exp, log, sin, cos, tan, atan, tanh, Abs, Min and Max, keeping
every domain valid over a box (arguments of log, sqrt, real powers and denominators shifted above their sampled
minimum; tan's argument within a branch).  On random sub-boxes and zonotopes of directions (wide, touching 0,
tiny; magnitudes from 1e-6 to 1e6) the tape kernels of :mod:`reachconf_kernels.taylor` must enclose

* the values of ``f`` at dense samples and corners (``range_enclosure``, the ``f_iv`` of a model), and
* the exact remainders ``f(p + d) - f(p) - J(p) d`` (order 2) and ``... - 1/2 H(p)[d, d]`` (order 3),
  computed with mpmath at 50 digits (``lagrange_bound``, the ``lagrange_iv`` of a model),

and the printed point code of ``f``, its Jacobian and its Hessian must agree with mpmath.  A failed domain
check (a guard) is allowed; a bound that misses is not.  The slow variant runs 200 models.
"""

import math

import mpmath
import numpy as np
import pytest
import sympy as sp

from reachconf.errors import ModelError
from reachconf.model.codegen import _derivatives
from reachconf.model.printers import point_code, real_diff
from reachconf.model.tape import build_tape
from reachconf_kernels import taylor as TM

OPS = ("add", "sub", "mul", "div", "neg", "exp", "log", "sqrt", "sin", "cos", "tan", "atan", "tanh", "abs", "powi",
       "powr", "rsqrt", "min", "max", "powxy", "scale")  # fmt: skip
_MODULES = [{"Heaviside": lambda x, h0=0.5: mpmath.mpf(1) if x > 0 else (mpmath.mpf(0) if x < 0 else h0),
             "DiracDelta": lambda *a: mpmath.mpf(0), "sign": mpmath.sign, "Min": min, "Max": max}, "mpmath"]  # fmt: skip


class _Gen:
    def __init__(self, rng, z, p, pv, lo, hi):
        self.rng, self.z, self.p, self.pv = rng, z, p, pv
        self.samples = np.vstack([rng.uniform(lo, hi, size=(128, len(z))),
                                  np.array(np.meshgrid(*zip(lo, hi))).reshape(len(z), -1).T])  # fmt: skip

    def values(self, e):
        with np.errstate(all="ignore"):
            v = np.asarray(sp.lambdify([self.z, self.p], e, "numpy")(self.samples.T, self.pv), dtype=float)
        v = np.broadcast_to(v, (self.samples.shape[0],))
        return v[np.isfinite(v)]

    def const(self):
        r = self.rng.random()
        if r < 0.3:
            return sp.Integer(int(self.rng.integers(-5, 6)) or 1)
        if r < 0.5:
            return sp.Rational(int(self.rng.integers(-9, 10)) or 1, int(self.rng.integers(2, 12)))
        if r < 0.55:
            return sp.pi / int(self.rng.integers(1, 5))
        return sp.Float(float(self.rng.uniform(-2, 2) * 10.0 ** self.rng.choice([-6, -1, 0, 0, 1, 6])))

    def leaf(self):
        r = self.rng.random()
        if r < 0.75:
            v = self.z[self.rng.integers(len(self.z))]
            return self.const() * v if self.rng.random() < 0.3 else v
        return self.p[0] if r < 0.85 else self.const()

    def positive(self, e):
        if self.rng.random() < 0.2:
            return sp.Float(float(10.0 ** self.rng.uniform(-3, 1))) + e**2
        v = self.values(e)
        if v.size == 0:
            return 1 + e**2
        lo, hi = v.min(), v.max()
        return e + sp.Float(-lo + (hi - lo + abs(lo) + 1e-300) * float(10.0 ** self.rng.choice([-3, -1, 0])))

    def bounded(self, e, limit):
        v = self.values(e)
        m = np.abs(v).max() if v.size else 0.0
        return sp.Float(limit / m) * e if m > limit else e

    def expr(self, depth=0):
        if depth >= 4 or (depth > 0 and self.rng.random() < 0.3):
            return self.leaf()
        op = OPS[self.rng.integers(len(OPS))]
        a = lambda: self.expr(depth + 1)  # noqa: E731
        if op in ("add", "sub", "mul", "min", "max"):
            x, y = a(), a()
            return {"add": x + y, "sub": x - y, "mul": x * y, "min": sp.Min(x, y), "max": sp.Max(x, y)}[op]
        if op == "div":
            return a() / self.positive(a())
        if op == "neg":
            return -a()
        if op == "scale":
            return self.const() * a()
        if op == "exp":
            return sp.exp(self.bounded(a(), float(self.rng.choice([3.0, 30.0]))))
        if op in ("log", "sqrt", "rsqrt"):
            e = self.positive(a())
            return {"log": sp.log(e), "sqrt": sp.sqrt(e), "rsqrt": 1 / sp.sqrt(e)}[op]
        if op in ("sin", "cos", "atan", "tanh", "abs"):
            return {"sin": sp.sin, "cos": sp.cos, "atan": sp.atan, "tanh": sp.tanh, "abs": sp.Abs}[op](a())
        if op == "tan":  # the argument's sampled range mapped into (-1.5, 1.5)
            e = a()
            v = self.values(e)
            if v.size == 0:
                return sp.tan(sp.atan(e) / 2)
            c, r = 0.5 * (v.min() + v.max()), 0.5 * (v.max() - v.min())
            if not r > 1e-6 * abs(c):  # (nearly) constant over the box: no scaling that large
                return sp.tan(sp.atan(e) / 2)
            return sp.tan(sp.Float(float(self.rng.uniform(0.3, 1.4)) / r) * (e - sp.Float(c)))
        if op == "powi":
            k = int(self.rng.choice([2, 3, 4, 5, -1, -2, -3]))
            e = self.positive(a()) if k < 0 else a()
            return self.bounded(e, 1e30 ** (1.0 / abs(k))) ** k
        if op == "powr":
            ex = self.rng.choice([sp.Rational(3, 2), sp.Rational(1, 3), sp.Rational(-3, 2), sp.Float(0.7),
                                  sp.Float(-0.3), sp.Rational(7, 3)])  # fmt: skip
            return self.positive(a()) ** ex
        return self.positive(a()) ** self.bounded(a(), 3.0)  # powxy


def _magnitude(e):
    """``e`` with every sum and product of its top level taken over the magnitudes of the terms."""
    if e.is_Add or e.is_Mul:
        return e.func(*[_magnitude(a) for a in e.args])
    return sp.Abs(e)


def _model(seed):
    """Expressions, variables (the last one fixed: an input), parameter, its value and the domain box."""
    rng = np.random.default_rng(seed)
    nz = int(rng.integers(2, 5))
    z = tuple(sp.Symbol(f"z{j}", real=True) for j in range(nz))
    p = (sp.Symbol("k", real=True),)
    pv = np.array([float(rng.uniform(-2, 2))])
    scale = 10.0 ** rng.choice([0, 0, 0, -6, 6], size=nz) if rng.random() < 0.6 else np.ones(nz)
    c, r = scale * rng.uniform(-2, 2, nz), scale * 10.0 ** rng.uniform(-3, 0.3, nz)
    lo, hi = c - r, c + r
    touch = rng.random(nz)
    lo, hi = np.where(touch < 0.15, 0.0, lo), np.where(touch < 0.15, 2 * r, hi)
    lo, hi = np.where((touch >= 0.15) & (touch < 0.25), -r, lo), np.where((touch >= 0.15) & (touch < 0.25), r, hi)
    gen = _Gen(rng, z, p, pv, lo, hi)
    exprs = [gen.expr() for _ in range(int(rng.integers(1, 4)))]
    return exprs, z, p, pv, lo, hi, rng


class _Ref:
    def __init__(self, exprs, z, p, pv):
        self.f = sp.lambdify([z, p], exprs, _MODULES)
        J = [[real_diff(e, v) for v in z] for e in exprs]
        self.J = sp.lambdify([z, p], J, _MODULES)
        self.H = sp.lambdify([z, p], [[[real_diff(d, v) for v in z] for d in row] for row in J], _MODULES)
        self.exprs, self.Jexprs = exprs, J
        self.p = [mpmath.mpf(float(v)) for v in pv]

    def __call__(self, fn, zm, pm=None):
        try:
            v = fn(zm, self.p if pm is None else pm)
        except (ZeroDivisionError, ValueError, OverflowError, TypeError):
            return None
        flat = np.ravel(np.array(v, dtype=object))
        return v if all(isinstance(x, mpmath.mpf) and mpmath.isfinite(x) for x in flat) else None


def _tape(exprs, z, p, nz):
    class M:  # the fields of a model _derivatives reads
        pass

    m = M()
    m.z_symbols, m.f_expr, m.h_expr = z, tuple(exprs), ()
    _, _, hess, third, _, _ = _derivatives(m, 3)
    moving = list(range(nz - 1))  # the last variable is a known input
    return build_tape(exprs, z, p, [], directional=moving, tensors={2: hess, 3: third})


def _check_model(seed, boxes=4, zonotopes=4, samples=24, points=1):
    exprs, z, p, pv, lo, hi, rng = _model(seed)
    nz, n = len(z), len(exprs)
    try:
        tape = _tape(exprs, z, p, nz)
    except (ModelError, OverflowError):  # refused, as compile_model refuses it with a ModelError: sympy rewrote a
        return 0  # power of a parameter with atan2, or the expanded form's float constants overflow (1 in 200 each)
    ref = _Ref(exprs, z, p, pv)
    mpmath.mp.dps = 50
    M = mpmath.mpf
    checked = 0
    # f over sub-boxes
    for b in range(boxes):
        a, c = rng.uniform(lo, hi), rng.uniform(lo, hi)
        blo, bhi = (np.minimum(a, c), np.maximum(a, c)) if b else (lo.copy(), hi.copy())
        olo, ohi = np.zeros(n), np.zeros(n)
        if TM.range_enclosure(tape.ops, tape.consts, tape.outs, tape.segments, blo, bhi, pv, olo, ohi) != 0:
            continue
        pts = np.vstack([rng.uniform(blo, bhi, size=(samples, nz)),
                         np.array(np.meshgrid(*zip(blo, bhi))).reshape(nz, -1).T])  # fmt: skip
        for x in pts:
            v = ref(ref.f, [M(t) for t in x])
            if v is None:
                continue
            for i in range(n):
                checked += 1
                assert M(olo[i]) <= v[i] <= M(ohi[i]), (seed, i, exprs[i], blo, bhi, x, olo[i], ohi[i], v[i])
    # remainders over zonotopes of directions (the input fixed)
    for _ in range(zonotopes):
        zp = rng.uniform(lo, hi)
        width = (hi - lo) * 10.0 ** rng.uniform(-6, -0.5)
        g = int(rng.integers(1, nz + 2))
        dG = rng.normal(size=(nz, g)) * width[:, None] / np.sqrt(g)
        dc = rng.uniform(-0.3, 0.3, nz) * width
        dG[-1], dc[-1] = 0.0, 0.0
        rad = np.abs(dG).sum(axis=1)
        dlo, dhi = np.nextafter(dc - rad, -np.inf), np.nextafter(dc + rad, np.inf)
        dlo[-1] = dhi[-1] = 0.0
        zlo, zhi = np.nextafter(zp + np.minimum(dlo, 0.0), -np.inf), np.nextafter(zp + np.maximum(dhi, 0.0), np.inf)
        zlo[-1] = zhi[-1] = zp[-1]
        bounds = {}
        for K in (2, 3):
            out = np.zeros(n)
            status = TM.lagrange_bound(tape.ops, tape.consts, tape.outs, tape.tens, tape.segments, zlo, zhi, dlo, dhi,
                                       zp, dc, dG, pv, K, out)  # fmt: skip
            if status == 0:
                bounds[K] = out
        zpm = [M(t) for t in zp]
        f0, J0, H0 = ref(ref.f, zpm), ref(ref.J, zpm), ref(ref.H, zpm)
        if not bounds or f0 is None or J0 is None or H0 is None:
            continue
        beta = np.vstack([rng.uniform(-1, 1, size=(samples // 2, g)), np.where(rng.random((samples // 2, g)) < 0.5,
                                                                                -1.0, 1.0)])  # fmt: skip
        for bv in beta:
            d = [M(dc[j]) + mpmath.fsum(M(dG[j, k]) * M(bv[k]) for k in range(g)) for j in range(nz)]
            f1 = ref(ref.f, [a + b for a, b in zip(zpm, d)])
            if f1 is None:
                continue
            for i in range(n):
                jd = [J0[i][j] * d[j] for j in range(nz)]
                hq = [H0[i][j][k] * d[j] * d[k] for j in range(nz) for k in range(nz)]
                r2 = f1[i] - f0[i] - mpmath.fsum(jd)
                # sympy rounds products of float constants in the derivatives: a few ulps of the terms
                noise = 1e-14 * (abs(f1[i]) + abs(f0[i]) + sum(abs(t) for t in jd) + sum(abs(t) for t in hq))
                for K, r in ((2, r2), (3, r2 - mpmath.fsum(hq) / 2)):
                    if K in bounds:
                        checked += 1
                        assert abs(r) <= M(bounds[K][i]) + noise, (seed, K, i, exprs[i], zp, d, bounds[K][i], r)
    # printed point code of f, J, H at unit-scale points of the box
    for _ in range(points):
        x = rng.uniform(lo, hi)
        env = {"math": math, **{s.name: float(v) for s, v in zip(z, x)}, "k": float(pv[0])}
        zm = [M(t) for t in x]
        for e, je in zip(exprs, ref.Jexprs):
            for expr in [e, *je, *(real_diff(d, v) for j, d in enumerate(je) for v in z[j:])]:
                want = ref(sp.lambdify([z, p], expr, _MODULES), zm)
                if want is None:
                    continue
                try:
                    got = eval(point_code(expr), env)
                except (ZeroDivisionError, ValueError, OverflowError):
                    continue
                checked += 1
                # conditioning: the value a few ulps away in every variable and parameter
                near = ref(sp.lambdify([z, p], expr, _MODULES), [t * (1 + M(4e-16)) for t in zm],
                           [t * (1 + M(4e-16)) for t in ref.p])  # fmt: skip
                spread = abs(near - want) if near is not None else M(0)
                # and the float rounding of sums that cancel: the sum of the terms' magnitudes
                terms = ref(sp.lambdify([z, p], _magnitude(expr), _MODULES), zm)
                slack = 1e-12 * terms if terms is not None else M(0)
                assert abs(got - want) <= 1e-9 * abs(want) + 1e3 * spread + slack + 1e-300, (seed, expr, x, got, want)
    return checked


def test_random_compositions_are_enclosed():
    total = sum(_check_model(seed) for seed in range(20))
    assert total > 1000


@pytest.mark.slow
def test_random_compositions_are_enclosed_many():
    total = sum(_check_model(seed, boxes=6, zonotopes=6, samples=40, points=2) for seed in range(1000, 1200))
    assert total > 10000
