"""Set-kernel benchmark: compiled kernels against plain numpy/scipy references.

Prints, for a zonotope with n = 6 and m = 100 generators, the time of the
linear map, of Girard reduction to order 10 and of containment of 10,000
points, each with the ratio against a reference written here:
linear map and reduction in plain numpy, containment with one scipy
``linprog`` (HiGHS) per point (timed on a subset and scaled, since 10,000 LPs
take about a minute).

Run: ``python benchmarks/bench_kernel.py``
"""

from __future__ import annotations

import time

import numpy as np

from reachconf import Zonotope
from reachconf.sets import contains_points_lp
from reachconf_kernels import zonotope as zk

N_DIM, N_GEN, ORDER, N_POINTS, N_LP = 6, 100, 10, 10_000, 400


def best_of(fn, repeat=5, number=1):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            out = fn()
        times.append((time.perf_counter() - t0) / number)
    return min(times), out


def numpy_linear_map(M, c, G):
    return M @ c, M @ G


def numpy_girard(c, G, order):
    n = c.size
    n_keep = int(n * (order - 1))
    score = np.abs(G).sum(axis=0) - np.abs(G).max(axis=0)
    idx = np.argsort(-score)
    keep, rest = idx[:n_keep], idx[n_keep:]
    box = np.abs(G[:, rest]).sum(axis=1)
    return c, np.hstack([G[:, keep], np.diag(box)])


def test_points(Z, rng, k):
    """A mix: a quarter sampled inside, a quarter just inside/outside the boundary, half in the hull box."""
    c, G = Z.center, Z.generators
    Y = rng.normal(size=(k // 4, c.size))
    D = np.sign(Y @ G) @ G.T  # extreme points (support points of random directions)
    near = np.vstack([c + D[: k // 8] * 0.999, c + D[k // 8 :] * 1.001])
    inside = Z.sample(k // 4, rng)
    H = Z.interval()
    box = rng.uniform(H.lo, H.hi, size=(k - near.shape[0] - inside.shape[0], c.size))
    return np.vstack([inside, near, box])


def main():
    rng = np.random.default_rng(0)
    Z = Zonotope(rng.normal(size=N_DIM), rng.normal(size=(N_DIM, N_GEN)))
    M = rng.normal(size=(N_DIM, N_DIM))
    c, G = np.array(Z.center), np.array(Z.generators)
    # warm up (numba compilation is cached on disk, the first call still loads it)
    M @ Z
    Z.reduce(ORDER)
    zk.linear_map(M, c, G)
    zk.reduce_girard(c, G, float(ORDER))
    P = test_points(Z, rng, N_POINTS)
    Z.contains(P[:10])

    t_map, _ = best_of(lambda: M @ Z, number=200)
    t_map_np, _ = best_of(lambda: numpy_linear_map(M, c, G), number=200)
    t_red, R = best_of(lambda: Z.reduce(ORDER), number=200)
    t_red_np, _ = best_of(lambda: numpy_girard(c, G, ORDER), number=200)
    t_map_k, _ = best_of(lambda: zk.linear_map(M, c, G), number=2000)
    t_red_k, _ = best_of(lambda: zk.reduce_girard(c, G, float(ORDER)), number=2000)
    t_in, inside = best_of(lambda: Z.contains(P), repeat=3)
    sub = rng.choice(N_POINTS, N_LP, replace=False)
    t_lp_sub, ref = best_of(lambda: contains_points_lp(c, G, P[sub]), repeat=1)
    t_lp = t_lp_sub * N_POINTS / N_LP
    agree = np.array_equal(inside[sub], ref)

    print(f"zonotope n={N_DIM}, m={N_GEN}")
    print(f"linear map           {t_map * 1e6:9.1f} us   numpy {t_map_np * 1e6:9.1f} us   ratio {t_map_np / t_map:6.2f}x")
    print(f"  kernel only        {t_map_k * 1e6:9.1f} us                      ratio {t_map_np / t_map_k:6.2f}x")
    print(f"reduce to order {ORDER:<3d}  {t_red * 1e6:9.1f} us   numpy {t_red_np * 1e6:9.1f} us   ratio {t_red_np / t_red:6.2f}x")
    print(f"  kernel only        {t_red_k * 1e6:9.1f} us                      ratio {t_red_np / t_red_k:6.2f}x")
    print(f"contains {N_POINTS} pts  {t_in:9.3f} s    LP/pt {t_lp:9.3f} s    ratio {t_lp / t_in:6.1f}x "
          f"({inside.mean():.0%} inside; LP timed on {N_LP} points and scaled; agree on them: {agree})")


if __name__ == "__main__":
    main()
