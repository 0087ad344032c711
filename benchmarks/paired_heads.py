"""Two VQA heads on the same episodes: which answers better, paired by question, intervals by scene.

Table III's paired differences hold systems apart (their rollouts differ); an ablation of the answering half
(frozen vs fine-tuned perception, one encoder against another, one seed against another) holds the episodes
fixed and changes the head. Each side is one ``vqa.pt`` (or folder) or several, whose answer probabilities
are averaged (``VQAEnsemble``, as evaluate.py does with a list of ``vqa_dir``s). COUNTING questions per level:
each side's accuracy and A − B with 95 % intervals that resample whole scenes.

    python benchmarks/paired_heads.py --rollouts runs/answering/rollouts/counting/no_manipulation/test \\
        --a runs/answering/vqa/counting-ft/no_manipulation --b checkpoints/vqa_counting/no_manipulation
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import json
from pathlib import Path

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.evaluation import answering as ans
from mqa_rl.modules.vqa import CHECKPOINT_NAME, load_vqa
from mqa_rl.modules.vqa_ensemble import VQAEnsemble
from mqa_rl.training.vqa_data import load_answering_records


def load_side(paths: list[str]):
    """One VQA, or the average of several (their answer probabilities)."""
    files = [Path(p) / CHECKPOINT_NAME if Path(p).is_dir() else Path(p) for p in paths]
    return load_vqa(files[0]) if len(files) == 1 else VQAEnsemble.load(files)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rollouts", required=True, help="a test (or held-out) rollout store of collect_rollouts.py")
    p.add_argument("--a", nargs="+", required=True, help="vqa.pt files or folders (several: their average)")
    p.add_argument("--b", nargs="+", required=True)
    p.add_argument("--json", default=None, help="also write the figures to this file")
    args = p.parse_args()
    records = load_answering_records(args.rollouts, images=False)
    counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
    records = records[counting]
    if records.shape[0] == 0:
        raise SystemExit(f"{args.rollouts} holds no COUNTING episodes: give a store collected with questions=counting")
    right = {}
    for side, paths in (("a", args.a), ("b", args.b)):
        model = load_side(paths)       # each side reads its frames (a finer perception: the answer camera's)
        frames = load_answering_records(args.rollouts, size=model.frame_size)[counting]
        right[side] = ans.predict(model, frames) == records.get(keys.ANSWER_LABEL)
    report = {"rollouts": args.rollouts, "a": args.a, "b": args.b, "levels": {}}
    print(f"{args.rollouts}: COUNTING, A = {' + '.join(args.a)}, B = {' + '.join(args.b)}")
    print(f"{'level':8} {'A':>22} {'B':>22} {'A - B':>26} scenes")
    fmt = lambda m, lo, hi: f"{m:.3f} [{lo:.3f}, {hi:.3f}]"   # noqa: E731
    for i, level in enumerate(LEVELS):
        m = records.get(keys.LEVEL) == i
        if not m.any():
            continue
        sub = records[m]
        a = ans.accuracy_by_scene(right["a"][m], sub)[level]
        b = ans.accuracy_by_scene(right["b"][m], sub)[level]
        d = ans.paired_difference_by_scene(right["a"][m], sub, right["b"][m], sub)
        report["levels"][level] = {"a": a[:3], "b": b[:3], "a_minus_b": d[:3], "scenes": d[3], "questions": int(m.sum())}
        print(f"{level:8} {fmt(*a[:3]):>22} {fmt(*b[:3]):>22} {fmt(*d[:3]):>26} {d[3]}")
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
