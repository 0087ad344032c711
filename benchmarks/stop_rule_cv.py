"""Is a learned stop worth its pushes? Scene-fold cross-validation of ``recipes/fit_stop.py``'s rule on the
never-stopping training episodes it cached (``<out_dir>/trajectories``), in a minute and without the simulator.

Per fold (scenes split by a hash of their id, as fit_stop's hold-out), a critic is fitted on the other folds
and its rule scored on this one: stop when the predicted gain of pushing on is >= a threshold (0 is the rule
``LearnedStop`` runs; inf never stops), and the same rule from an average of ``--members`` critics fitted on
bootstrap resamples (bagging). Prints the mean final χ of the targets and the mean pushes per level. The test
split is never read (docs/notebook/policy_attempts.md, "A look at the stop").

    python benchmarks/stop_rule_cv.py runs/student_s3/stop runs/student/stop_mem1
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import torch

from mqa_rl.data.dataset import LEVELS
from mqa_rl.training.optimal_stopping import fit_stop_critic, stopped_chi

THRESHOLDS = (0.0, 0.005, 0.01, 0.02, 0.04, float("inf"))


def load_trajectories(stop_dir: Path) -> dict:
    """fit_stop's cached episodes of every level, concatenated, with each episode's level index."""
    levels = [lv for lv in LEVELS if (stop_dir / "trajectories" / f"{lv}.pt").is_file()]
    if not levels:
        raise FileNotFoundError(f"no {stop_dir}/trajectories/<level>.pt: give a recipes/fit_stop.py out_dir")
    parts = [torch.load(stop_dir / "trajectories" / f"{lv}.pt", weights_only=False)["data"] for lv in levels]
    data = {k: torch.cat([p[k] for p in parts]) for k in ("features", "chi", "valid")}
    data["scenes"] = [s for p in parts for s in p["scenes"]]
    data["level"] = torch.cat([torch.full((p["chi"].shape[0],), i) for i, p in enumerate(parts)])
    data["levels"] = levels
    return data


def outcome(gain: torch.Tensor, chi: torch.Tensor, valid: torch.Tensor, threshold: float) -> tuple[torch.Tensor, torch.Tensor]:
    """[E] final χ and pushes of the rule "stop when the predicted gain >= threshold"."""
    stop = (gain >= threshold) & valid
    return stopped_chi(chi, stop, valid), (~stop & valid).long().cumprod(1).sum(1).float()


def cross_validate(data: dict, folds: int, members: int) -> dict:
    """{rule name: ([E] final χ, [E] pushes)} with every episode scored by critics that never saw its scene."""
    fold = torch.tensor([int(hashlib.sha256(s.encode()).hexdigest(), 16) % folds for s in data["scenes"]])
    f, chi, valid = data["features"], data["chi"], data["valid"]
    names = [f"threshold {t:g}" for t in THRESHOLDS] + [f"bagged x{members}"]
    out = {n: (torch.zeros(len(fold)), torch.zeros(len(fold))) for n in names}
    for k in range(folds):
        train, test = (fold != k).nonzero().squeeze(1), fold == k
        if len(train) == 0 or not test.any():
            continue
        critic = fit_stop_critic(f[train], chi[train], valid[train], seed=0)[0]
        bag = []
        for m in range(members):
            rows = train[torch.randint(0, len(train), (len(train),), generator=torch.Generator().manual_seed(100 + m))]
            bag.append(fit_stop_critic(f[rows], chi[rows], valid[rows], seed=m)[0])
        with torch.no_grad():
            gain = critic(f[test])
            bagged = torch.stack([c(f[test]) for c in bag]).mean(0)
        for name, (g, t) in zip(names, [(gain, t) for t in THRESHOLDS] + [(bagged, 0.0)]):
            end, pushes = outcome(g, chi[test], valid[test], t)
            out[name][0][test], out[name][1][test] = end, pushes
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stop_dirs", nargs="+", type=Path, help="recipes/fit_stop.py out_dirs")
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--members", type=int, default=5, help="critics in the bagged average")
    args = p.parse_args()
    torch.set_num_threads(1)
    for stop_dir in args.stop_dirs:
        data = load_trajectories(stop_dir)
        results = cross_validate(data, args.folds, args.members)
        print(f"{stop_dir}: mean final χ of the targets (pushes), {args.folds}-fold by scene")
        print(f"{'rule':>16} " + " ".join(f"{lv:>15}" for lv in data["levels"]) + f" {'all':>7}")
        for name, (end, pushes) in results.items():
            cells = [f"{end[data['level'] == i].mean():.3f} ({pushes[data['level'] == i].mean():4.1f})"
                     for i in range(len(data["levels"]))]
            print(f"{name:>16} " + " ".join(f"{c:>15}" for c in cells) + f" {end.mean():7.4f}")
        hindsight = data["chi"].min(1).values
        print(f"{'hindsight best':>16} " + " ".join(f"{hindsight[data['level'] == i].mean():15.3f}"
                                                    for i in range(len(data["levels"]))) + f" {hindsight.mean():7.4f}")


if __name__ == "__main__":
    main()
