"""Linear reach against exact trajectories: random A (oscillatory, defective, singular, unstable, stiff), inputs.

``x' = A x + B u + E w + k`` with known inputs ``u`` (one row per sample time, non-uniform samples), a
disturbance set ``W`` (a box or a zonotope with a non-zero centre) and a zonotope ``X0``, from t0 = 0 and 1e6.
Trajectories with piecewise-constant disturbances (bang-bang on the vertices, uniform inside, constant corners;
switching off the sample grid) are exact: each constant piece is ``e^{A h} x + int_0^h e^{A s} ds f`` from the
matrix exponential.  Every state must lie in the time-point set at its sample and, at both stamps and inside
every step, in the time-interval set of that step.
"""

import numpy as np
import pytest
import scipy.linalg as sla

import reachconf as rc

N, M, Q = 3, 1, 2


def _model():
    names = [f"x{i}" for i in range(N)]
    params = {f"a{i}{j}": 0.0 for i in range(N) for j in range(N)}
    params.update({f"b{i}": 0.0 for i in range(N)})
    params.update({f"e{i}{j}": 0.0 for i in range(N) for j in range(Q)})
    params.update({f"k{i}": 0.0 for i in range(N)})

    def f(s):
        return [sum(s[f"a{i}{j}"] * s[names[j]] for j in range(N)) + s[f"b{i}"] * s.u
                + sum(s[f"e{i}{j}"] * s[f"w{j}"] for j in range(Q)) + s[f"k{i}"] for i in range(N)]  # fmt: skip

    return rc.Model(name="linear_fuzz", states=names, inputs=("u",), disturbances=("w0", "w1"), params=params,
                    dynamics=f)  # fmt: skip


MODEL = _model()


def _case(seed, kind, t0):
    rng = np.random.default_rng(seed)
    V = np.eye(N) + 0.3 * rng.normal(size=(N, N))
    if kind == "oscillatory":
        w = rng.uniform(1, 8)
        A = V @ np.array([[-0.1, w, 0], [-w, -0.1, 0], [0, 0, -0.5]]) @ np.linalg.inv(V)
    elif kind == "defective":
        A = V @ (rng.uniform(-0.5, 0.2) * np.eye(N) + np.diag([1.5, 1.5], 1)) @ np.linalg.inv(V)
    elif kind == "singular":
        A = rng.normal(size=(N, 1)) @ rng.normal(size=(1, N))
        A *= 0.5 / max(1.0, abs(np.trace(A)))
    elif kind == "unstable":
        A = V @ np.diag([0.8, -0.3, 0.1]) @ np.linalg.inv(V)
    else:  # stiff: eigenvalues from -1e-3 to -1e3
        A = V @ np.diag([-1e-3, -1.0, -1e3]) @ np.linalg.inv(V)
    B = rng.normal(size=N)
    E = rng.normal(size=(N, 1)) @ rng.normal(size=(1, Q)) if seed % 2 else rng.normal(size=(N, Q))  # rank 1 or 2
    k = rng.normal(size=N)
    p = {f"a{i}{j}": A[i, j] for i in range(N) for j in range(N)}
    p.update({f"b{i}": B[i] for i in range(N)})
    p.update({f"e{i}{j}": E[i, j] for i in range(N) for j in range(Q)})
    p.update({f"k{i}": k[i] for i in range(N)})
    wc = rng.normal(size=Q)
    W = rc.Interval(wc - 0.3, wc + 0.3) if seed % 3 else rc.Zonotope(wc, 0.3 * rng.normal(size=(Q, 3)))
    X0 = rc.Zonotope(rng.normal(size=N) * 3, 0.1 * rng.normal(size=(N, 4)))
    times = t0 + np.concatenate([[0.0], np.cumsum(rng.uniform(0.1, 0.6, 6))])
    U = rng.normal(size=(times.size, M))
    return MODEL.with_params(**p), A, np.column_stack([B, E, k]), X0, W, times, U


def _simulate(A, F, X0, W, times, U, queries, rng, count=200):
    """States at ``queries`` (count, len(queries), n) of exact piecewise-constant runs."""
    Z, Wz = X0.to_zonotope(), W.to_zonotope()
    x = Z.center + rng.choice([-1.0, 1.0], size=(count, Z.generators.shape[1])) @ Z.generators.T
    x[count // 2 :] = Z.center + rng.uniform(-1, 1, size=(count - count // 2, Z.generators.shape[1])) @ Z.generators.T
    switches = np.sort(rng.uniform(times[0], times[-1], 25))
    grid = np.unique(np.concatenate([queries, switches, times]))
    b = rng.uniform(-1, 1, size=(count, switches.size + 1, Wz.generators.shape[1]))
    b[: count // 3] = np.sign(b[: count // 3])  # bang-bang
    b[count // 3 : count // 2] = np.sign(b[count // 3 : count // 2, :1])  # one corner all the time
    w = Wz.center + b @ Wz.generators.T  # (count, pieces, q)
    qi = {t: i for i, t in enumerate(queries)}
    out = np.empty((count, queries.size, A.shape[0]))
    out[:, qi[grid[0]]] = x
    for a, e in zip(grid[:-1], grid[1:]):
        n = A.shape[0]
        Mx = np.zeros((2 * n, 2 * n))
        Mx[:n, :n], Mx[:n, n:] = A * (e - a), np.eye(n) * (e - a)
        Ex = sla.expm(Mx)
        u = U[np.searchsorted(times, 0.5 * (a + e)) - 1]
        piece = np.searchsorted(switches, 0.5 * (a + e))
        forcing = np.column_stack([np.broadcast_to(u, (count, 1)), w[:, piece], np.ones(count)]) @ F.T
        x = x @ Ex[:n, :n].T + forcing @ Ex[:n, n:].T
        if e in qi:
            out[:, qi[e]] = x
    return out


def _check(seed, kind, t0, options):
    model, A, F, X0, W, times, U = _case(seed, kind, t0)
    tube = rc.reach(model, X0, times, inputs=U, W=W, options=options)
    rng = np.random.default_rng(seed + 1)
    I = tube.time_intervals
    inner = I[:, :1] + (I[:, 1:] - I[:, :1]) * rng.uniform(0, 1, size=(len(I), 2))
    queries = np.unique(np.concatenate([times, I.ravel(), inner.ravel()]))
    X = _simulate(A, F, X0, W, times, U, queries, rng)
    qi = {t: i for i, t in enumerate(queries)}
    for k, t in enumerate(times):
        inside = tube.time_point_sets[k].contains(X[:, qi[t]])
        assert inside.all(), f"{kind} t0={t0}: time point {k}: {np.count_nonzero(~inside)} outside"
    for s in range(len(I)):
        P = np.vstack([X[:, qi[t]] for t in (I[s, 0], I[s, 1], *inner[s])])
        inside = tube.time_interval_sets[s].contains(P)
        assert inside.all(), f"{kind} t0={t0}: step {s} {I[s]}: {np.count_nonzero(~inside)} outside"
    return tube


LIN = rc.ReachOptions(algorithm="lin", time_step=0.02, taylor_terms=8, zonotope_order=20)


@pytest.mark.parametrize("seed, kind, t0", [(1, "oscillatory", 1e6), (2, "singular", 0.0)])
@pytest.mark.parametrize("options", [None, LIN], ids=["adaptive", "lin"])
def test_linear_reach_contains_exact_trajectories(seed, kind, t0, options):
    _check(seed, kind, t0, options)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["oscillatory", "defective", "singular", "unstable", "stiff"])
@pytest.mark.parametrize("t0", [0.0, 1e6])
def test_linear_reach_contains_exact_trajectories_more(kind, t0):
    for seed in range(10, 14):
        _check(seed, kind, t0, None)
        if kind != "stiff":  # (0.02-s steps are far too long for an eigenvalue of -1e3)
            _check(seed, kind, t0, LIN)
