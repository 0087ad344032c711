"""Answer statistics like the paper's Fig. 4: COUNTING answers overall and per level, yes/no balance."""

from __future__ import annotations

from collections import Counter

LEVELS = ("easy", "medium", "hard")
COUNT_ANSWERS = ("0", "1", "2", "3")


def answer_statistics(rows) -> dict:
    """``rows`` of (difficulty, type, answer) → fractions: counting[level][answer], yes[type][level]."""
    counts = Counter((lvl, t, a) for lvl, t, a in rows)
    totals = Counter((lvl, t) for lvl, t, _ in rows)

    def frac(levels, qtype, answer):
        n = sum(totals[(lv, qtype)] for lv in levels)
        return round(sum(counts[(lv, qtype, answer)] for lv in levels) / n, 6) if n else 0.0

    groups = {**{lv: (lv,) for lv in LEVELS}, "all": LEVELS}
    return {
        "counting": {g: {a: frac(lv, "counting", a) for a in COUNT_ANSWERS} for g, lv in groups.items()},
        "yes": {t: {g: frac(lv, t, "yes") for g, lv in groups.items()} for t in ("existence", "spatial", "logic")},
        "questions": {t: sum(v for (_, tt), v in totals.items() if tt == t) for t in ("counting", "existence", "spatial", "logic")},
    }


def format_statistics(stats: dict) -> str:
    rows = ["  COUNTING answers (fraction)      0      1      2      3"]
    for g in (*LEVELS, "all"):
        rows.append(f"    {g:<28}" + "".join(f" {stats['counting'][g][a]:6.3f}" for a in COUNT_ANSWERS))
    rows.append("  'yes' fraction                easy medium   hard    all")
    for t, by in stats["yes"].items():
        rows.append(f"    {t:<26}" + "".join(f" {by[g]:6.3f}" for g in (*LEVELS, "all")))
    return "\n".join(rows)


def plot_statistics(stats: dict, path) -> None:
    """Two panels as in the paper's Fig. 4 plus the yes/no balance; saved as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    x = np.arange(len(COUNT_ANSWERS))
    ax[0].bar(x, [stats["counting"]["all"][a] for a in COUNT_ANSWERS], color="tab:blue")
    ax[0].set(title="(a) COUNTING answers", xticks=x, xticklabels=COUNT_ANSWERS, xlabel="answer", ylabel="fraction")
    for k, lv in enumerate(LEVELS):
        ax[1].bar(x + (k - 1) * 0.27, [stats["counting"][lv][a] for a in COUNT_ANSWERS], 0.27, label=lv)
    ax[1].set(title="(b) COUNTING answers per level", xticks=x, xticklabels=COUNT_ANSWERS, xlabel="answer")
    ax[1].legend()
    types = list(stats["yes"])
    yes = [stats["yes"][t]["all"] for t in types]
    ax[2].bar(types, yes, label="yes", color="tab:green")
    ax[2].bar(types, [1 - y for y in yes], bottom=yes, label="no", color="tab:red")
    ax[2].set(title="(c) yes / no balance", ylabel="fraction")
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
