"""The push Q-network's pretrained recognition as a file: the rgb trunk and class head (what is
where) and the question encoder with its attention over the classes (what is asked about).

``recipes/pretrain.py part=push_trunk`` writes it; ``recipes/train_dqn.py`` loads it into a fresh
``PushQNet`` (``model.pretrained=<file>``) before DQN training: the visual part frozen by default
(``freeze``), the question part always trainable (the Q head reads its feature too). A trained DQN
checkpoint holds these weights itself: evaluating or demoing it never needs this file.
"""

from __future__ import annotations

from pathlib import Path

from mqa_rl.files import load_versioned, save_versioned

RECOGNITION_FORMAT = "mqa_rl.push_recognition"
RECOGNITION_VERSION = 1
VISUAL = ("rgb_trunk", "class_head")
QUESTION = ("question", "question_classes")
HINT = "make one with `python recipes/pretrain.py part=push_trunk` (or set model.pretrained=null)"


def _architecture(net) -> dict:
    trunk = net.rgb_trunk
    return {"trunk": net.trunk_name, "trunk_out": trunk.out_channels, "num_classes": net.num_classes,
            "trunk_shapes": {k: list(v.shape) for k, v in trunk.state_dict().items()},
            "question_shapes": {k: list(v.shape) for k, v in net.question.state_dict().items()}}


def save_recognition(net, path: str | Path, classes, meta: dict) -> Path:
    """Write ``net``'s recognition modules (``VISUAL`` + ``QUESTION``), the class names and ``meta`` atomically."""
    blob = {"classes": list(classes), "architecture": _architecture(net), "meta": dict(meta)}
    for name in (*VISUAL, *QUESTION):
        blob[name] = {k: v.detach().cpu() for k, v in getattr(net, name).state_dict().items()}
    return save_versioned(path, RECOGNITION_FORMAT, RECOGNITION_VERSION, blob)


def load_recognition(net, path: str | Path, classes, freeze: bool = True) -> dict:
    """Load the file into ``net`` (a ``PushQNet`` with ``class_map``); returns its ``meta``. Clear errors
    for a missing, unreadable or mismatched file (other trunk, other classes)."""
    path = Path(path).expanduser()
    if net.class_head is None:
        raise ValueError(f"model.pretrained={path} needs model.class_map=true (the class head it fills)")
    blob = load_versioned(path, RECOGNITION_FORMAT, RECOGNITION_VERSION, what="push-recognition file", hint=HINT)
    if list(blob["classes"]) != list(classes):
        raise ValueError(f"{path} was trained on classes {blob['classes'][:4]}… of another dataset, not this one's "
                         f"{list(classes)[:4]}…; {HINT} on this dataset")
    own, saved = _architecture(net), dict(blob["architecture"])
    if "question_shapes" not in saved:          # a file with the visual part only
        own.pop("question_shapes")
    if saved != own:
        raise ValueError(f"{path} holds a {blob['architecture']['trunk']} trunk or question encoder of another shape "
                         f"than model.* builds (trunk, light_channels, light_downsample, question_dim, the dataset's "
                         f"vocabulary must match the pretraining run's); {HINT}")
    for name in (*VISUAL, *QUESTION):
        if name in blob:
            getattr(net, name).load_state_dict(blob[name])
    if freeze:
        for name in VISUAL:
            for p in getattr(net, name).parameters():
                p.requires_grad_(False)
    return dict(blob.get("meta", {}))
