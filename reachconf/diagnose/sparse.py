"""Model-free check: which dictionary features explain the disturbance traces (sparse regression).

The per-step disturbance traces of the refitted base model (section 3.2.1)
are regressed on a dictionary of candidate features — the inputs delayed by
several lags, their time derivatives, the measured states and pairwise
products of states and inputs — by sequentially thresholded least squares
(the sparse regression of SINDy: fit, drop the features with small
standardised coefficients, refit).  Each kept feature's share is the drop of
the explained variance when it alone is removed.  This points at effects that
are not in the library (e.g. a lagged input that no library effect models).
"""

from __future__ import annotations

import numpy as np

__all__ = ["feature_dictionary", "sparse_features"]


def feature_dictionary(t, U, Y, input_names, output_names, lags=(0.05, 0.1, 0.2)):
    """Features on the sample intervals ``[t_k, t_k+1)`` (K-1 rows) and their names."""
    K = t.size
    dt = np.diff(t)
    cols, names = [], []
    for j, u in enumerate(U.T):
        cols.append(u[:-1])
        names.append(input_names[j])
        for lag in lags:
            tl = t[:-1] - lag
            cols.append(np.interp(tl, t, u, left=u[0]))
            names.append(f"{input_names[j]}(t-{lag:g}s)")
        cols.append(np.diff(u) / dt)
        names.append(f"d{input_names[j]}/dt")
    for i, y in enumerate(Y.T):
        cols.append(y[:-1])
        names.append(output_names[i])
    base = list(zip(names[:], cols[:]))
    raw = [(n, c) for n, c in base if "(" not in n and not n.startswith("d")]
    for a in range(len(raw)):
        for b in range(a + 1, len(raw)):
            cols.append(raw[a][1] * raw[b][1])
            names.append(f"{raw[a][0]}*{raw[b][0]}")
    F = np.column_stack(cols) if cols else np.zeros((K - 1, 0))
    return F, names


def _stlsq(X, y, threshold=0.05, iterations=10):
    keep = np.ones(X.shape[1], dtype=bool)
    coef = np.zeros(X.shape[1])
    for _ in range(iterations):
        if not keep.any():
            break
        c, *_ = np.linalg.lstsq(X[:, keep], y, rcond=None)
        coef[:] = 0
        coef[keep] = c
        small = np.abs(coef) < threshold * np.max(np.abs(coef))
        new_keep = keep & ~small
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return coef, keep


def _r2(X, y):
    if X.shape[1] == 0:
        return 0.0
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ c
    return 1.0 - float(r @ r) / float(y @ y)


def sparse_features(W_traces, feature_blocks, names, channels, top=3, threshold=0.05, min_share=0.02):
    """Features explaining each disturbance channel (best first, over all channels).

    Parameters
    ----------
    W_traces : list of ndarray (K_i - 1, q)
    feature_blocks : list of ndarray (K_i - 1, F)
    names : list of str
        Feature names.
    channels : sequence of str
        Disturbance names.

    Returns
    -------
    list of dict: ``channel``, ``feature``, ``share`` (explained-variance drop when
    removed), ``r2`` (of the sparse model of that channel).
    """
    F = np.vstack(feature_blocks)
    W = np.vstack(W_traces)
    ok = np.all(np.isfinite(F), axis=1) & np.all(np.isfinite(W), axis=1)
    F, W = F[ok], W[ok]
    mu, sd = F.mean(axis=0), F.std(axis=0)
    useful = sd > 1e-12 * (1 + np.abs(mu))
    Z = (F[:, useful] - mu[useful]) / sd[useful]
    znames = [n for n, u in zip(names, useful) if u]
    out = []
    for i, ch in enumerate(channels):
        y = W[:, i] - W[:, i].mean()
        if not np.any(y):
            continue
        coef, keep = _stlsq(Z, y, threshold)
        idx = np.flatnonzero(keep)
        full = _r2(Z[:, idx], y)
        shares = []
        for j in idx:
            rest = idx[idx != j]
            shares.append((full - _r2(Z[:, rest], y), j))
        for share, j in sorted(shares, reverse=True)[:top]:
            if share >= min_share:
                out.append({"channel": ch, "feature": znames[j], "share": float(share), "r2": float(full)})
    return sorted(out, key=lambda d: -d["share"])
