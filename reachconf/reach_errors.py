"""The :class:`~reachconf.errors.ReachError` of a failed reach: what failed, where, what was tried, what to change.

:func:`fixed_step_failure` for the fixed-step algorithms ("lin", "poly"),
:func:`adaptive_failure` for ``algorithm="adaptive"`` (which also says the
smallest step, highest tensor order, splits and error budgets it tried).
"""

from __future__ import annotations

from contextlib import contextmanager

import re

import numpy as np

from reachconf.errors import ReachError

__all__ = ["fixed_step_failure", "adaptive_failure", "wrapping_diagnosis", "STATUS", "TERMS"]

#: the compiled step's status codes (``-1``: the adaptive control's own "rate grew faster than the step")
STATUS = {
    -1: "the error rate grew faster than smaller steps could follow: the set exploded",
    1: "a guarded interval operation failed (division by an interval containing 0, log/sqrt of a "
    "non-positive interval or tan across a pole)",
    2: "the set or its error bound became NaN/inf",
    3: "the abstraction-error bound did not converge (the set grows faster than the linearisation "
    "can follow)",
    4: "the abstraction error exceeded options.max_error",
}
#: the error terms of the step
TERMS = {
    0: "second-order Lagrange remainder (interval Hessian over the set)",
    1: "quadratic term at the linearisation point (quad_map of the Hessian)",
    2: "third-order Lagrange remainder (interval third-order tensor over the set)",
    3: "static quadratic term of 'poly'",
}


def wrapping_diagnosis(model, t: float) -> str:
    """Why the set of a *linear* model exploded, if the wrapping effect explains it ("" otherwise).

    A linear model has no abstraction error, so a set that becomes NaN/inf is grown by the
    order reduction: every step it boxes part of the set in the state axes, and a box grows
    under ``e^{A dt}`` at up to the logarithmic norm ``mu_inf(A) = max_i (a_ii + sum_{j != i}
    |a_ij|)`` per unit time, even when every eigenvalue is stable (a stiff, non-normal ``A``).
    Reported when ``mu_inf(A) t`` exceeds 30 (a growth of e^30 of the rounding-sized boxes).
    """
    try:
        from reachconf.model.modal import affine_parts

        if not model.is_linear():
            return ""
        A = affine_parts(model)[0][:, : model.n]
        lognorm = float(np.max(np.diag(A) + np.sum(np.abs(A), axis=1) - np.abs(np.diag(A))))
        eig = np.linalg.eigvals(A)
        abscissa = float(np.max(eig.real))
        norm, spectral = float(np.max(np.abs(A))), float(np.max(np.abs(eig)))
    except Exception:  # noqa: BLE001 - only a hint: the message stands without it
        return ""
    if np.isfinite(norm) and norm > 1e6 * max(spectral, 1.0):  # e.g. a' = -a + 1e-9 b, b' = 1e9 a - b/2
        return (f" The model is linear, so it has no abstraction error: its matrix A has an entry of {norm:.3g} "
                f"while its eigenvalues are at most {spectral:.3g} in size, so its states' scales differ widely and "
                f"the series of e^(A dt) overflows. Rescale the states: new units in which A's entries are of "
                f"similar size.")
    if not (np.isfinite(lognorm) and lognorm * max(t, 0.0) > 30.0):
        return ""
    return (f" The model is linear, so it has no abstraction error: the set grew by the wrapping effect of the order "
            f"reduction, whose boxes grow at up to the logarithmic norm mu_inf(A) = {lognorm:.3g} 1/s "
            f"(e^{lognorm * t:.3g} after {t:.6g} s) while the eigenvalues' largest real part is {abscissa:.3g} 1/s "
            f"(a stiff, non-normal system). Reach it in coordinates where A is nearly normal, where the boxes do not "
            f"grow: for a diagonalisable A its real modal form z = V^-1 x (reachconf.modal_form(model): reach its "
            f".model from .to_modal(X0)).")


def fixed_step_failure(model, options, status, step, bad_state, bad_term, t_start, dts, err, comp, splits):
    """The ReachError of a failed fixed-step reach ("lin"/"poly"): where, which state and term, what to try."""
    t = float(t_start[step])
    where = f"at t = {t:.6g} s (step {step}, dt = {dts[step]:.3g} s)"
    if status == 1:
        guard = comp.guards[bad_state - 1] if 0 < bad_state <= len(comp.guards) else "an interval operation"
        msg = (f"reachability of model {model.name!r} failed {where}: {guard}. The set has grown into a region "
               f"where the model is not defined; reduce the initial set or W, or use a smaller time_step.")
        return ReachError(msg, time=t, state=None, term="domain")
    state = model.state_names[bad_state] if 0 <= bad_state < model.n else None
    term = TERMS.get(bad_term, "abstraction error")
    detail = f" in state {state!r} through the {term}" if state else ""
    size = f"; error bound there {err[bad_state]:.3g}" if state and np.isfinite(err[bad_state]) else ""
    hints = [f"a smaller time_step (now {dts[step]:.3g})"]
    if options.effective_tensor_order == 2:
        hints.append("tensor_order=3 (or algorithm='poly')")
    hints.append(f"a larger max_splits (used {splits} of {options.effective_max_splits})")
    hints.append("splitting the initial set, or a smaller initial set / disturbance set W")
    wrapping = wrapping_diagnosis(model, t - float(t_start[0])) if status in (-1, 2, 3) else ""
    advice = wrapping or f" Try {', '.join(hints)}."
    msg = f"reachable set of model {model.name!r} exploded {where}{detail}: {STATUS.get(status, '')}{size}.{advice}"
    return ReachError(msg, time=t, state=state, term=term)


def adaptive_failure(model, options, state, t, c, G, smallest, highest, splits, max_splits, dt_min, limit="",
                     steps=0, t0=None) -> ReachError:  # fmt: skip
    """The ReachError of a failed adaptive reach: what was tried, where it failed, what to change.

    ``dt_min`` is the smallest step the run allows; ``limit`` (if any) the step or memory limit it hit.
    """
    from reachconf_kernels import adaptive as ak
    from reachconf_kernels import zonotope as zk

    status = int(state[ak.S_FAIL_CODE])
    bad_state = int(state[ak.S_FAIL_STATE])
    bad_term = int(state[ak.S_FAIL_TERM])
    state_name = model.state_names[bad_state] if status != 1 and 0 <= bad_state < model.n else None
    if status == 1:
        term = "domain"
    elif bad_term < 0:
        term = f"abstraction error of tensor order {-bad_term}"
    else:
        term = TERMS.get(bad_term, "abstraction error")
    lo, hi = zk.interval_hull(np.ascontiguousarray(c), np.ascontiguousarray(G))
    box = ", ".join(f"{nm} in [{a:.4g}, {b:.4g}]" for nm, a, b in zip(model.state_names, lo, hi))
    what = STATUS.get(status, "the step failed")
    if status == 1:  # the guard's own text: which operation, in which expression
        try:
            guards = model.compiled(order=max(int(highest), 2), remainder=options.remainder).guards
            if 0 < bad_state <= len(guards):  # the generated code names the model's symbols s_<name>
                what = "a guarded interval operation failed: " + re.sub(r"\bs_(\w+)", r"\1", guards[bad_state - 1])
        except Exception:  # noqa: BLE001 - the message falls back to the generic text
            pass
    where = f"at t = {t:.6g} s" + (f" in state {state_name!r} through the {term}" if state_name else "")
    tried = (f"time steps down to {smallest:.3g} s (limit {dt_min:.3g} s), tensor order up to "
             f"{highest}, zonotope order up to {options.alg.max_order:g}, {splits} of {max_splits} splits")  # fmt: skip
    hints = []
    if status == 1:
        hints.append("checking where the model is defined (the set reached a region where it is not)")
    if splits >= max_splits:
        hints.append(f"a larger max_splits (now {max_splits})")
    hints.append("a smaller initial set or disturbance set W")
    hints.append(f"a smaller error_budget (now {options.alg.error_budget:g}; smaller keeps the set tighter before "
                 "it reaches this point)")  # fmt: skip
    if limit:
        hints.insert(0, "a larger AdaptiveReach max_steps or more memory, if the sets stay small")
        msg = (f"adaptive reachability of model {model.name!r} stopped at t = {t:.6g} s: {limit}. It tried {tried}. "
               f"The set there: {box}. Try {', '.join(hints)}.")  # fmt: skip
    else:
        wrapping = wrapping_diagnosis(model, t - t0) if status in (-1, 2, 3) and t0 is not None else ""
        failed = "failed" if wrapping else "could not bound the abstraction error"
        msg = (f"adaptive reachability of model {model.name!r} {failed} {where} "
               f"({what}). It tried {tried}. The set there: {box}.{wrapping or ' Try ' + ', '.join(hints) + '.'}")
    info = {"smallest_step": float(smallest), "highest_tensor_order": int(highest),
            "max_order": float(options.alg.max_order), "splits": int(splits), "max_splits": int(max_splits),
            "steps": int(steps)}  # fmt: skip
    return ReachError(msg, time=float(t), state=state_name, term="steps/memory" if limit else term, tried=info)


@contextmanager
def float_failure(model):
    """Turn a division by zero inside the compiled reach loops into a :class:`ReachError`.

    The loops' interval guards compare bounds; once a bound has overflowed to inf and a sum of infinities made it
    NaN (a Jacobian entry such as ``d log(x) / dx = 1 / x`` on a set next to 0), no comparison holds and the
    compiled code divides by zero.  The sets are then meaningless; say so instead of a bare ZeroDivisionError.
    """
    try:
        yield
    except ZeroDivisionError:
        raise ReachError(
            f"reach {model.name}: the sets' bounds overflowed (a division by zero in the compiled reach loop): a "
            "derivative of the model is beyond floating point on the set, as 1/x is near x = 0 (log, sqrt, division); "
            "start the set further from that point, or rescale the states") from None
