"""Does a learned stop that remembers the episode's start stop better? (issue 40's "history" item)

The shipped stop critic reads the current state's features only. This probe refits it, 5-fold by scene on the
episodes `recipes/fit_stop.py` cached, with the target features' change since I_start and their gap below the best
seen so far appended, and prints the share the stopped frame leaves uncountable per level, with history − base
paired by episode and bootstrapped by scene.

    python recipes/fit_stop.py run=checkpoints/dqn_countable value=uncountable episodes_per_level=400 out_dir=runs/stop/countable400
    python benchmarks/stop_history_cv.py runs/stop/countable400
"""
import hashlib
import sys
from pathlib import Path

import torch

from mqa_rl.files import load_tensors
from mqa_rl.modules.learned_stop import FEATURES
from mqa_rl.training.optimal_stopping import fit_stop_critic, fixed_rules, stopped_chi

LEVELS = ("easy", "medium", "hard")
TARGET_FEATURES = [FEATURES.index(n) for n in ("target_mean", "target_max", "target_cells")]


def with_history(features):
    """The feature sets compared: base, + change since the start, + that and the gap below the best so far."""
    target = features[:, :, TARGET_FEATURES]
    since_start = target - target[:, :1]
    below_best = torch.cummax(target, dim=1).values - target
    return {"base": features, "+since_start": torch.cat([features, since_start], -1),
            "+since_start+below_best": torch.cat([features, since_start, below_best], -1)}


def scene_bootstrap(diff, scene_ids, draws=2000, seed=0):
    generator = torch.Generator().manual_seed(seed)
    ids = scene_ids.unique()
    means = []
    for _ in range(draws):
        weight = torch.bincount(ids[torch.randint(len(ids), (len(ids),), generator=generator)], minlength=int(scene_ids.max()) + 1)[scene_ids].float()
        means.append(float((weight * diff).sum() / weight.sum()))
    return torch.tensor(means).quantile(torch.tensor([0.025, 0.975])).tolist()


def main(root, value="uncountable", folds=5):
    levels = {lv: load_tensors(Path(root) / "trajectories" / f"{lv}.pt", what="cached stop trajectories",
                               hint="run recipes/fit_stop.py first")["data"] for lv in LEVELS}
    data = {k: torch.cat([levels[lv][k] for lv in LEVELS]) for k in ("features", value, "valid")}
    scenes = [s for lv in LEVELS for s in levels[lv]["scenes"]]
    level_of = torch.cat([torch.full((levels[lv][value].shape[0],), i) for i, lv in enumerate(LEVELS)])
    fold = torch.tensor([int(hashlib.sha256(s.encode()).hexdigest(), 16) % folds for s in scenes])
    scene_ids = torch.tensor([sorted(set(scenes)).index(s) for s in scenes])
    print(f"{len(scenes)} episodes, {len(set(scenes))} scenes, {folds} folds by scene, value={value}")
    stopped = {}
    for name, features in with_history(data["features"]).items():
        out = torch.zeros(len(scenes))
        for k in range(folds):
            train, test = fold != k, fold == k
            critic, _ = fit_stop_critic(features[train], data[value][train], data["valid"][train], seed=0)
            with torch.no_grad():
                stop = (critic(features[test]) >= 0) & data["valid"][test]
            out[test] = stopped_chi(data[value][test], stop, data["valid"][test])
        stopped[name] = out
        print(name, {lv: round(float(out[level_of == i].mean()), 3) for i, lv in enumerate(LEVELS)}, flush=True)
    for i, lv in enumerate(LEVELS):
        rules = fixed_rules(data[value][level_of == i], data["valid"][level_of == i])
        print(f"{lv}: stop at once {rules['after_0']:.3f}, hindsight {rules['hindsight']:.3f}")
    for name in list(stopped)[1:]:
        diff = stopped[name] - stopped["base"]
        for i, lv in enumerate(LEVELS):
            m = level_of == i
            low, high = scene_bootstrap(diff[m], scene_ids[m])
            print(f"{name} − base, {lv}: {float(diff[m].mean()):+.3f} [{low:+.3f}, {high:+.3f}]")


if __name__ == "__main__":
    main(*sys.argv[1:])
