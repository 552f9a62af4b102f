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
        Best first: ``effect``, ``target``, ``params`` (name -> value),
        ``params_std``, ``shrink_volume``, ``shrink_per_channel`` (channel ->
        factor), ``prediction_cost`` (held-out), ``prediction_gain``,
        ``box`` (channel -> [lo, hi]) when box-scored.
    verdict : str
    base : dict
        The refitted base model: ``params``, ``prediction_cost``, ``box``, ``V_box``.
    combination : dict or None
        The best effect together with a second one, if that shrinks the box further.
    features : list of dict
        Model-free check: dictionary features that explain the disturbance traces.
    before_after : dict
        Minimal trace-conformant W (and V) of the base and the best model, per channel, with shrink factors.
    split : dict
        Training and held-out case names (disjoint).
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
    tubes: list = field(default_factory=list, repr=False)  # before/after reach tubes (not serialised)

    @property
    def best(self) -> dict | None:
        """The best-ranked effect (``ranked_effects[0]``), or None."""
        return self.ranked_effects[0] if self.ranked_effects else None

    def to_dict(self) -> dict:
        """The report as plain JSON values (NaN and inf as None); the reach tubes are left out."""
        return _plain({"where": self.where, "ranked_effects": self.ranked_effects, "verdict": self.verdict,
                       "base": self.base, "combination": self.combination, "features": self.features,
                       "before_after": self.before_after, "split": self.split, "seconds": self.seconds})  # fmt: skip

    def summary(self, top: int = 5) -> str:
        """Markdown summary."""
        lines = ["# Sim-to-real gap diagnosis", "", f"**Verdict:** {self.verdict}", ""]
        lines += ["## Which effect", "", "| rank | effect | target | parameters (± std) | W volume shrink | "
                  "per channel | held-out prediction cost |", "|---|---|---|---|---|---|---|"]  # fmt: skip
        for i, e in enumerate(self.ranked_effects[:top]):
            ps = ", ".join(f"{k} = {v:.4g} ± {e.get('params_std', {}).get(k, float('nan')):.2g}"
                           for k, v in e["params"].items())  # fmt: skip
            sv = e.get("shrink_volume")
            pc = ", ".join(f"{k} {v:.2f}" for k, v in (e.get("shrink_per_channel") or {}).items())
            lines.append(f"| {i + 1} | {e['effect']} | {e['target']} | {ps} | "
                         f"{'' if sv is None else f'{sv:.2f}'} | {pc} | {e['prediction_cost']:.3g} |")  # fmt: skip
        lines.append(f"| - | base (refitted) | | | 1 | | {self.base.get('prediction_cost', float('nan')):.3g} |")
        if self.combination:
            c = self.combination
            lines += ["", f"Combined: {c['label']}, W volume shrink {c['shrink_volume']:.2f}, parameters "
                      + ", ".join(f"{k} = {v:.4g}" for k, v in c["params"].items())]  # fmt: skip
        if self.before_after:
            lines += ["", "## How far it shrinks (minimal trace-conformant boxes, held-out cases)", "",
                      "| set | channel | base | with effect | shrink |", "|---|---|---|---|---|"]  # fmt: skip
            for setname in ("W", "V", "W_reachset"):
                for ch, row in self.before_after.get(setname, {}).items():
                    lines.append(f"| {setname} | {ch} | [{row['before'][0]:.4g}, {row['before'][1]:.4g}] | "
                                 f"[{row['after'][0]:.4g}, {row['after'][1]:.4g}] | {row['shrink']:.2f} |")  # fmt: skip
        loc = self.where.get("location", {})
        if loc:
            lines += ["", "## Where", ""]
            for ch, sh in sorted(loc.get("shares", {}).items(), key=lambda kv: -kv[1]):
                drv = ", ".join(f"{o} (rho {v:.2f})" for o, v in list(loc.get("drivers", {}).get(ch, {}).items())[:2]
                                if v > 0.3)  # fmt: skip
                lines.append(f"- {ch}: {100 * sh:.0f} % of the normalised disturbance box"
                             + (f", driven by the errors of {drv}" if drv else ""))  # fmt: skip
            for g, segs in loc.get("group_segments", {}).items():
                for s in segs[:3]:
                    lines.append(f"- {s['channel']}, {s['t0']:.1f}-{s['t1']:.1f} s of {s['share']:.0%} of the {g} runs")
            for ch, corr in loc.get("conditions", {}).items():
                best = list(corr.items())[:3]
                if best:
                    lines.append(f"- |{ch}| grows with " + ", ".join(f"{k} (rho {v:+.2f})" for k, v in best))
        avp = self.where.get("actuator_vs_process")
        if avp:
            lines += ["", f"Actuator vs process: {avp['verdict']}"]
        if self.features:
            lines += ["", "## Model-free check (sparse regression of the disturbance traces)", ""]
            for f in self.features[:top]:
                lines.append(f"- {f['channel']}: {f['feature']} explains {100 * f['share']:.0f} % of the variance")
        lines += ["", f"Training cases: {len(self.split.get('train', []))}, held-out: "
                  f"{len(self.split.get('test', []))}; {self.seconds:.1f} s."]  # fmt: skip
        return "\n".join(lines) + "\n"

    @classmethod
    def from_dict(cls, d: dict) -> "GapReport":
        """The report from :meth:`to_dict` (without the reach tubes, which are not saved)."""
        return cls(d["where"], list(d["ranked_effects"]), d["verdict"], dict(d.get("base", {})), d.get("combination"),
                   list(d.get("features", [])), dict(d.get("before_after", {})), dict(d.get("split", {})),
                   float(d.get("seconds", 0.0)))  # fmt: skip

    def plot(self, ax=None, kind: str = "effects"):
        """One picture of the report; returns its axes (``None`` when the report has no data for it).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            For ``kind="boxes"`` one per disturbance channel.  (A folder
            instead writes every picture, as :meth:`save_plots`.)
        kind : {"effects", "boxes", "tubes"}
            Effect ranking by the shrink of the minimal W volume; the
            per-channel minimal W before/after; the reach tubes of a held-out
            case before/after with its measurements.
        """
        import matplotlib.pyplot as plt

        if isinstance(ax, (str, Path)):  # the old plot(out): write the PNGs
            return self.save_plots(ax)
        if kind == "effects":
            scored = [e for e in self.ranked_effects if e.get("shrink_volume") is not None]
            if not scored:
                return None
            if ax is None:
                _, ax = plt.subplots(figsize=(7, 0.4 * len(scored) + 1.5))
            labels = [f"{e['effect']}({e['target']})" for e in scored][::-1]
            ax.barh(labels, [e["shrink_volume"] for e in scored][::-1], color="tab:blue")
            ax.axvline(1.0, color="k", lw=0.8)
            ax.set_xscale("log")
            ax.set_xlabel("shrink of the minimal trace-conformant W volume (held-out cases)")
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
            ax.set_title("reach tubes of a held-out case, before and after modelling the effect", fontsize=9)
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
