"""ARCH-COMP nonlinear benchmarks (specs in ``../shared/research/cora.md`` section 7)."""

from __future__ import annotations

from reachconf.model.core import Model

__all__ = ["vanderpol", "coupled_vanderpol", "laub_loomis"]


def vanderpol(mu: float = 1.0) -> Model:
    """Van der Pol oscillator ``x' = y``, ``y' = mu (1 - x^2) y - x``.

    ARCH-COMP NLN (mu = 1): ``x0 in [1.25, 1.55] x [2.35, 2.45]``, ``T = 7``,
    specification ``y < 2.75``.
    """
    return Model(
        name="vanderpol",
        states=("x", "y"),
        params={"mu": mu},
        dynamics=lambda s: [s.y, s.mu * (1 - s.x**2) * s.y - s.x],
        description="Van der Pol oscillator (ARCH-COMP NLN)",
    )


def coupled_vanderpol(mu: float = 1.0) -> Model:
    """Two coupled Van der Pol oscillators (4-D, ARCH-COMP NLN 2020/21).

    ``x1' = y1``, ``y1' = mu (1 - x1^2) y1 - 2 x1 + x2`` and the same with the
    indices swapped.  ARCH (mu = 1): both oscillators start in
    ``[1.25, 1.55] x [2.35, 2.45]``, ``T = 7``, specification ``y1, y2 <= 2.75``.
    """
    return Model(
        name="coupled_vanderpol",
        states=("x1", "y1", "x2", "y2"),
        params={"mu": mu},
        dynamics=lambda s: [
            s.y1,
            s.mu * (1 - s.x1**2) * s.y1 - 2 * s.x1 + s.x2,
            s.y2,
            s.mu * (1 - s.x2**2) * s.y2 - 2 * s.x2 + s.x1,
        ],
        description="two coupled Van der Pol oscillators (ARCH-COMP NLN)",
    )


def laub_loomis() -> Model:
    """Laub–Loomis 7-D model of enzymatic activity (ARCH-COMP NLN).

    ``x0 = (1.2, 1.05, 1.5, 2.4, 1, 0.1, 0.45) ± W`` with W in {0.01, 0.05, 0.1},
    ``T = 20``; specification ``x4 < 4.5`` (W = 0.01, 0.05) or ``x4 < 5`` (W = 0.1).
    """

    def f(s):
        return [
            1.4 * s.x3 - 0.9 * s.x1,
            2.5 * s.x5 - 1.5 * s.x2,
            0.6 * s.x7 - 0.8 * s.x2 * s.x3,
            2 - 1.3 * s.x3 * s.x4,
            0.7 * s.x1 - s.x4 * s.x5,
            0.3 * s.x1 - 3.1 * s.x6,
            1.8 * s.x6 - 1.5 * s.x2 * s.x7,
        ]

    return Model(
        name="laub_loomis",
        states=tuple(f"x{i}" for i in range(1, 8)),
        dynamics=f,
        description="Laub-Loomis 7-D benchmark (ARCH-COMP NLN)",
    )
