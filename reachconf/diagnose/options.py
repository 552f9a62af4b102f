"""Options of the gap diagnosis (:func:`reachconf.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reachconf.checks import check_field_types
from reachconf.errors import OptionsError

__all__ = ["DiagnoseOptions", "INPUT_HOLDS", "INTERVAL_METHODS", "LOSS_SCALES", "PAST_SPAN_MAX"]


@dataclass(frozen=True)
class DiagnoseOptions:
    """Options of :func:`reachconf.diagnose`.

    The decision thresholds (``z_name``, ``min_improvement``, ``z_separate``)
    and the interval method were chosen on the tuning suites of the
    validation protocol only (``docs/diagnosis-validation.md``) and checked
    on test suites made differently.

    Parameters
    ----------
    window : float, default 1.0
        Length of the multi-step prediction windows (s).
    stride : float, default 1.0
        Time between window starts (s).
    compare_step : float, default 0.05
        Predictions are compared with the measurements every ``compare_step``
        seconds of a window (at least every sample; the integration runs on
        every sample): neighbouring errors of a prediction are nearly equal.
    substeps : int or None, default None
        RK4 steps per sample interval in the predictions; None: enough that
        no step is longer than 0.01 s (one per sample at 100 Hz and above,
        five at 20 Hz; :func:`reachconf.diagnose.residuals.steps_per_sample`).
        With more than one step, a lag's or dead time's output is evaluated
        on every step (held over the step as its mean), not held over the
        whole sample interval: at 20 Hz a 0.03-s lag held per sample came out
        5 % short with a 95 % interval 2 % wide (docs/notes/diagnosis.md,
        "Inputs per substep").
    input_hold : {"zero", "linear"}, default "zero"
        What the inputs did between their samples.  "zero": each recorded
        input was held until the next sample (the sampled-data assumption of
        Alg. 2 and of a controller that runs at the log's rate).  "linear":
        the input moved linearly from one sample to the next (a first-order
        hold: for logs that sample the commands of a faster controller, or a
        continuous signal); the predictions then take the ramp's mean over
        every RK4 step.  The data cannot tell the two apart when a timing
        effect is fitted (a hold shifts the commands by about half a sample,
        which a lag or a dead time absorbs), so it is an option, not a fit:
        on a log decimated to 20 Hz from a 100-Hz controller "zero" gives
        timing effects about 0.02 s short (docs/notes/diagnosis.md, "How the
        inputs were held").  At 100 Hz and above the two differ by at most
        half a sample.  The hold applies to the predictions that choose and
        fit the effects; the minimal W boxes of "how far" use Alg. 2's
        sampled-data inputs either way.
    smooth : int, default 11
        Savitzky–Golay window (samples, quadratic) of smoothed states, at
        most ``smooth_span`` long.
    smooth_span : float or None, default 0.3
        Longest span (s) of the Savitzky–Golay window: at a low sample rate
        the window is the largest odd number of samples (at least 3) whose
        span ``(n - 1) dt`` is within it (7 at 20 Hz; 11 samples are 0.5 s
        there and bias the start states of a fast plant).  None: ``smooth``
        samples at every rate.  Both defaults chosen on first-order plants at
        20 and 50 Hz (docs/notes/diagnosis.md); at 50 Hz and above the window
        is ``smooth``.
    start_state : {"prefix", "auto", "past", "centered"}, default "prefix"
        How each prediction window's start state is estimated from the
        measurements.  "prefix": each window is simulated from the centred
        Savitzky–Golay estimate ``(smooth + 1) / 2`` samples before its start
        (whose last sample is the one before the start) through the
        candidate's own model and effects; only the window's samples are
        scored.  "past": a quadratic extrapolated over the ``2 smooth - 1``
        samples before the start (independent of the sensor noise that the
        recorded commands react to in closed loop); where the state's slope
        jumps with the input within that span it is biased, and a dead time
        absorbs the bias better than a lag (a 0.05-s lag named a dead time at
        50 Hz, span 0.42 s: ``tests/diagnose/test_start_state.py``; 0.03-s
        lags at 100–120 Hz in an outside check).  "auto": "past" while its
        span is at most :data:`PAST_SPAN_MAX` seconds, else "prefix" (the
        default of 3 Dec 2026).  "centered": the smoothed measurement itself
        (uses later samples; for open-loop data).  "prefix" is the default
        since 3 Dec 2026: an outside check (three plants, 20–200 Hz, 370
        suites; ``docs/notes/diagnosis.md``) gave it 363 right names and no
        wrong one ("auto" 4 wrong, "past" 9), and the vehicle protocol's
        test seeds gave the same verdicts as with "past".
    prior : float, default 0.1
        Relative standard deviation of the prior on the base parameters.
    param_bounds : float, default 0.5
        Base parameters stay within ``nominal (1 +- param_bounds)``.
    screen : int, default 6
        Single effects (best by an in-sample fit with the base parameters
        frozen) that are fitted jointly with the base parameters and scored on
        held-out cases.
    pair_top : int, default 4
        The best ``pair_top`` single effects (held-out; among those that beat
        the base with a paired z of at least 1) are also scored in pairs.
    pair_next : int, default 2
        A second effect can be masked by a large first one (screened alone,
        it imitates the first instead): every candidate is screened again
        next to the best single effect, and the best ``pair_next`` of these
        pairs are scored too.
    z_name : float, default 3.0
        An effect (or a second effect) is added only if its held-out gain is
        significant: paired z statistic of the held-out losses over clusters
        (cases) at least ``z_name``.
    min_improvement : float, default 0.35
        ... and relevant: it lowers the held-out prediction loss of the model
        it is added to by at least this share (chosen on the validation
        protocol's 37 tuning suites, 13 of them at 0.5-2 times the
        campaign's noise, with ``start_state="prefix"``: grid objective
        0.844 against 0.820 at 0.4, which misses a -0.6 deg yaw offset at
        twice the noise, and 0.814 at 0.3, which names a tyre saturation
        next to a 0.1-s dead time; docs/diagnosis-validation.md; a second
        effect is judged with the case weights of the first effect's own
        misfit when ``loss_scale="case"``).
    consistent_gain : float, default 0.2
        The consistency route to relevance: an effect whose significant gain
        is below ``min_improvement`` but at least this share is still
        relevant when it is the same in every maneuver group (a model's own
        misfit, absorbed by an effect, changes with the maneuver):
    max_spread : float, default 0.0
        ... the standard deviation of its size (the parameter's distance from
        the effect's null value) fitted on each group alone, relative to the
        mean size, at most this (``reachconf.diagnose.consistency``).
        ``max_spread = 0`` (the default) closes the route: chosen open (0.2)
        on the protocol's tuning suites, it named a small lag of the plant's
        own (tau 0.012-0.018 s, the same in every maneuver) next to the true
        effect in 3 of 32 fresh test suites.
    z_separate : float, default 1.5
        An alternative explanation is ruled out when the chosen one predicts the
        held-out cases better with a paired z of at least ``z_separate``;
        otherwise both are reported as indistinguishable.
    interval : float, default 0.95
        Nominal coverage of the parameter intervals.
    interval_method : {"spread", "case", "group"}, default "spread"
        Parameter intervals: "case" and "group" — the cluster-robust
        (sandwich) covariance with test cases or groups (maneuvers) as
        clusters; "spread" — the spread of the estimates fitted on each group
        alone (a prediction interval for the estimate another maneuver would
        give: it holds the model misfit that makes different maneuvers give
        different values).
    min_clusters : int, default 8
        With fewer cases than this, cases are cut into blocks of windows so
        that the paired tests have at least this many clusters.
    box_rate : float or None, default None
        Sample rate (Hz) the held-out cases are decimated to for the minimal-box scores (*how far*);
        None: the data's own rate.  Decimating holds each input for the longer interval, and the held
        input's error enters the boxes: before 27 Nov the default was 20 Hz, and a DC motor with a 50-ms
        electrical time constant, driven by steps and chirps at 100 Hz, reported its exactly modelled input
        offset as "W shrinks 0.95x" (22x at its own rate); on the vehicle suite of ``bench_diagnose.py``
        2.0x instead of 6.2x, for 2.4 s less of 23.5 s.
    box_segment : float, default 2.0
        The held-out cases are cut into segments of this length (s) for the
        minimal-box scores (the box is the hull of the segments' boxes).
    box_cases : int, default 2
        Number of held-out cases whose minimal boxes are computed before/after.
    tube_horizon : float, default 2.0
        Horizon (s) of the before/after reach tubes of one held-out case (0: none).
    loss_scale : {"sensor", "residual", "case"}, default "case"
        Scale of each output channel in the prediction loss (the standard
        deviation of the Gaussian likelihood that every fit minimises and
        every held-out comparison sums).  "sensor": the sensor noise
        estimated from third differences of the data — right when the
        prediction errors of the correct model are measurement noise.
        "residual": the root-mean-square multi-step prediction residual of the
        refitted base model per channel (at least the sensor noise), after
        which the base model is refitted with it (a two-step weighted least
        squares): each channel counts by its own misfit level, so a channel
        whose predictions carry large errors no effect in the library explains
        (e.g. a velocity integrated from a noisy measured acceleration) does
        not drown the others.  See :func:`reachconf.diagnose.scales.residual_scale`.
        "case": the sensor noise per channel, and each case (run) weighted by
        the inverse of the refitted base model's root-mean-square prediction
        residual on it (at least 1 noise unit), after which the base model is
        refitted: a few runs the base cannot follow (large slip) do not
        dominate the fits and the held-out comparisons.  See
        :func:`reachconf.diagnose.scales.case_weights`.  The default since
        the validation protocol's seed-9 test set: with "sensor", steering
        dead times of 0.12 s and more were found in 1 of 24 test suites (a
        few runs at large slip held nearly all of the loss), with "case" in
        5 of 5.
    reference_loss : {"difference", "excess"}, default "difference"
        With a reference run (``diagnose(..., reference=)``), what each
        model is scored by, window by window
        (:mod:`reachconf.diagnose.reference`).  "excess": its held-out loss
        on the suite minus its held-out loss on the reference.
        "difference": the squared difference of its held-out residuals on
        the suite and on the reference — what the model fitted on each
        recording leaves of the *change* between them; the model's own
        misfit, common to both recordings, cancels residual by residual.
        The default since 26 Nov: on the real car against its clean run,
        10 of 10 injected effects named first (dead times included), against
        8 of 10 with "excess" (dead times indistinguishable from a lag) and
        an ``ax`` scale of 1.1 or a yaw-rate bias of -0.02 rad/s, which move
        the car's own towards none, missed as "no change".
    """

    window: float = 1.0
    stride: float = 1.0
    compare_step: float = 0.05
    substeps: int | None = None
    input_hold: str = "zero"
    smooth: int = 11
    smooth_span: float | None = 0.3
    start_state: str = "prefix"
    prior: float = 0.1
    param_bounds: float = 0.5
    screen: int = 6
    pair_top: int = 4
    pair_next: int = 2
    z_name: float = 3.0
    min_improvement: float = 0.35
    consistent_gain: float = 0.2
    max_spread: float = 0.0
    z_separate: float = 1.5
    interval: float = 0.95
    interval_method: str = "spread"
    min_clusters: int = 8
    box_rate: float | None = None
    box_segment: float = 2.0
    box_cases: int = 2
    tube_horizon: float = 2.0
    loss_scale: str = "case"
    reference_loss: str = "difference"

    def __post_init__(self):
        check_field_types(self)
        for name in ("window", "stride", "compare_step", "prior", "param_bounds", "box_rate", "box_segment",
                     "smooth_span"):  # fmt: skip
            v = getattr(self, name)
            if name in ("box_rate", "smooth_span") and v is None:
                continue
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise OptionsError(f"DiagnoseOptions.{name} must be a positive number, got {v!r}")
        for name in ("substeps", "smooth", "screen", "min_clusters", "box_cases"):
            v = getattr(self, name)
            if name == "substeps" and v is None:
                continue
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1):
                raise OptionsError(f"DiagnoseOptions.{name} must be a positive integer, got {v!r}")
        if not (isinstance(self.pair_top, (int, np.integer)) and self.pair_top >= 0):
            raise OptionsError(f"DiagnoseOptions.pair_top must be an integer >= 0, got {self.pair_top!r}")
        if not (isinstance(self.pair_next, (int, np.integer)) and not isinstance(self.pair_next, bool)
                and self.pair_next >= 0):
            raise OptionsError(f"DiagnoseOptions.pair_next must be an integer >= 0, got {self.pair_next!r}")
        if self.smooth < 3 or self.smooth % 2 == 0:
            raise OptionsError(f"DiagnoseOptions.smooth must be an odd number >= 3, got {self.smooth}")
        for name in ("z_name", "z_separate"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise OptionsError(f"DiagnoseOptions.{name} must be a number >= 0, got {v!r}")
        if not (isinstance(self.min_improvement, (int, float)) and 0 <= self.min_improvement < 1):
            raise OptionsError(f"DiagnoseOptions.min_improvement must be in [0, 1), got {self.min_improvement!r}")
        for name in ("consistent_gain", "max_spread"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and 0 <= v < 1):
                raise OptionsError(f"DiagnoseOptions.{name} must be in [0, 1), got {v!r}")
        if not (isinstance(self.interval, (int, float)) and 0 < self.interval < 1):
            raise OptionsError(f"DiagnoseOptions.interval must be in (0, 1), got {self.interval!r}")
        if self.start_state not in ("auto", "past", "centered", "prefix"):
            raise OptionsError(f"DiagnoseOptions.start_state must be 'auto', 'past', 'prefix' or 'centered', got "
                               f"{self.start_state!r}")  # fmt: skip
        if self.input_hold not in INPUT_HOLDS:
            raise OptionsError(f"DiagnoseOptions.input_hold must be one of {INPUT_HOLDS}, got {self.input_hold!r}")
        if self.interval_method not in INTERVAL_METHODS:
            raise OptionsError(f"DiagnoseOptions.interval_method must be one of {INTERVAL_METHODS}, "
                               f"got {self.interval_method!r}")  # fmt: skip
        if not (isinstance(self.tube_horizon, (int, float)) and self.tube_horizon >= 0):
            raise OptionsError(f"DiagnoseOptions.tube_horizon must be >= 0, got {self.tube_horizon!r}")
        if self.loss_scale not in LOSS_SCALES:
            raise OptionsError(f"DiagnoseOptions.loss_scale must be one of {LOSS_SCALES}, got {self.loss_scale!r}")
        if self.reference_loss not in REFERENCE_LOSSES:
            raise OptionsError(f"DiagnoseOptions.reference_loss must be one of {REFERENCE_LOSSES}, "
                               f"got {self.reference_loss!r}")  # fmt: skip


#: longest span (s) of the "past" start-state estimate that ``start_state="auto"`` uses (0.21 s at 100 Hz with the
#: default ``smooth``, where it was validated); longer spans use "prefix"
PAST_SPAN_MAX = 0.25
#: parameter interval methods (:attr:`DiagnoseOptions.interval_method`)
INTERVAL_METHODS = ("spread", "case", "group")
#: how the inputs are taken to move between their samples (``DiagnoseOptions.input_hold``)
INPUT_HOLDS = ("zero", "linear")
#: per-channel scales of the prediction loss (:attr:`DiagnoseOptions.loss_scale`)
LOSS_SCALES = ("sensor", "residual", "case")
#: what a model is scored by against a reference run (:attr:`DiagnoseOptions.reference_loss`)
REFERENCE_LOSSES = ("difference", "excess")
