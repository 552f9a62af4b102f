"""The result of :func:`reachconf.diagnose`: where the gap lies, which effect causes it, how far W shrinks."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reachconf.errors import OptionsError
from reachconf.io.results import JsonResult
from reachconf.plot import plot_measured, save_figure

__all__ = ["GapReport"]


def _plain(x):
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


@dataclass
class GapReport(JsonResult):
    """Sim-to-real gap diagnosis of a model on a suite.

    Attributes
    ----------
    where : dict
        Gap location (:class:`~reachconf.diagnose.locate.GapLocation` as a dict:
        channel shares, time segments per case and group, operating
        conditions) and, if the suite has requested and measured actuator
        signals, ``actuator_vs_process``.
    ranked_effects : list of dict
        Every scored model (one or two effects), lowest held-out prediction
        loss first: ``label``, ``parts`` ([[effect, target], ...]),
        ``held_out_loss``, ``prediction_gain`` (share of the base model's
        held-out loss removed), ``z_vs_base``, ``admissible``, ``tests``,
        ``params_by_effect`` (mean over the folds); single effects also
        ``effect``, ``target``, ``params``.  Then the effects left out by the
        screening (``screen_cost``, no held-out scores).
    verdict : str
    base : dict
        The refitted base model: ``params``, ``prediction_cost``, ``box``, ``V_box``.
    combination : dict or None
        Unused since the decision scores pairs of effects itself (kept for old JSON readers; always None).
    features : list of dict
        Model-free check: dictionary features that explain the disturbance traces.
    before_after : dict
        Minimal trace-conformant W (and V) of the base and the best model, per channel, with shrink factors.
    split : dict
        Training and held-out case names of the first fold (disjoint) and every case's fold.
    decision : dict
        Machine-readable verdict: ``status`` ("named", "indistinguishable" or
        "none"), ``model`` (label of the chosen model), ``named`` (per effect:
        ``effect``, ``target``, ``params``, ``params_std`` and ``interval``
        from the all-cases fit with the cluster-robust covariance),
        ``alternatives`` (explanations the data cannot separate from the
        chosen one: ``label``, ``parts``, ``z``, ``differs``, ``effects``,
        ``separating`` — the probe maneuver that would separate them — and
        ``data_band_shares``), ``admissible``, ``tests``, ``thresholds``;
        with a reference run (``diagnose(..., reference=)``) also
        ``reference``: ``excess_loss``, ``share`` (of the suite's base loss)
        and ``z`` of the base model's excess misfit over it, ``loss``
        (``options.reference_loss``) and ``difference_loss`` (the base's
        squared residual difference, with ``"difference"``) — the shares in
        ``tests`` and the ranked entries' ``prediction_gain`` are then of the
        base's loss of the change.
    """

    where: dict
    ranked_effects: list
    verdict: str
    base: dict = field(default_factory=dict)
    combination: dict | None = None
    features: list = field(default_factory=list)
    before_after: dict = field(default_factory=dict)
    split: dict = field(default_factory=dict)
    seconds: float = 0.0
    decision: dict = field(default_factory=dict)
    cpu_seconds: float = 0.0
    tubes: list = field(default_factory=list, repr=False)  # before/after reach tubes (not serialised)
    scores: dict = field(default_factory=dict, repr=False)  # held-out losses per window and model (not serialised)

    @property
    def best(self) -> dict | None:
        """The model with the lowest held-out loss, named or not (``ranked_effects[0]``), or None."""
        return self.ranked_effects[0] if self.ranked_effects else None

    @property
    def status(self) -> str:
        """"named", "indistinguishable" or "none"."""
        return self.decision.get("status", "none")

    @property
    def named(self) -> list:
        """The named effects (``effect``, ``target``, ``params``, ``params_std``, ``interval``)."""
        return list(self.decision.get("named", []))

    def to_dict(self) -> dict:
        """The report as plain JSON values (NaN and inf as None); the reach tubes are left out."""
        return _plain({"where": self.where, "ranked_effects": self.ranked_effects, "verdict": self.verdict,
                       "base": self.base, "combination": self.combination, "features": self.features,
                       "before_after": self.before_after, "split": self.split, "seconds": self.seconds,
                       "cpu_seconds": self.cpu_seconds, "decision": self.decision})  # fmt: skip

    def summary(self, top: int = 5) -> str:
        """Markdown summary."""
        lines = ["# Sim-to-real gap diagnosis", "", f"**Verdict:** {self.verdict}", ""]
        dec = self.decision
        if dec.get("named"):
            lines += ["## Named", "", "| effect | target | parameter | estimate | robust std | "
                      f"{100 * dec['thresholds']['interval']:.0f} % interval |", "|---|---|---|---|---|---|"]  # fmt: skip
            for e in dec["named"]:
                for p, v in e["params"].items():
                    lo, hi = e["interval"][p]
                    lines.append(f"| {e['effect']} | {e['target']} | {p} | {_f(v, '.4g')} | {_f(e['params_std'][p], '.2g')} | "
                                 f"[{_f(lo, '.4g')}, {_f(hi, '.4g')}] |")  # fmt: skip
            lines.append("")
            note = timing_hold_note(dec)
            if note:
                lines += [note, ""]
        for a in dec.get("alternatives", []):
            lines.append(f"- Indistinguishable from **{a['label']}** (held-out z = {_f(a['z'], '.1f')})"
                         + _separating_text(a.get("separating")))
        lines += ["", "## Which effect (held-out prediction, cross-fitted)", "",
                  "| rank | model | parameters (mean over folds) | held-out loss | gain vs base | z vs base | "
                  "admissible |", "|---|---|---|---|---|---|---|"]  # fmt: skip
        for i, e in enumerate([e for e in self.ranked_effects if e.get("held_out_loss") is not None][:top]):
            ps = "; ".join(f"{lab}: " + ", ".join(f"{k} = {v:.4g}" for k, v in pv.items())
                           for lab, pv in e["params_by_effect"].items())  # fmt: skip
            lines.append(f"| {i + 1} | {e['label']} | {ps} | {_f(e['held_out_loss'], '.4g')} | "
                         f"{_pct(e['prediction_gain'])} | {_f(e['z_vs_base'], '.1f')} | "
                         f"{'yes' if e['admissible'] else 'no'} |")  # fmt: skip
        lines.append(f"| - | base (refitted) | | {_f(self.base.get('held_out_loss'), '.4g')} | | | |")
        if self.before_after:
            lines += ["", "## How far it shrinks (minimal trace-conformant boxes, held-out cases)", "",
                      "| set | channel | base | with effect | shrink |", "|---|---|---|---|---|"]  # fmt: skip
            for setname in ("W", "V", "W_reachset"):
                for ch, row in self.before_after.get(setname, {}).items():
                    lines.append(f"| {setname} | {ch} | [{_f(row['before'][0], '.4g')}, {_f(row['before'][1], '.4g')}] | "
                                 f"[{_f(row['after'][0], '.4g')}, {_f(row['after'][1], '.4g')}] | {_f(row['shrink'], '.2f')} |")  # fmt: skip
            lines += ["", "Shrink: the ratio of the boxes' sizes about 0 (2 max(|lo|, |hi|), so an offset counts), each "
                          "W size plus a floor of 5 % of its channel's disturbance-trace spread: a channel taken to "
                          "nearly 0 shows a finite factor."]  # fmt: skip
        loc = self.where.get("location", {})
        if loc:
            lines += ["", "## Where", ""]
            for ch, sh in sorted(loc.get("shares", {}).items(), key=lambda kv: -(kv[1] if kv[1] is not None else -np.inf)):
                drv = ", ".join(f"{o} (rho {_f(v, '.2f')})" for o, v in list(loc.get("drivers", {}).get(ch, {}).items())[:2]
                                if v is not None and v > 0.3)  # fmt: skip
                lines.append(f"- {ch}: {_pct(sh)} of the normalised disturbance box"
                             + (f", driven by the errors of {drv}" if drv else ""))  # fmt: skip
            for g, segs in loc.get("group_segments", {}).items():
                for s in segs[:3]:
                    lines.append(f"- {s['channel']}, {_f(s['t0'], '.1f')}-{_f(s['t1'], '.1f')} s of {_pct(s['share'])} of the {g} runs")
            for ch, corr in loc.get("conditions", {}).items():
                best = list(corr.items())[:3]
                if best:
                    lines.append(f"- |{ch}| grows with " + ", ".join(f"{k} (rho {_f(v, '+.2f')})" for k, v in best))
        for tb in self.tubes:  # the picture's tubes: a reach that failed is said here too
            if "error" in tb:
                lines += ["", f"Reach tube ({tb['label']}) of the held-out case: not drawn, the reach failed: {tb['error']}"]
        avp = self.where.get("actuator_vs_process")
        if avp:
            lines += ["", f"Actuator vs process: {avp['verdict']}"]
        if self.features:
            lines += ["", "## Model-free check (sparse regression of the disturbance traces)", ""]
            for f in self.features[:top]:
                lines.append(f"- {f['channel']}: {f['feature']} explains {_pct(f['share'])} of the variance")
        lines += ["", f"{self.base.get('folds', '?')} folds; first fold: {len(self.split.get('train', []))} "
                  f"training, {len(self.split.get('test', []))} held-out cases; {self.seconds:.1f} s "
                  f"({self.cpu_seconds:.1f} s CPU)."]  # fmt: skip
        return "\n".join(lines) + "\n"

    @classmethod
    def from_dict(cls, d: dict) -> "GapReport":
        """The report from :meth:`to_dict` (without the reach tubes, which are not saved)."""
        return cls(d["where"], list(d["ranked_effects"]), d["verdict"], dict(d.get("base", {})), d.get("combination"),
                   list(d.get("features", [])), dict(d.get("before_after", {})), dict(d.get("split", {})),
                   float(d.get("seconds", 0.0)), dict(d.get("decision", {})), float(d.get("cpu_seconds", 0.0)))  # fmt: skip

    def plot(self, ax=None, kind: str = "effects"):
        """One picture of the report; returns its axes (``None`` when the report has no data for it).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            For ``kind="boxes"`` one per disturbance channel.  (A folder
            instead writes every picture, as :meth:`save_plots`.)
        kind : {"effects", "boxes", "tubes"}
            The scored models by their held-out prediction gain (admissible
            ones in green); the
            per-channel minimal W before/after; the reach tubes of a held-out
            case before/after with its measurements.
        """
        import matplotlib.pyplot as plt

        if isinstance(ax, (str, Path)):  # the old plot(out): write the PNGs
            return self.save_plots(ax)
        if kind == "effects":
            scored = [e for e in self.ranked_effects if e.get("held_out_loss") is not None]
            if not scored:
                return None
            if ax is None:
                _, ax = plt.subplots(figsize=(7, 0.4 * len(scored) + 1.5))
            labels = [e["label"] for e in scored][::-1]
            colors = ["tab:green" if e["admissible"] else "tab:gray" for e in scored][::-1]
            ax.barh(labels, [100 * e["prediction_gain"] for e in scored][::-1], color=colors)
            ax.axvline(0.0, color="k", lw=0.8)
            ax.set_xlabel("held-out prediction loss removed vs the base model [%] (green: admissible)")
            ax.tick_params(axis="y", labelsize=7)
            ax.set_title(self.verdict[:90], fontsize=8)
        elif kind == "boxes":
            ba = self.before_after.get("W")
            if not ba:
                return None
            chans = list(ba)
            if ax is None:
                fig, ax = plt.subplots(1, len(chans), figsize=(2.4 * len(chans), 3))
                fig.suptitle("minimal trace-conformant W, before/after", fontsize=9)
            ax = np.atleast_1d(ax)
            for a, ch in zip(ax, chans):
                b, af = ba[ch]["before"], ba[ch]["after"]
                a.bar([0, 1], [b[1] - b[0], af[1] - af[0]], bottom=[b[0], af[0]], color=["tab:gray", "tab:green"])
                a.set_xticks([0, 1], ["base", "effect"])
                a.set_title(f"{ch}: x{ba[ch]['shrink']:.2f}", fontsize=9)
        elif kind == "tubes":
            drawn = [tb for tb in self.tubes if "tube" in tb]
            if not drawn:
                return None
            from matplotlib.patches import Patch

            if ax is None:
                _, ax = plt.subplots(figsize=(8, 4))
            colors = {"base": "tab:gray", "with effect": "tab:green"}
            for tb in drawn:
                tb["tube"].plot(ax=ax, color=colors.get(tb["label"], "tab:blue"), alpha=0.35)
            plot_measured(ax, drawn[0]["measured"], drawn[0]["tube"].state_names[:2], ms=2)
            ax.legend(handles=[Patch(color=colors[t["label"]], alpha=0.5, label=f"{t['label']} (W minimal box)")
                               for t in drawn if t["label"] in colors] + ax.get_legend_handles_labels()[0],
                      fontsize=8)  # fmt: skip
            failed = [tb["label"] for tb in self.tubes if "tube" not in tb]  # a reach that failed is said, not left out
            note = f"; {' and '.join(failed)}: the reach failed (see the report)" if failed else ""
            ax.set_title(f"reach tubes of a held-out case, before and after modelling the effect{note}", fontsize=9)
        else:
            raise OptionsError(f"GapReport.plot: kind must be 'effects', 'boxes' or 'tubes', got {kind!r}")
        np.atleast_1d(ax)[0].figure.tight_layout()
        return ax

    def save_plots(self, out) -> list:
        """PNGs into folder ``out``: ``effects.png``, ``boxes.png``, ``tubes.png`` (those with data); returns the paths."""
        import matplotlib.pyplot as plt

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for kind in ("effects", "boxes", "tubes"):
            ax = self.plot(kind=kind)
            if ax is None:
                continue
            fig = np.atleast_1d(ax)[0].figure
            paths.append(str(save_figure(fig, out / f"{kind}.png", dpi=110, bbox_inches=None)))
            plt.close(fig)
        return paths


def _f(value, spec: str) -> str:
    """A number for the summary; "—" for a value a saved report holds as None (NaN or inf when computed)."""
    if value is None or not np.isfinite(value):
        return "—"
    return format(value, spec)


def _pct(share) -> str:
    """A share as a whole percentage ("—" when None or not finite)."""
    return "—" if share is None or not np.isfinite(share) else f"{100 * share:.0f} %"


def _separating_text(sep) -> str:
    if not sep:
        return ""
    if sep.get("expected_z") is not None:  # checked with the candidates refitted to each other
        if sep["probe"] is None:
            return f"; no probe maneuver separates them (expected z {_f(sep['expected_z'], '.2g')} per run)"
        return (f"; separating maneuver: {sep['probe']['text']} (expected z {_f(sep['expected_z'], '.1f')} per "
                f"run)")  # fmt: skip
    if sep["probe"] is None:
        return f"; no probe maneuver separates them (at most {_f(sep['separation'], '.2g')} noise std)"
    return f"; separating maneuver: {sep['probe']['text']} ({_f(sep['separation'], '.1f')} noise std)"


def timing_hold_note(decision) -> str:
    """A sentence for named timing effects (parameters in seconds: a lag, a dead time): their estimates assume how
    the inputs moved between samples (``DiagnoseOptions.input_hold``), which the data cannot tell (the other hold
    shifts the commands by about half a sample interval); empty when nothing timed is named or the hold is unknown."""
    from reachconf.diagnose.effects import EFFECTS

    hold, dt = decision.get("input_hold"), decision.get("sample_interval")
    timed = [f"{e['effect']}({e['target']})" for e in decision.get("named", [])
             if "s" in (getattr(EFFECTS.get(e["effect"]), "units", None) or ())]  # fmt: skip
    if not timed or hold is None or dt is None:
        return ""
    if hold == "zero":
        how, log, other, shift = ("each input was held until its next sample",
                                  "samples a faster controller or a continuous command", "linear", "longer.")
    else:
        how, log, other, shift = ("each input moved linearly to its next sample",
                                  "holds the commands of a controller that ran at its rate", "zero",
                                  "shorter (a dead time of about that size may be the hold alone).")
    return (f"Timing: the estimate of {', '.join(timed)} assumes that {how} (input_hold=\"{hold}\"). If the log "
            f"{log}, input_hold=\"{other}\" gives it about half a sample interval ({_f(dt / 2, '.3g')} s) {shift}")
