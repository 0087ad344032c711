"""Tables and figures of the answering evaluation (``recipes/evaluate.py``): Table III (COUNTING
accuracy per level beside the paper's), the per-type table, the policies' pushes and χ, as markdown,
CSV and a bar chart. Every file is written atomically.

``results["systems"][name]`` is either ``{"status": "missing", "reason": ..., "command": ...}`` or
``{"status": "ok", "accuracy": {type: {level: {accuracy, low, high, n}}}, "vs_random": {level: [mean,
half, n]}, "vs_prior": the same against the answer prior, "counter_first" / "counter_last" / "counter_either" / "counter_calibrated" / "counter_calibrated_either" (the last two absent when the training rollouts are gone): like accuracy, "policy": {level: {metric: [mean, half, n]}}}``;
``results["references"]`` maps a reference's name (the answer prior) to an accuracy table.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

from mqa_rl.data.dataset import LEVELS
from mqa_rl.evaluation.paper import PAPER_NAMES, TABLE_III
from mqa_rl.files import write_atomic

# the perfect counters of a system's results, in the order policy.md and table3.csv show them
COUNTERS = ("counter_first", "counter_last", "counter_either", "counter_calibrated", "counter_calibrated_either")
CSV_HEADER = ["system", "status", "type", "level", "accuracy", "low", "high", "n", "paper", "vs_random", "vs_random_ci95",
              "vs_prior", "vs_prior_ci95", "pushes", "chi_end", "chi_change", *COUNTERS]


def save_figure(fig, path: Path, dpi: int = 120) -> Path:
    """A matplotlib figure to ``path`` (format from its suffix), written atomically, then closed."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format=path.suffix.lstrip(".") or "png", dpi=dpi)
    plt.close(fig)
    return write_atomic(path, buffer.getvalue())


def _acc(cell: dict | None) -> str:
    if not cell or cell["n"] == 0:
        return "—"
    half = (cell["high"] - cell["low"]) / 2
    return f"{cell['accuracy']:.3f} ± {half:.3f} (n={cell['n']})"


def _mean(triple) -> str:
    mean, half, n = triple
    if n == 0 or not math.isfinite(mean):
        return "—"
    return f"{mean:+.3f} ± {half:.3f}" if math.isfinite(half) else f"{mean:+.3f}"


def _label(name: str) -> str:
    return f"{name} ({PAPER_NAMES[name]})" if name in PAPER_NAMES and name != "random" else name


def table3_markdown(results: dict, qtype: str = "counting") -> str:
    head = ("| system | " + " | ".join(LEVELS) + " | paper: " + " / ".join(LEVELS)
            + " | − random (paired by question): " + " / ".join(LEVELS)
            + " | − answer prior (paired): " + " / ".join(LEVELS) + " |")
    lines = [head, "|---|" + "---|" * (len(LEVELS) + 3)]
    for name, res in results["systems"].items():
        paper = " / ".join(f"{TABLE_III[name][lv]:.3f}" for lv in LEVELS) if name in TABLE_III else "—"
        if res["status"] != "ok":
            lines.append(f"| {_label(name)} | " + " | ".join(["missing"] * len(LEVELS)) + f" | {paper} | {res['reason']} | |")
            continue
        cells = [_acc(res["accuracy"].get(qtype, {}).get(lv)) for lv in LEVELS]
        vs = " / ".join(_mean(res["vs_random"][lv]) for lv in LEVELS) if res.get("vs_random") else "—"
        prior = " / ".join(_mean(res["vs_prior"][lv]) for lv in LEVELS) if res.get("vs_prior") else "—"
        lines.append(f"| {_label(name)} | " + " | ".join(cells) + f" | {paper} | {vs} | {prior} |")
    for name, table in results.get("references", {}).items():
        cells = [_acc(table.get(qtype, {}).get(lv)) for lv in LEVELS]
        lines.append(f"| *{name}* | " + " | ".join(cells) + " | — | — | — |")
    return "\n".join(lines)


BASELINES = ("no_manipulation", "random")     # what every other system is paired against, by question
STORED_KEYS = {"no_manipulation": "vs_no_manipulation", "random": "vs_random"}


def _interval(diff) -> str:
    """``+0.044 [+0.006, +0.089]``, bold when the interval excludes zero; empty without a measurement."""
    if not diff or len(diff) < 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in diff[:3]):
        return ""
    text = f"{diff[0]:+.3f} [{diff[1]:+.3f}, {diff[2]:+.3f}]"
    return f"**{text}**" if diff[1] > 0 or diff[2] < 0 else text


def paired_markdown(results: dict, stored: dict | None = None) -> str:
    """Every evaluated system − each baseline, COUNTING, per level, paired by question with 95 % intervals that
    resample whole scenes; beside it the stored full-test-split difference where ``stored`` has it."""
    head = "| system − baseline | " + " | ".join(LEVELS) + (" | stored, full test split: " + " / ".join(LEVELS)
                                                          if stored else "") + " |"
    lines = [head, "|---|" + "---|" * (len(LEVELS) + bool(stored))]
    for name, res in results["systems"].items():
        if res["status"] != "ok" or name in BASELINES:
            continue
        for base in BASELINES:
            measured = res.get(f"vs_{base}_by_scene")
            if not measured:
                continue
            row = f"| {_label(name)} − {base.replace('_', ' ')} | " + " | ".join(_interval(measured.get(lv)) for lv in LEVELS)
            if stored:
                kept = ((stored.get("systems") or {}).get(name) or {}).get(STORED_KEYS[base]) or {}
                row += " | " + (" / ".join(_interval(kept.get(lv)) or "—" for lv in LEVELS) if kept else "—")
            lines.append(row + " |")
    return "\n".join(lines)


def sample_line(results: dict) -> str:
    """What this many questions can separate: the mean half-width of the paired intervals by scene, per level."""
    widths: dict[str, list[float]] = {lv: [] for lv in LEVELS}
    counts: dict[str, tuple[int, int]] = {}
    for name, res in results["systems"].items():
        if res["status"] != "ok":
            continue
        for lv in LEVELS:
            cell = res["accuracy"].get("counting", {}).get(lv)
            scenes = res.get("accuracy_by_scene", {}).get(lv)
            if cell and scenes:
                counts[lv] = (cell["n"], scenes[3])
            for base in BASELINES:
                diff = res.get(f"vs_{base}_by_scene", {}).get(lv)
                if diff and diff[3] and math.isfinite(diff[1]) and math.isfinite(diff[2]):
                    widths[lv].append((diff[2] - diff[1]) / 2)
    half = {lv: sum(w) / len(w) for lv, w in widths.items() if w}
    if not half:
        return "No paired difference was measured (evaluate no_manipulation or random beside the other systems)."
    sizes = ", ".join(f"{lv} {counts[lv][0]} questions on {counts[lv][1]} scenes" for lv in LEVELS if lv in counts)
    spans = " / ".join(f"±{half[lv]:.2f}" for lv in LEVELS if lv in half)
    return (f"This sample ({sizes}) separates a paired difference from zero only when it exceeds about {spans} "
            f"(easy / medium / hard, the mean half-width of its intervals); smaller differences need more questions.")


def best_line(results: dict, stored: dict | None = None) -> str:
    """Which system answers best: the highest COUNTING accuracy averaged over the levels, here and stored."""
    def ranked(table: dict[str, dict[str, float]]) -> list[tuple[float, str]]:
        return sorted(((sum(acc[lv] for lv in LEVELS) / len(LEVELS), n) for n, acc in table.items()
                       if all(lv in acc for lv in LEVELS)), reverse=True)

    here = ranked({n: {lv: r["accuracy"]["counting"][lv]["accuracy"] for lv in LEVELS
                       if lv in r["accuracy"].get("counting", {})}
                   for n, r in results["systems"].items() if r["status"] == "ok"})
    if not here:
        return "No system was evaluated."
    line = "Answers best on this sample (mean COUNTING accuracy over the levels): " + ", then ".join(
        f"{_label(n)} {m:.3f}" for m, n in here[:3]) + "."
    if stored:
        kept = ranked({n: s.get("accuracy", {}) for n, s in (stored.get("systems") or {}).items()})
        if kept:
            line += " Stored, full test split: " + ", then ".join(f"{_label(n)} {m:.3f}" for m, n in kept[:3]) + "."
    return line


def per_type_markdown(results: dict) -> str:
    lines = ["| system | type | " + " | ".join(LEVELS) + " | all |", "|---|---|" + "---|" * (len(LEVELS) + 1)]
    rows = [(n, r["accuracy"]) for n, r in results["systems"].items() if r["status"] == "ok"]
    rows += [(f"*{n}*", t) for n, t in results.get("references", {}).items()]
    for name, table in rows:
        for qtype, cells in table.items():
            lines.append(f"| {name} | {qtype} | " + " | ".join(_acc(cells.get(lv)) for lv in (*LEVELS, "all")) + " |")
    return "\n".join(lines)


def policy_markdown(results: dict) -> str:
    cols = ("pushes", "stopped", "chi_end", "chi_change", "countable_gain")
    lines = ["| system | level | pushes | stopped | targets' χ at the end | χ end − start | targets made countable − "
             "buried | perfect counter (≥ 20 px) on I_start | on I_stop | on either | calibrated on I_stop | calibrated "
             "on either |", "|---|---|" + "---|" * 10]
    for name, res in results["systems"].items():
        if res["status"] != "ok":
            continue
        for lv in (*LEVELS, "all"):
            stats = res["policy"].get(lv)
            if stats is None:
                continue
            counters = [_acc(res.get(c, {}).get("counting", {}).get(lv)) for c in COUNTERS]
            lines.append(f"| {name} | {lv} | " + " | ".join(_mean(stats[c]) for c in cols) + " | " + " | ".join(counters) + " |")
    return "\n".join(lines)


def by_scene_markdown(results: dict) -> str:
    """COUNTING accuracy per system and level with intervals that resample whole scenes, and the paired
    differences to no manipulation (the gain manipulation brings to the answer), random and the answer prior, same
    intervals."""
    lines = ["COUNTING accuracy, 95 % intervals resampling whole scenes (cluster bootstrap); system − no manipulation, "
             "− random and − the answer prior paired by question, same intervals; and the difference to no manipulation "
             "for a perfect counter (≥ 20 px) on I_stop", "",
             "| system | level | accuracy [95 %] | scenes | − no manipulation [95 %] | − random [95 %] | − prior [95 %] "
             "| perfect counter on I_stop − no manipulation [95 %] |",
             "|---|---|---|---|---|---|---|---|"]

    def cell(diff) -> str:
        return f"{diff[0]:+.3f} [{diff[1]:+.3f}, {diff[2]:+.3f}]" if diff and diff[3] else ""

    for name, res in results["systems"].items():
        for lv, (mean, low, high, scenes) in res.get("accuracy_by_scene", {}).items():
            d, r, p, c = (cell(res.get(key, {}).get(lv)) for key in ("vs_no_manipulation_by_scene", "vs_random_by_scene",
                                                                       "vs_prior_by_scene", "counter_stop_vs_no_manipulation_by_scene"))
            lines.append(f"| {name} | {lv} | {mean:.3f} [{low:.3f}, {high:.3f}] | {scenes} | {d} | {r} | {p} | {c} |")
    return "\n".join(lines) + "\n"


def rows_csv(results: dict) -> str:
    """One row per system × type × level: accuracy and interval, paper's value, pushes, χ, counters."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(CSV_HEADER)
    pad = lambda row: row + [""] * (len(CSV_HEADER) - len(row))   # noqa: E731  (empty trailing columns)
    for name, res in results["systems"].items():
        if res["status"] != "ok":
            for lv in LEVELS:
                w.writerow(pad([name, "missing", "counting", lv, "", "", "", 0, TABLE_III.get(name, {}).get(lv, "")]))
            continue
        for qtype, cells in res["accuracy"].items():
            for lv, c in cells.items():
                vs = res["vs_random"].get(lv, ("", "", 0)) if res.get("vs_random") and qtype == "counting" else ("", "", 0)
                vp = res["vs_prior"].get(lv, ("", "", 0)) if res.get("vs_prior") and qtype == "counting" else ("", "", 0)
                pol = res["policy"].get(lv, {})
                counters = [res.get(k, {}).get(qtype, {}).get(lv, {}).get("accuracy", "") for k in COUNTERS]
                paper = TABLE_III.get(name, {}).get(lv, "") if qtype == "counting" else ""
                w.writerow([name, "ok", qtype, lv, c["accuracy"], c["low"], c["high"], c["n"], paper, vs[0], vs[1], vp[0], vp[1],
                            pol.get("pushes", ("",))[0], pol.get("chi_end", ("",))[0], pol.get("chi_change", ("",))[0], *counters])
    for name, table in results.get("references", {}).items():
        for qtype, cells in table.items():
            for lv, c in cells.items():
                w.writerow(pad([name, "reference", qtype, lv, c["accuracy"], c["low"], c["high"], c["n"]]))
    return buf.getvalue()


def table3_figure(results: dict, path: Path, qtype: str = "counting") -> Path:
    """Grouped bars (one group per level, one bar per evaluated system and the answer prior) with the
    95 % intervals; the paper's value of the same system as a black diamond on its bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bars = [(n, r["accuracy"].get(qtype, {})) for n, r in results["systems"].items() if r["status"] == "ok"]
    bars += [(n, t.get(qtype, {})) for n, t in results.get("references", {}).items()]
    missing = [n for n, r in results["systems"].items() if r["status"] != "ok"]
    fig, ax = plt.subplots(figsize=(8.5, 4.2))
    width = 0.8 / max(len(bars), 1)
    for i, (name, cells) in enumerate(bars):
        xs, ys, errs, paper_x, paper_y = [], [], [[], []], [], []
        for j, lv in enumerate(LEVELS):
            c = cells.get(lv)
            if not c or c["n"] == 0:
                continue
            x = j - 0.4 + width * (i + 0.5)
            xs.append(x)
            ys.append(c["accuracy"])
            errs[0].append(c["accuracy"] - c["low"])
            errs[1].append(c["high"] - c["accuracy"])
            if name in TABLE_III:
                paper_x.append(x)
                paper_y.append(TABLE_III[name][lv])
        ax.bar(xs, ys, width * 0.95, yerr=errs, capsize=2, label=_label(name), hatch="//" if name not in results["systems"] else None)
        if paper_x:
            ax.plot(paper_x, paper_y, "kD", ms=5, label="paper" if "paper" not in ax.get_legend_handles_labels()[1] else None)
    ax.set_xticks(range(len(LEVELS)), LEVELS)
    ax.set_ylabel(f"{qtype.upper()} accuracy (95 % CI)")
    ax.set_ylim(0, 1)
    title = "Table III as measured" + (f" (missing: {', '.join(missing)})" if missing else "")
    ax.set_title(title, fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return save_figure(fig, path)
