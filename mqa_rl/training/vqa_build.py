"""The VQA a ``train_vqa.py`` config names, for a dataset's vocabularies: the paper's head on EQA's pretrained encoder
or on the counting perception, its weights loaded from their files (each checked against the dataset), or started
from a trained VQA file to fine-tune it."""

from __future__ import annotations

import warnings

from omegaconf import DictConfig

from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.modules.answering.perception import check_library, load_perception
from mqa_rl.modules.answering.vqa import VQAModel, load_vqa
from mqa_rl.modules.answering.vqa_encoder import load_encoder

# the vqa config's keys that are the model's architecture
MODEL_OPTIONS = ("pool", "image_size", "dim", "lstm_layers", "dropout", "cell_heads", "frame_fusion")


def build_model(cfg: DictConfig, ds: MQADataset) -> tuple[VQAModel, dict]:
    """The VQA for ``ds``'s vocabularies with the pretrained encoder (if given) loaded; the encoder's
    architecture (channels, head width) is the file's."""
    options = {k: cfg.vqa[k] for k in MODEL_OPTIONS}
    if cfg.vqa.pool == "counts":                      # the counting perception in place of EQA's CNN
        perception, perception_meta = load_perception(cfg.perception.weights)
        check_library(perception, len(ds.classes), cfg.perception.weights)
        if perception.depth:
            raise ValueError(f"perception {cfg.perception.weights} reads depth (model.depth=true), which the VQA does not "
                             f"pass it yet (its answer contract is rgb: docs/perception.md, 'Depth as an input'): "
                             f"name an rgb perception, e.g. checkpoints/vqa_counting/perception.pt")
        model = VQAModel(ds.vocab.itos, ds.answers, freeze_encoder=bool(cfg.encoder.freeze),
                         encoder_classes=1 + len(ds.classes), perception=perception.config(), **options)
        model.encoder.load_state_dict(perception.state_dict())
        kept = {k: perception_meta.get(k) for k in ("command", "frames", "step", "val", "train_seconds")}
        return model, {"perception": str(cfg.perception.weights), **kept}
    encoder, encoder_meta = load_encoder(cfg.encoder.weights) if cfg.encoder.weights else (None, {})
    if encoder is not None:
        options.update(encoder_channels=encoder.channels, encoder_head_width=encoder.head_width)
    model = VQAModel(ds.vocab.itos, ds.answers, freeze_encoder=bool(cfg.encoder.freeze), encoder_classes=1 + len(ds.classes),
                     **options)
    if encoder is not None:
        found = (encoder.image_size, encoder.num_classes)
        needed = (model.encoder.image_size, model.encoder.num_classes)
        if found != needed:
            raise ValueError(f"encoder {cfg.encoder.weights} has (image size, classes) {found}, the VQA "
                             f"needs {needed}: pretrain it again for this dataset and vqa config")
        if encoder_meta.get("dataset_sha256") not in (None, dataset_fingerprint(ds.root)):
            warnings.warn(f"encoder {cfg.encoder.weights} was pretrained on another dataset", stacklevel=2)
        model.encoder.load_state_dict(encoder.state_dict())
    elif cfg.encoder.freeze:
        warnings.warn("encoder.weights=null with encoder.freeze=true: the VQA reads a fixed random projection of the "
                      "images; pretrain one (recipes/pretrain.py part=vqa_encoder) or set encoder.freeze=false", stacklevel=2)
    return model, encoder_meta


def start_from(model: VQAModel, path: str) -> dict:
    """Copy a trained VQA file's weights (head and encoder) into ``model``: a frozen head fine-tuned with its
    encoder starts where it stood. Refuses a file of other vocabularies or another architecture."""
    init = load_vqa(path)
    differs = {k: (init.config.get(k), v) for k, v in model.config.items()
               if k not in ("freeze_encoder", "perception") and init.config.get(k) != v}
    there, here = init.config.get("perception") or {}, model.config.get("perception") or {}
    differs.update({f"perception.{k}": (there[k], here[k]) for k in there.keys() & here.keys() if there[k] != here[k]})
    if bool(there) != bool(here):
        differs["perception"] = (there or None, here or None)
    hint = "start from a head trained with the same vqa config and dataset, or set init_from=null"
    if init.vocab != model.vocab or init.answers != model.answers or differs:
        what = ", ".join(f"{k}: {a!r} there, {b!r} here" for k, (a, b) in differs.items()) or "the vocabularies"
        raise ValueError(f"init_from={path} does not fit this VQA ({what}): {hint}")
    try:                                               # settings an older file lacks are checked by its weights
        model.load_state_dict(init.state_dict())
    except RuntimeError as error:
        raise ValueError(f"init_from={path} does not fit this VQA ({str(error)[:300]}): {hint}") from error
    return {"init_from": str(path), "init_step": init.meta.get("step")}
