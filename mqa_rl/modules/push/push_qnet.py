"""PushQNet: the paper's manipulation Q-network (Sec. IV-B, Fig. 3), one Q value per action.

    rgb   → trunk → 28×28×C ┐
    depth → trunk → 28×28×C ┴ concat → 1×1 convs → 28×28×32 ┐
    question → embedding → 2-layer LSTM → linear → 32, tiled ┴ concat 28×28×64 → head → 28×28×9

The head's channels 0…7 are the pushes in direction d (``mqa_rl.envs.actions``), channel 8 is a
stop map whose spatial mean is Q(stop). The output is flat ``[*B, 6273]`` in the env's layout
``a = d·784 + row·28 + col`` (6272 = stop): channel d, grid row and column of the map are the
direction, image row and column of the push.

Alignment: a stride-8 conv trunk's output cell (r, c) is centred on input pixel (8r, 8c) + the trunk's
``centre_offset`` (0 for the ResNets: half a cell up-left of the cell centre where the env starts the
push; 7 for EfficientNet-Lite0's TensorFlow padding: half a cell down-right). The input is shifted by
the difference (``_align``) so that feature cell (r, c) is centred on grid cell (r, c) (a test checks
this with input gradients).

Depth enters as height above the bin floor, ``(camera_distance − depth) / depth_scale`` (metres /
0.1 m by default; 0 on the floor, ~1.4 for a 50-object pile), so it does not depend on the
camera height. The ImageNet trunks (the ResNets, EfficientNet-Lite0) get it as 3 identical channels
through a second trunk of the same kind and weights (as the authors did) and rgb with the ImageNet
mean/std, to suit pretrained weights.

Options beyond the paper (``paper`` profile: all off): ``head_context`` 3×3 convs (at the width of
the first head layer, after a 1×1 reduction) before the final 1×1 layers (a push acts 7 cells away;
1×1 heads only see their own cell), ``coords`` two channels of grid coordinates (where the walls
are), ``light_downsample`` (the light trunk on a 2×2-averaged image).

``class_map`` (recognition made explicit; pretrain it with ``recipes/pretrain.py part=push_trunk``): a 1×1
``class_head`` on the rgb trunk gives per-cell class probabilities p [B, 1 + classes, 28, 28] (channel 0:
no object), the question gives an attention w over the classes (softmax of a linear map of its
feature), and the map of the question's targets, t = Σ_c w_c p_c, joins the state as one more channel.
Recognition is then learnt once from the segmentation of a few thousand renders (the paper relied on
ImageNet features for it) and the DQN learns only where to push given t and depth; ``target_logits`` is
logit(t), so the auxiliary target-map loss (``mqa_rl.losses.target_map``) trains the question's attention.

``rotated_head`` (VPG's rotation sharing, ``mqa_rl.modules.push.rotated_head``): one push head scores "push
right" on the state rotated for each of the 8 directions, so every demonstration and reward teaches all
directions; same output layout.

``geometric_push`` (with ``class_map`` and ``rotated_head``): the push branch reads only what the image
teacher's rule reads — the question's target map t, the cells' object presence (1 − p(no object)) and
the height map pooled per cell (mean, max, min) — while the stop branch keeps the whole state. The
teacher pushes an object that stands higher than a visible target's part next to it, away from the
target: a local function of t and height. A push branch that also sees the rgb features memorised the
70 training scenes (docs/notebook/policy.md, the student trained three times longer: 47 % of pushes near the teacher's there, 5 % on new
scenes); one that sees no appearance has nothing scene-specific to memorise.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from mqa_rl.envs import actions
from mqa_rl.modules.push.rotated_head import RotatedPushHead
from mqa_rl.modules.push.trunks import conv_stack, make_trunk

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
GEOMETRY_CHANNELS = 5      # target map, object presence, height mean / max / min per cell


class QuestionEncoder(nn.Module):
    """Tokens [B, L] (0 = padding) → [B, out]: embedding, LSTM, last non-padding state, linear."""

    def __init__(self, vocab_size: int, embed: int = 64, hidden: int = 64, layers: int = 2, out: int = 32):
        super().__init__()
        self.embedding = nn.Embedding(vocab_size, embed, padding_idx=0)
        self.lstm = nn.LSTM(embed, hidden, num_layers=layers, batch_first=True)
        self.proj = nn.Linear(hidden, out)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        states, _ = self.lstm(self.embedding(tokens))
        last = (tokens != 0).sum(-1).clamp(min=1) - 1
        return self.proj(states[torch.arange(tokens.shape[0], device=tokens.device), last])


class PushQNet(nn.Module):
    """(rgb uint8 [*B,3,H,W], depth [*B,1,H,W] metres, question int64 [*B,L]) → Q [*B, 6273]."""

    def __init__(
        self,
        vocab_size: int,
        *,
        camera_distance: float,
        trunk: str = "light",
        weights: str | None = None,
        light_channels=(16, 32, 64, 64),
        light_downsample: int = 1,
        fuse_channels=(512, 128, 32),
        question_dim: int = 32,
        head_channels=(32, 16),
        head_context: int = 0,
        coords: bool = False,
        depth_scale: float = 0.1,
        freeze_trunk: bool = False,
        class_map: bool = False,
        num_classes: int = 20,
        rotated_head: bool = False,
        geometric_push: bool = False,
    ):
        super().__init__()
        if geometric_push and not (class_map and rotated_head):
            raise ValueError("geometric_push needs class_map=true (its target map) and rotated_head=true (its push branch)")
        self.geometric_push = bool(geometric_push)
        self.trunk_name = trunk
        self.imagenet_input = trunk != "light"
        self.depth_channels = 3 if self.imagenet_input else 1    # the ImageNet trunks see depth as 3 copies
        self.rgb_trunk = make_trunk(trunk, weights, light_channels, light_downsample)
        self.depth_trunk = make_trunk(trunk, weights, light_channels, light_downsample, in_channels=self.depth_channels)
        if freeze_trunk:
            for p in (*self.rgb_trunk.parameters(), *self.depth_trunk.parameters()):
                p.requires_grad_(False)
        self.camera_distance = float(camera_distance)
        self.depth_scale = float(depth_scale)
        feat = self.rgb_trunk.out_channels + self.depth_trunk.out_channels
        self.fuse = conv_stack([feat, *fuse_channels])
        self.question = QuestionEncoder(vocab_size, out=question_dim)
        self.coords = coords
        state = fuse_channels[-1] + question_dim + (2 if coords else 0) + (1 if class_map else 0)
        self.num_classes = int(num_classes)
        self.class_head = nn.Conv2d(self.rgb_trunk.out_channels, 1 + self.num_classes, 1) if class_map else None
        self.question_classes = nn.Linear(question_dim, 1 + self.num_classes) if class_map else None
        if rotated_head:      # one push head for all directions (rotated state), its own stop branch
            self.head = RotatedPushHead(state, tuple(head_channels), head_context, actions.DIRECTIONS,
                                        push_channels=GEOMETRY_CHANNELS if geometric_push else None)
        elif head_context:    # 1×1 down to head_channels[0], then 3×3 convs at that width
            width = head_channels[0]
            context = [nn.Conv2d(state, width, 1), nn.ReLU(inplace=True)]
            for _ in range(head_context):
                context += [nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True)]
            self.head = nn.Sequential(*context, conv_stack([*head_channels, actions.DIRECTIONS + 1], last_relu=False))
        else:                 # the paper: 1×1 convs only
            self.head = nn.Sequential(conv_stack([state, *head_channels, actions.DIRECTIONS + 1], last_relu=False))
        self.register_buffer("rgb_mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1) if self.imagenet_input
                             else torch.full((1, 3, 1, 1), 0.5))
        self.register_buffer("rgb_std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1) if self.imagenet_input
                             else torch.full((1, 3, 1, 1), 0.25))

    # ------------------------------------------------------------------------------------ inputs
    def normalise(self, rgb: torch.Tensor, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 rgb → standardised float; depth (m, any float dtype) → height above floor / depth_scale."""
        return self._standardise(rgb), self._height(depth)

    def _standardise(self, rgb: torch.Tensor) -> torch.Tensor:
        return (rgb.to(torch.float32) / 255.0 - self.rgb_mean) / self.rgb_std

    def _height(self, depth: torch.Tensor) -> torch.Tensor:
        d = depth.to(torch.float32)
        h = torch.where(d > 0, (self.camera_distance - d) / self.depth_scale, torch.zeros_like(d))
        return h.expand(-1, self.depth_channels, -1, -1)

    def _align(self, x: torch.Tensor) -> torch.Tensor:
        """Shift the image so that feature cell (r, c) centres on grid cell (r, c): up-left for a trunk
        centred before the cell centre, down-right for one centred after it.

        A stride-8 trunk centres output r on input pixel 8r + offset; the cell centre is pixel
        8r + 3.5 (pixel-index coordinates): shift by round(3.5 − offset) (0.5 px off at worst)."""
        cell = x.shape[-1] / actions.GRID
        shift = int(round(cell / 2 - 0.5 - self.rgb_trunk.centre_offset))
        if shift > 0:
            return F.pad(x[..., shift:, shift:], (0, shift, 0, shift), mode="replicate")
        if shift < 0:
            return F.pad(x[..., :shift, :shift], (-shift, 0, -shift, 0), mode="replicate")
        return x

    def _grid(self, feat: torch.Tensor) -> torch.Tensor:
        if feat.shape[-2:] != (actions.GRID, actions.GRID):
            feat = F.adaptive_avg_pool2d(feat, actions.GRID)
        return feat

    # ------------------------------------------------------------------------------------ forward
    def _rgb_features(self, rgb: torch.Tensor) -> torch.Tensor:
        return self._grid(self.rgb_trunk(self._align(self._standardise(rgb))))

    def class_logits(self, rgb: torch.Tensor) -> torch.Tensor:
        """[B, 1 + classes, 28, 28] per-cell class logits from rgb alone (``class_map``)."""
        if self.class_head is None:
            raise RuntimeError("this PushQNet has no class head: build it with class_map=True")
        return self.class_head(self._rgb_features(rgb))

    def _targets(self, probs: torch.Tensor, qf: torch.Tensor) -> torch.Tensor:
        """t = Σ_c softmax(question)_c · p_c over the class head's probabilities p, [B, 1, 28, 28]."""
        weights = torch.softmax(self.question_classes(qf), -1)[:, :, None, None]
        return (weights * probs).sum(1, keepdim=True)

    def _features(self, rgb, depth, question):
        """(rgb features, depth features, question feature, class probabilities p, target map t): p and t None
        without the class head; p computed once for both the target map and the geometric branch."""
        fr = self._rgb_features(rgb)
        fd = self._grid(self.depth_trunk(self._align(self._height(depth))))
        qf = self.question(question)
        probs = torch.softmax(self.class_head(fr), 1) if self.class_head is not None else None
        return fr, fd, qf, probs, (self._targets(probs, qf) if probs is not None else None)

    def state(self, rgb: torch.Tensor, depth: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        """[B, C, 28, 28]: visual features, the tiled question feature (coordinates, the targets' map)."""
        fr, fd, qf, _, targets = self._features(rgb, depth, question)
        return self._state(fr, fd, qf, targets)

    def _state(self, fr, fd, qf, targets) -> torch.Tensor:
        visual = self.fuse(torch.cat([fr, fd], 1))
        q = qf[:, :, None, None].expand(-1, -1, actions.GRID, actions.GRID)
        parts = [visual, q]
        if self.coords:
            lin = torch.linspace(-1, 1, actions.GRID, device=visual.device)
            yy, xx = torch.meshgrid(lin, lin, indexing="ij")
            parts.append(torch.stack([xx, yy]).expand(visual.shape[0], -1, -1, -1))
        if targets is not None:
            parts.append(targets)
        return torch.cat(parts, 1)

    def geometry(self, probs: torch.Tensor, depth: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """[B, 5, 28, 28] the geometric push branch's input: t, object presence, height mean / max / min.

        The height is pooled over each cell's pixels as they are (a cell's pixels 8r…8r+7 are centred on
        the push start; no ``_align`` shift, which is for the conv trunk's receptive fields)."""
        h = self._height(depth)[:, :1]
        pooled = [F.adaptive_avg_pool2d(h, actions.GRID), F.adaptive_max_pool2d(h, actions.GRID),
                  -F.adaptive_max_pool2d(-h, actions.GRID)]
        return torch.cat([targets, 1.0 - probs[:, :1], *pooled], 1)

    def geometry_maps(self, rgb: torch.Tensor, depth: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        """``geometry`` from the observation: [B, 5, 28, 28] (``class_map``; the learned stop reads it)."""
        if self.class_head is None:
            raise RuntimeError("this PushQNet has no class head: build it with class_map=True")
        probs = torch.softmax(self.class_logits(rgb), 1)
        return self.geometry(probs, depth, self._targets(probs, self.question(question)))

    def q_map(self, rgb: torch.Tensor, depth: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        """[B, 9, 28, 28]: 8 push direction maps and the stop map (batch dims flattened)."""
        fr, fd, qf, probs, targets = self._features(rgb, depth, question)
        state = self._state(fr, fd, qf, targets)
        if not self.geometric_push:
            return self.head(state)
        return self.head(state, self.geometry(probs, depth, targets))

    def target_logits(self, rgb: torch.Tensor, depth: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        """[B, 28, 28] logits of "a target of this question is visible in the cell": logit(t) of the class map
        (rgb and question only: the depth trunk plays no part)."""
        if self.class_head is None:
            raise RuntimeError("this PushQNet has no target map: build it with class_map=True")
        targets = self._targets(torch.softmax(self.class_logits(rgb), 1), self.question(question))
        return torch.logit(targets.clamp(1e-4, 1 - 1e-4)).squeeze(1)

    def forward(self, rgb: torch.Tensor, depth: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        batch = rgb.shape[:-3]
        maps = self.q_map(rgb.reshape(-1, *rgb.shape[-3:]), depth.reshape(-1, *depth.shape[-3:]),
                          question.reshape(-1, question.shape[-1]))
        push = maps[:, : actions.DIRECTIONS].flatten(1)          # d·784 + row·28 + col
        stop = maps[:, actions.DIRECTIONS].mean((-2, -1)).unsqueeze(-1)
        return torch.cat([push, stop], -1).reshape(*batch, actions.NUM_ACTIONS)
