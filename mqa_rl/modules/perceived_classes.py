"""PerceivedClasses: the counting perception's class map on the push grid, as the push policy's recognition.

Why: the students' recognition (a light trunk and a 1×1 class head learnt on the renders of the 70 training scenes,
``checkpoints/recognition``) gives object cells their class 0.76-0.78 of the time on piles it never saw, against
0.93-0.95 for the counting perception (issue 39's U-Net, learnt on 900 fresh piles), and the geometric push branch
decides from the question's target map alone (docs/policy.md, "The students' recognition on new piles").

A TensorDict module that writes ``keys.PERCEIVED_CLASSES`` (float32 [1 + classes, 28, 28]: the perception's class
probabilities averaged over each push-grid cell's pixels) from ``keys.RGB``, unless the tensordict carries them
already (a replay sample, a demonstration set filled once): placed before the Q-network's actor it reads each state
once, when the policy acts. Frozen: it is part of the policy's weights, never trained. A demonstration folder's
readings are kept beside it (``kept``): every phase of a chain trains on the same demonstrations, which never change
once collected (``collect_demonstrations.py`` refuses a folder that holds some).
"""

from __future__ import annotations

import io
from pathlib import Path

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.files import load_tensors, write_atomic
from mqa_rl.modules.perceived_count import file_sha256
from mqa_rl.modules.perception import CountingPerception, load_perception

CHUNK = 8              # frames per perception pass (a 448-px pass holds ~0.2 GB of activations a frame)


class PerceivedClasses(TensorDictModuleBase):
    """``td[RGB]`` uint8 [*B, 3, H, W] → ``td[PERCEIVED_CLASSES]`` float32 [*B, 1 + classes, 28, 28]."""

    def __init__(self, perception: CountingPerception, sha256: str | None = None):
        super().__init__()
        self.sha256 = sha256                # the perception's file, which names the readings ``kept`` writes
        self.in_keys, self.out_keys = [keys.RGB], [keys.PERCEIVED_CLASSES]
        self.perception = perception.eval()
        for p in self.perception.parameters():
            p.requires_grad_(False)

    @classmethod
    def from_file(cls, path: str | Path, num_classes: int) -> "PerceivedClasses":
        """The perception at ``path``; ValueError when it tells another number of classes than the dataset's."""
        model, _ = load_perception(path)
        if model.num_classes != 1 + num_classes:
            raise ValueError(f"{path} tells {model.num_classes - 1} object classes and the dataset has {num_classes}: "
                             f"model.perceived_classes needs a counting perception of this dataset's classes")
        return cls(model, file_sha256(path))

    def train(self, mode: bool = True) -> "PerceivedClasses":
        super().train(mode)
        self.perception.eval()          # frozen: batch statistics never move
        return self

    @torch.no_grad()
    def read(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 rgb [*B, 3, H, W] → float32 [*B, 1 + classes, 28, 28]."""
        flat = rgb.reshape(-1, *rgb.shape[-3:])
        out = [F.adaptive_avg_pool2d(self.perception.predict(flat[i:i + CHUNK].to(torch.uint8))[0].float(), actions.GRID)
               for i in range(0, flat.shape[0], CHUNK)]
        probs = torch.cat(out) if out else flat.new_zeros((0, self.perception.num_classes, actions.GRID, actions.GRID),
                                                          dtype=torch.float32)
        return probs.reshape(*rgb.shape[:-3], *probs.shape[1:])

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        if keys.PERCEIVED_CLASSES not in tensordict.keys():
            tensordict.set(keys.PERCEIVED_CLASSES, self.read(tensordict.get(keys.RGB)))
        return tensordict

    def fill(self, tensordict: TensorDictBase) -> TensorDictBase:
        """``forward`` on the roots and, where there are, the ``"next"`` states of stored transitions [N]. A successor that
        is the following transition's root (the same frame: a trajectory goes on) takes that root's reading: the
        collector's batches are trajectories, so most successors are read once, not twice."""
        self(tensordict)
        after = tensordict.get("next", None)
        if after is None or keys.RGB not in after.keys() or keys.PERCEIVED_CLASSES in after.keys():
            return tensordict
        if tensordict.batch_dims != 1:
            self(after)
            return tensordict
        rgb, next_rgb, read = tensordict.get(keys.RGB), after.get(keys.RGB), tensordict.get(keys.PERCEIVED_CLASSES)
        same = torch.zeros(len(tensordict), dtype=torch.bool)
        same[:-1] = (next_rgb[:-1] == rgb[1:]).flatten(1).all(1)
        out = torch.empty_like(read)
        out[:-1][same[:-1]] = read[1:][same[:-1]]
        if (~same).any():
            out[~same] = self.read(next_rgb[~same])
        after.set(keys.PERCEIVED_CLASSES, out)
        return tensordict

    def kept(self, tensordict: TensorDictBase, folder: str | Path) -> TensorDictBase:
        """``forward`` on a stored set [N] (a demonstration folder's), its readings kept in ``folder`` as
        ``perceived_classes-<the perception's SHA-256, 16 digits>.pt`` and read from there the next time; a kept
        file of another length or unreadable is read again and replaced; a folder that cannot be written only
        costs the reading."""
        if self.sha256 is None or keys.PERCEIVED_CLASSES in tensordict.keys():
            return self(tensordict)
        path = Path(folder) / f"perceived_classes-{self.sha256[:16]}.pt"
        shape = (len(tensordict), self.perception.num_classes, actions.GRID, actions.GRID)
        if path.exists():
            try:
                readings = load_tensors(path, what="file of perceived classes", hint="it is read again")
            except ValueError:
                readings = None
            if isinstance(readings, torch.Tensor) and tuple(readings.shape) == shape:
                return tensordict.set(keys.PERCEIVED_CLASSES, readings.float())
        self(tensordict)
        buffer = io.BytesIO()
        torch.save(tensordict.get(keys.PERCEIVED_CLASSES), buffer)
        try:
            write_atomic(path, buffer.getvalue())
        except OSError as error:
            print(f"  the perceived classes are not kept in {folder} ({error}): the next training reads them again")
        return tensordict
