"""The answering model: EmbodiedQA's ``VqaLstmCnnAttentionModel`` over two frames, I_start and I_stop.

    I_start, I_stop → FrameEncoder (EQA's CNN, 32×10×10) → frame vector v_t (64)
    question tokens → embedding → 2-layer LSTM (64) → q (64)
    attention  a_t = softmax_t( linear_128→1( tanh([ques_tr(q), img_tr(v_t)]) ) )   over the 2 frames
    fused      q ⊙ Σ_t a_t v_t  → MLP 64 → 64 → answers (the dataset's answer vocabulary)

Frame fusion (``frame_fusion``): ``"attention"`` is EQA's weighted mean above; ``"max"`` (ours) takes
each feature's maximum over the two frames instead. Objects do not vanish between the frames, so what
either frame shows is evidence: a push that uncovers one target and buries another leaves I_stop's
visible count where I_start's was, while the targets seen in either frame rise (docs/results.md "Reading both
frames": a perfect counter on either frame gains 0.06-0.09 over I_stop for the learned student; the
max-fused VQA did not, at one seed). A weighted mean cannot take a maximum. ``"last"`` reads I_stop alone
(the ablation that asks what the first frame adds).

Frame vector (``pool``):

* ``"eqa"`` (the paper's): flatten the 32×10×10 map, linear 3200 → 64, ReLU, dropout.
* ``"classes"`` (ours, for counting): the encoder's ``class_head`` and ``density_head`` (supervised in
  pretraining with each cell's class areas and each visible object's centre) give class
  probabilities and per-class object densities on the third block's 24 × 24 map (the 10 × 10
  bottleneck is too coarse to count); the question picks classes (``heads`` softmaxes over them,
  e.g. A and B for LOGIC), which gives a map of how much of the asked class each cell holds and
  where its objects are; small convs on those maps, their means and maxima, and the maps' sums (the
  second: a count of the visible objects of the asked class) → 64. The question-to-class choice
  and how visible counts relate to answers is what must be learnt from answers, not what a can
  looks like. What the frozen encoder computes (``encode_frames``, cached in training) is then
  [2·21, 24, 24] instead of the bottleneck [32, 10, 10].

* ``"counts"`` (ours, ``vqa=counting``): the encoder is the counting perception
  (``mqa_rl.modules.answering.perception``, frozen by default), which reads per class how many objects show ≥ 20 px,
  its largest vote clusters and its area (``vote_counting.count_features``); the question picks the class
  (heads over the class channels, grounded) and an MLP reads what it picked plus how crowded the image
  is (docs/perception.md). ``freeze_encoder=False`` fine-tunes the perception through the same numbers
  (``vote_counting.trainable_count_features``: straight-through gradients to its density and classes).

Public contract (the web demo and ``recipes/evaluate.py`` use only this)::

    from mqa_rl.modules.answering.vqa import load_vqa
    model = load_vqa("runs/answering/vqa/counting-eqa/random")     # or the vqa.pt file itself
    probs = model.answer_probs(tokens, first_rgb, last_rgb)         # LongTensor [B, L], uint8 [B, H, W, 3] ×2
    model.answers[probs.argmax(-1)[0]]                              # e.g. "2"
    tokens = model.tokenize(["How many cans are there in the bin?"])

``load_vqa`` raises ``FileNotFoundError`` (no checkpoint) or ``ValueError`` (unreadable, not a VQA
checkpoint, weights that do not fit), each saying what to do; ``tokenize`` and ``answer_probs``
raise ``ValueError`` for a word or token outside the model's vocabulary.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
from pathlib import Path

import torch
import torch.nn.functional as F
from tensordict.nn import TensorDictModule
from torch import nn

from mqa_rl import keys
from mqa_rl.data.vocab import PAD, UNK, words
from mqa_rl.files import load_failure, refuse_nonfinite, write_atomic
from mqa_rl.modules.answering import vote_counting
from mqa_rl.modules.answering.perception import CountingPerception, check_library
from mqa_rl.modules.answering.vqa_encoder import FrameEncoder, standardise
from mqa_rl.modules.push.push_qnet import QuestionEncoder

VQA_FORMAT = "mqa_rl.vqa"
VQA_VERSION = 1
CHECKPOINT_NAME = "vqa.pt"          # what recipes/train_vqa.py writes into its out_dir
POOLS = ("eqa", "classes", "counts")
FUSIONS = ("attention", "max", "last")
TRAIN_HINT = "train one with `python recipes/train_vqa.py system=<name>` (it writes <out_dir>/vqa.pt)"


class _ClassChoice(nn.Module):
    """The question's choice of class (``heads`` softmaxes over the K class channels) shared by the
    question-selected pools; what the grounding loss supervises."""

    def __init__(self, num_classes: int, dim: int, heads: int):
        super().__init__()
        self.select = nn.Linear(dim, heads * num_classes)
        self.heads = heads

    def choice_logits(self, q: torch.Tensor) -> torch.Tensor:
        """[N, H, K]: which class each head picks, before the softmax (what the grounding loss supervises)."""
        return self.select(q).view(q.shape[0], self.heads, -1)


class QuestionClassPool(_ClassChoice):
    """Question-selected class maps (``pool="classes"``): [N, 2K, h, w] (class log-probabilities, then
    per-class object densities; ``FrameEncoder.class_maps``), q [N, D] → [N, D]."""

    def __init__(self, num_classes: int, dim: int, heads: int, dropout: float, width: int = 16):
        super().__init__(num_classes, dim, heads)
        self.conv = nn.Sequential(nn.Conv2d(2 * heads, width, 3, padding=1), nn.ReLU(inplace=True),
                                  nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True))
        self.norm = nn.LayerNorm(2 * width + 2 * heads)
        self.out = nn.Sequential(nn.Linear(2 * width + 2 * heads, dim), nn.ReLU(inplace=True), nn.Dropout(dropout))

    def forward(self, maps: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        maps = maps.float()
        k = maps.shape[1] // 2
        probs, density = maps[:, :k].exp(), maps[:, k:]                           # [N, K, h, w] each
        choice = F.softmax(self.choice_logits(q), dim=-1)                        # [N, H, K]
        area = torch.einsum("nhk,nkyx->nhyx", choice, probs)                     # share of the asked class per cell
        objects = torch.einsum("nhk,nkyx->nhyx", choice, density)                # its objects' centres
        both = torch.cat([area, objects], 1)
        c = self.conv(both)
        sums = both.flatten(2).sum(-1)                                           # [N, 2H]: area (cells), visible count
        return self.out(self.norm(torch.cat([c.flatten(2).mean(-1), c.flatten(2).amax(-1), sums], -1)))


class QuestionCountPool(_ClassChoice):
    """Question-selected counts (``pool="counts"``): per-class count features [N, K, F] of the counting
    perception (``vote_counting.count_features``; row 0 the image-wide entry, row c the class c), q [N, D]
    → [N, D]. The question picks classes (``heads`` softmaxes over them, supervised by the grounding
    loss); what each head picked and the image-wide entry go through one MLP."""

    def __init__(self, num_classes: int, features: int, dim: int, heads: int, dropout: float):
        super().__init__(num_classes, dim, heads)
        self.out = nn.Sequential(nn.Linear((heads + 1) * features, dim), nn.ReLU(inplace=True), nn.Dropout(dropout))

    def forward(self, feats: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        feats = feats.float()
        choice = F.softmax(self.choice_logits(q), dim=-1)                        # [N, H, K]
        picked = torch.einsum("nhk,nkf->nhf", choice, feats)                     # [N, H, F]
        return self.out(torch.cat([picked.flatten(1), feats[:, 0]], -1))


class VQAModel(nn.Module):
    """Two-frame VQA (see the module docstring). Build with ``VQAModel(vocab, answers, **config)``."""

    def __init__(self, vocab, answers, *, image_size: int = 224, encoder_channels=(8, 16, 32, 32), encoder_classes: int = 21,
                 encoder_head_width: int = 0, pool: str = "eqa", dim: int = 64, lstm_layers: int = 2, dropout: float = 0.5,
                 cell_heads: int = 4, freeze_encoder: bool = True, frame_fusion: str = "attention",
                 perception: dict | None = None):
        super().__init__()
        self.vocab = list(vocab)
        self.answers = list(answers)
        if self.vocab[:2] != [PAD, UNK]:
            raise ValueError(f"a question vocabulary starts with {PAD!r}, {UNK!r}; got {self.vocab[:2]}")
        if pool not in POOLS:
            raise ValueError(f"vqa pool={pool!r}; choose one of {POOLS}")
        if frame_fusion not in FUSIONS:
            raise ValueError(f"vqa frame_fusion={frame_fusion!r}; choose one of {FUSIONS}")
        self.config = {"image_size": int(image_size), "encoder_channels": list(encoder_channels),
                       "encoder_classes": int(encoder_classes), "encoder_head_width": int(encoder_head_width), "pool": pool,
                       "dim": int(dim), "lstm_layers": int(lstm_layers), "dropout": float(dropout),
                       "cell_heads": int(cell_heads), "freeze_encoder": bool(freeze_encoder), "frame_fusion": frame_fusion,
                       "perception": dict(perception) if perception else None}
        self._stoi = {w: i for i, w in enumerate(self.vocab)}
        if (pool == "counts") != bool(perception):
            raise ValueError("pool='counts' reads the counting perception: give both (perception=<its config>, as "
                             "recipes/train_vqa.py does with vqa=counting), or neither")
        self.encoder = CountingPerception(**perception) if perception else \
            FrameEncoder(tuple(encoder_channels), image_size, encoder_classes, encoder_head_width)
        self.pool = pool
        if pool == "counts":
            self.image_fc = QuestionCountPool(self.encoder.num_classes, vote_counting.FEATURES, dim, cell_heads, dropout)
        elif pool == "eqa":
            c, h, w = self.encoder.out_shape
            self.image_fc = nn.Sequential(nn.Linear(c * h * w, dim), nn.ReLU(inplace=True), nn.Dropout(dropout))
        else:
            self.image_fc = QuestionClassPool(encoder_classes, dim, cell_heads, dropout)
        self.question = QuestionEncoder(len(self.vocab), embed=dim, hidden=dim, layers=lstm_layers, out=dim)
        self.img_tr = nn.Sequential(nn.Linear(dim, dim), nn.Dropout(dropout))
        self.ques_tr = nn.Sequential(nn.Linear(dim, dim), nn.Dropout(dropout))
        self.att = nn.Sequential(nn.Tanh(), nn.Dropout(dropout), nn.Linear(2 * dim, 1))
        self.classifier = nn.Sequential(nn.Linear(dim, dim), nn.ReLU(inplace=True), nn.Dropout(dropout),
                                        nn.Linear(dim, len(self.answers)))
        self.set_encoder_frozen(freeze_encoder)

    # ------------------------------------------------------------------------------------ training
    def set_encoder_frozen(self, frozen: bool) -> None:
        """Frozen: no gradients and batch-norm statistics fixed (the encoder stays in eval mode)."""
        self.config["freeze_encoder"] = bool(frozen)
        for p in self.encoder.parameters():
            p.requires_grad_(not frozen)
        self.train(self.training)

    def train(self, mode: bool = True):
        super().train(mode)
        if self.config["freeze_encoder"] or self.pool == "counts":
            # a fine-tuned perception keeps its batch-norm statistics of the pretraining frames: the answers'
            # batches hold a few hundred piles' first and last images
            self.encoder.eval()
        return self

    # ------------------------------------------------------------------------------------ forward
    def encode_frames(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 rgb [..., 3, H, W] → what the image part of the model reads (and a frozen encoder's cache
        holds): the bottleneck [..., 32, 10, 10], for ``pool="classes"`` the class log-probabilities
        and object densities [..., 2K, 24, 24], for ``pool="counts"`` the perception's count features [..., K, F]."""
        batch = rgb.shape[:-3]
        if self.pool == "counts":
            trainable = not self.config["freeze_encoder"] and torch.is_grad_enabled()
            out = self.encoder.count_features(rgb.reshape(-1, *rgb.shape[-3:]), trainable=trainable).to(rgb.device)
            return out.reshape(*batch, *out.shape[1:])
        if self.pool != "classes":
            return self.encoder.encode(rgb)
        out = self.encoder.class_maps(standardise(rgb.reshape(-1, *rgb.shape[-3:]), self.encoder.image_size))
        return out.reshape(*batch, *out.shape[1:])

    def forward_features(self, question: torch.Tensor, first: torch.Tensor, last: torch.Tensor):
        """(logits [B, A], attention [B, 2]) from tokens [B, L] and encoder features [B, C, h, w] of both frames.
        With ``frame_fusion="max"`` the "attention" is the share of features each frame supplies (ties halved);
        with ``"last"`` it is all on I_stop."""
        q = self.question(question)                                              # [B, D]
        frames = torch.stack([first, last], 1)                                   # [B, 2, C, h, w]
        b, t = frames.shape[:2]
        flat = frames.flatten(0, 1)
        if self.pool == "eqa":
            v = self.image_fc(flat.flatten(1))
        else:
            v = self.image_fc(flat, q.repeat_interleave(t, 0))
        v = v.view(b, t, -1)                                                     # [B, 2, D]
        if self.config["frame_fusion"] == "max":
            last = ((v[:, 1] > v[:, 0]).float() + 0.5 * (v[:, 1] == v[:, 0]).float()).mean(-1)   # ties split evenly
            return self.classifier(q * v.amax(1)), torch.stack([1 - last, last], -1)
        if self.config["frame_fusion"] == "last":
            return self.classifier(q * v[:, 1]), torch.tensor([0.0, 1.0], device=v.device).expand(b, 2)
        joint = torch.cat([self.ques_tr(q).unsqueeze(1).expand(-1, t, -1), self.img_tr(v)], -1)
        attention = F.softmax(self.att(joint).squeeze(-1), dim=1)                # [B, 2]
        attended = (attention.unsqueeze(-1) * v).sum(1)
        return self.classifier(q * attended), attention

    @property
    def grounds_classes(self) -> bool:
        """Whether the question picks encoder classes (``pool="classes"`` or ``"counts"``): then
        ``grounding_logits`` exists."""
        return self.pool in ("classes", "counts")

    @property
    def frame_size(self) -> int | None:
        """The side of the frames this VQA reads in full (the counting perception's input: 448 for one trained on
        a 448-px render, whose rollouts need the env's answer camera); None: the env's frames, resized."""
        return self.encoder.input_size if self.pool == "counts" else None

    @property
    def feature_reader(self) -> "VQAModel | None":
        """Itself where what ``encode_frames`` gives is small enough to cache per rollout store (the counting
        perception's count features, ~0.6 kB a frame; ``recipes/evaluate.py`` reads them back), else None."""
        return self if self.pool == "counts" else None

    @property
    def invariant_features(self) -> bool:
        """Whether what ``encode_frames`` gives is the same for a rotated or mirrored image (counts are):
        then caching the 8 dihedral transforms of each frame buys nothing."""
        return self.pool == "counts"

    def grounding_logits(self, question: torch.Tensor) -> torch.Tensor:
        """[B, heads, K]: the classes pool's choice of class per head, from tokens [B, L]. Learnt from the
        answers alone, the choice stayed near uniform (docs/results.md, "Which class is the question about?"); the
        grounding loss (``VQALoss(grounding=...)``) supervises it with the classes the question names."""
        if not self.grounds_classes:
            raise ValueError(f"pool={self.pool!r} picks no classes: grounding_logits needs pool='classes' or 'counts'")
        return self.image_fc.choice_logits(self.question(question))

    def forward(self, question: torch.Tensor, first_rgb: torch.Tensor, last_rgb: torch.Tensor):
        """(logits [B, A], attention [B, 2]) from tokens [B, L] and uint8 images [B, 3, H, W]."""
        return self.forward_features(question, self.encode_frames(first_rgb), self.encode_frames(last_rgb))

    # ------------------------------------------------------------------------------------ public
    def tokenize(self, texts) -> torch.Tensor:
        """Question texts → LongTensor [B, L] (0-padded). An unknown word raises ``ValueError``."""
        rows = []
        for text in ([texts] if isinstance(texts, str) else list(texts)):
            ids = []
            for word in words(text):
                if word not in self._stoi or self._stoi[word] < 2:
                    known = ", ".join(self.vocab[2:12])
                    raise ValueError(f"unknown question word {word!r} in {text!r}: this VQA knows the "
                                     f"{len(self.vocab) - 2} words of its dataset's questions ({known}, ...); ask "
                                     f"with the dataset's templates, e.g. 'How many cans are there in the bin?'")
                ids.append(self._stoi[word])
            if not ids:
                raise ValueError(f"question {text!r} has no words")
            rows.append(torch.tensor(ids, dtype=torch.int64))
        return nn.utils.rnn.pad_sequence(rows, batch_first=True, padding_value=0)

    def check_tokens(self, tokens: torch.Tensor) -> None:
        """``ValueError`` unless tokens are int64 [B, L] ids of known words (0 = padding, ≥ 1 word per row)."""
        if not isinstance(tokens, torch.Tensor) or tokens.dtype != torch.int64 or tokens.dim() != 2:
            raise ValueError(f"question tokens must be a LongTensor [B, L]; got "
                             f"{getattr(tokens, 'dtype', type(tokens))} {tuple(getattr(tokens, 'shape', ()))}")
        if tokens.numel() and (int(tokens.min()) < 0 or int(tokens.max()) >= len(self.vocab)):
            raise ValueError(f"question token ids must lie in [0, {len(self.vocab)}) (this VQA's vocabulary); got "
                             f"{int(tokens.min())}…{int(tokens.max())}: were they made with another dataset's vocabulary? "
                             f"Use model.tokenize(texts)")
        if (tokens == 1).any():
            raise ValueError(f"the question holds an unknown word (token 1 = {UNK!r}); this VQA cannot answer it. "
                             f"Use model.tokenize(texts) to see which word")
        if ((tokens != 0).sum(-1) == 0).any():
            raise ValueError("a question row holds only padding (token 0)")

    def answer_probs(self, question_tokens: torch.Tensor, first_rgb: torch.Tensor, last_rgb: torch.Tensor) -> torch.Tensor:
        """P(answer) [B, len(answers)] from tokens LongTensor [B, L] and uint8 images [B, H, W, 3] (I_start, I_stop).

        Images of another size are resized to the model's (224 px). Runs in eval mode, without gradients."""
        self.check_tokens(question_tokens)
        return self.answer_probs_from_features(question_tokens, *self.frame_features(first_rgb, last_rgb, question_tokens.shape[0]))

    def frame_features(self, first_rgb: torch.Tensor, last_rgb: torch.Tensor, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``encode_frames`` of uint8 images [B, H, W, 3] (checked) in eval mode, without gradients: what
        ``answer_probs_from_features`` reads (VQAs sharing one frozen perception compute it once)."""
        for name, img in (("first_rgb", first_rgb), ("last_rgb", last_rgb)):
            if (not isinstance(img, torch.Tensor) or img.dtype != torch.uint8 or img.dim() != 4 or img.shape[0] != batch
                    or img.shape[-1] != 3):
                raise ValueError(f"{name} must be a uint8 tensor [B={batch}, H, W, 3]; got "
                                 f"{getattr(img, 'dtype', type(img))} {tuple(getattr(img, 'shape', ()))}")
        device = next(self.parameters()).device
        if first_rgb.shape != last_rgb.shape:           # frames of two sizes: each is resized on its own
            with self._evaluating(), torch.no_grad():
                return tuple(self.encode_frames(img.permute(0, 3, 1, 2).to(device)) for img in (first_rgb, last_rgb))
        images = torch.cat([first_rgb, last_rgb])
        fresh, copies = split_repeats(images, {}, lambda i: i)
        with self._evaluating(), torch.no_grad():
            encoded = self.encode_frames(images[fresh].permute(0, 3, 1, 2).to(device))
        features = encoded.new_empty((len(images), *encoded.shape[1:]))
        features[fresh] = encoded
        if copies:                          # each copy's source is a fresh image, filled just above
            to, src = zip(*copies)
            features[list(to)] = features[list(src)]
        return features[:batch], features[batch:]

    def answer_probs_from_features(self, question_tokens: torch.Tensor, first: torch.Tensor, last: torch.Tensor) -> torch.Tensor:
        """``answer_probs`` from ``frame_features`` (tokens checked by the caller)."""
        device = next(self.parameters()).device
        with self._evaluating(), torch.no_grad():
            logits, _ = self.forward_features(question_tokens.to(device), first, last)
        return F.softmax(logits.float(), -1).cpu()

    @contextlib.contextmanager
    def _evaluating(self):
        was_training = self.training
        self.eval()
        try:
            yield
        finally:
            self.train(was_training)

    def check_dataset(self, dataset) -> None:
        """``ValueError`` unless ``dataset`` (an ``MQADataset``) tokenises questions and names answers as this model."""
        if list(dataset.vocab.itos) != self.vocab or list(dataset.answers) != self.answers:
            raise ValueError(f"this VQA was trained with another question or answer vocabulary than {dataset.root}'s "
                             f"({len(self.vocab)} vs {len(dataset.vocab)} words, answers {self.answers} vs "
                             f"{list(dataset.answers)}): retrain it on this dataset's rollouts")
        if self.pool == "counts":                       # its perception counts this dataset's object classes
            check_library(self.encoder, len(dataset.classes), "of this VQA")


def image_digest(image: torch.Tensor) -> bytes:
    """A digest of one image's bytes: equal images (a scene's I_start in each of its episodes) are encoded once."""
    return hashlib.sha1(image.detach().cpu().contiguous().numpy().tobytes()).digest()


def split_repeats(images: torch.Tensor, seen: dict, place) -> tuple[list[int], list[tuple[int, object]]]:
    """Each distinct image encoded once: the indices of ``images`` whose bytes ``seen`` does not hold yet (it records
    ``place(i)`` for each), and for the others (index, the place of the equal image seen first). ``seen`` may
    carry over between calls (a store read chunk by chunk). I_stop = I_start where nothing was pushed, and a
    scene's I_start is the same render in every episode of it."""
    fresh, copies = [], []
    for i in range(images.shape[0]):
        digest = image_digest(images[i])
        if digest in seen:
            copies.append((i, seen[digest]))
        else:
            seen[digest] = place(i)
            fresh.append(i)
    return fresh, copies


class _FromFeatures(nn.Module):
    def __init__(self, model: VQAModel):
        super().__init__()
        self.model = model

    def forward(self, question, first, last):
        return self.model.forward_features(question, first, last)


def grounding_module(model: VQAModel) -> TensorDictModule:
    """The classes pool's choice of class per head as a TensorDict module (question → grounding logits),
    for ``VQALoss(grounding=...)``."""
    return TensorDictModule(model.grounding_logits, in_keys=[keys.QUESTION], out_keys=[keys.GROUNDING_LOGITS])


def answer_size_for(models, image_size: int) -> int | None:
    """The answer camera a set of VQAs needs beside an env rendering ``image_size`` px: the finest ``frame_size``
    above it (None: every one reads the env's frames). What evaluate.py collects and the demo's env renders."""
    finer = [m.frame_size for m in models if (getattr(m, "frame_size", None) or 0) > image_size]
    return max(finer) if finer else None


def vqa_module(model: VQAModel, *, from_features: bool = False) -> TensorDictModule:
    """The VQA as a TensorDict module: reads the question and both frames' rgb (or, with
    ``from_features``, the frozen encoder's cached features), writes answer logits and frame attention."""
    if from_features:
        return TensorDictModule(_FromFeatures(model), in_keys=[keys.QUESTION, keys.FIRST_FEATURES, keys.LAST_FEATURES],
                                out_keys=[keys.ANSWER_LOGITS, keys.FRAME_ATTENTION])
    return TensorDictModule(model, in_keys=[keys.QUESTION, keys.FIRST_RGB, keys.LAST_RGB],
                            out_keys=[keys.ANSWER_LOGITS, keys.FRAME_ATTENTION])


# ----------------------------------------------------------------------------------------- files
def save_vqa(model: VQAModel, path: str | Path, meta: dict | None = None) -> Path:
    """Write a self-describing VQA checkpoint (config, vocabularies, weights, ``meta``) atomically."""
    path = Path(path)
    blob = {"format": VQA_FORMAT, "version": VQA_VERSION, "config": dict(model.config), "vocab": list(model.vocab),
            "answers": list(model.answers), "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
            "meta": dict(meta or {})}
    buffer = io.BytesIO()
    torch.save(blob, buffer)
    return write_atomic(path, buffer.getvalue())


def load_vqa(path: str | Path, map_location: str | torch.device = "cpu") -> VQAModel:
    """The VQA saved at ``path`` (a ``vqa.pt`` file or the train_vqa.py folder holding it), in eval mode.

    ``model.meta`` holds what it was trained on. Raises ``FileNotFoundError`` when there is no
    checkpoint, ``ValueError`` when it cannot be read, is not a VQA checkpoint or does not fit."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT_NAME
    if not path.is_file():
        raise FileNotFoundError(f"no VQA checkpoint at {path}: {TRAIN_HINT}")
    try:
        blob = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as error:
        raise ValueError(f"{path} cannot be read as a VQA checkpoint ({load_failure(error)}); it "
                         f"may be truncated or another kind of file: {TRAIN_HINT}") from error
    fmt = blob.get("format") if isinstance(blob, dict) else None
    if fmt != VQA_FORMAT:
        raise ValueError(f"{path} is not a VQA checkpoint (format {fmt!r}, expected {VQA_FORMAT!r}): {TRAIN_HINT}")
    if int(blob.get("version", 0)) > VQA_VERSION:
        raise ValueError(f"{path} has VQA format version {blob['version']}, newer than this mqa_rl's {VQA_VERSION}: "
                         f"update mqa_rl")
    refuse_nonfinite(blob.get("state_dict"), path, TRAIN_HINT)
    try:
        model = VQAModel(blob["vocab"], blob["answers"], **blob["config"])
        model.load_state_dict(blob["state_dict"])
    except (KeyError, TypeError, RuntimeError, ValueError) as error:
        raise ValueError(f"{path}: the checkpoint does not fit the VQA model ({type(error).__name__}: "
                         f"{str(error)[:300]}); {TRAIN_HINT}") from error
    model.meta = dict(blob.get("meta", {}))
    return model.to(map_location).eval()
