"""The VQA model and its public contract: forward / backward, attention over the two frames, the
checkpoint round trip, and clear errors for missing, corrupt or mismatched checkpoints and for
questions outside the vocabulary."""

import pytest
import torch

from mqa_rl.data.vocab import Vocabulary
from mqa_rl.modules.answering.vqa import VQAModel, load_vqa, save_vqa
from conftest import REPO

VOCAB = Vocabulary.build(["How many cans are there in the bin?", "Is there a can in the bin?",
                          "How many apples are there in the bin?"]).itos
ANSWERS = ("0", "1", "2", "3", "yes", "no")


def _batch(model, b=3, size=224):
    gen = torch.Generator().manual_seed(0)
    q = model.tokenize(["How many cans are there in the bin?", "Is there a can in the bin?",
                        "How many apples are there in the bin?"][:b])
    first = torch.randint(0, 256, (b, 3, size, size), dtype=torch.uint8, generator=gen)
    last = torch.randint(0, 256, (b, 3, size, size), dtype=torch.uint8, generator=gen)
    return q, first, last


def _encoded(model):
    """(tokens, I_start features, I_stop features) of ``_batch``."""
    q, first, last = _batch(model)
    return q, model.encode_frames(first), model.encode_frames(last)


@pytest.mark.parametrize("pool", ["eqa", "classes"])
@pytest.mark.parametrize("frozen", [True, False])
def test_forward_backward_and_attention_over_two_frames(pool, frozen):
    torch.manual_seed(0)
    model = VQAModel(VOCAB, ANSWERS, pool=pool, freeze_encoder=frozen).train()
    q, first, last = _batch(model)
    logits, attention = model(q, first, last)
    assert logits.shape == (3, len(ANSWERS)) and attention.shape == (3, 2)
    assert torch.allclose(attention.sum(-1), torch.ones(3)) and (attention >= 0).all()
    torch.nn.functional.cross_entropy(logits, torch.tensor([1, 4, 2])).backward()
    # "classes" reads the class head on the third block; the others read the fourth block's bottleneck
    used = [*model.encoder.net[:12].parameters(), *model.encoder.class_head.parameters()] if pool == "classes" \
        else list(model.encoder.net.parameters())
    enc_grads = [p.grad for p in used]
    if frozen:
        assert all(g is None for g in enc_grads) and not model.encoder.training     # BN statistics stay fixed
    else:
        assert all(g is not None and torch.isfinite(g).all() for g in enc_grads) and model.encoder.training
    head = [p for n, p in model.named_parameters() if not n.startswith("encoder.")]
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in head)
    # the cached-features path gives the same answer as the image path
    model.eval()
    with torch.no_grad():
        a, _ = model(q, first, last)
        b, _ = model.forward_features(q, model.encode_frames(first), model.encode_frames(last))
    assert torch.allclose(a, b, atol=1e-5)


def test_max_frame_fusion_takes_each_features_larger_value_and_round_trips(tmp_path):
    """frame_fusion="max": the classifier reads q ⊙ max(v_start, v_stop), so a frame that shows more of the
    asked class cannot be averaged away; the reported shares sum to 1; the option survives save/load."""
    torch.manual_seed(0)
    model = VQAModel(VOCAB, ANSWERS, pool="classes", frame_fusion="max").eval()
    q, f, l = _encoded(model)
    with torch.no_grad():
        logits, share = model.forward_features(q, f, l)
        qv = model.question(q)
        v = torch.stack([model.image_fc(f, qv), model.image_fc(l, qv)], 1)
        assert torch.allclose(logits, model.classifier(qv * v.amax(1)), atol=1e-5)
        assert torch.allclose(share.sum(-1), torch.ones(3)) and (share >= 0).all()
        assert torch.equal(model.forward_features(q, f, f)[1], torch.full((3, 2), 0.5))    # one frame twice: ties
        swapped, _ = model.forward_features(q, l, f)
    assert torch.allclose(logits, swapped, atol=1e-5)              # the order of the frames does not matter
    loaded = load_vqa(save_vqa(model, tmp_path / "vqa.pt"))
    assert loaded.config["frame_fusion"] == "max"
    with torch.no_grad():
        assert torch.allclose(loaded.forward_features(q, f, l)[0], logits, atol=1e-5)
    with pytest.raises(ValueError, match="frame_fusion"):
        VQAModel(VOCAB, ANSWERS, frame_fusion="sum")


def test_last_frame_fusion_reads_i_stop_alone():
    """frame_fusion="last" (the I_stop-only ablation): the answer does not move with I_start."""
    torch.manual_seed(0)
    model = VQAModel(VOCAB, ANSWERS, pool="eqa", frame_fusion="last").eval()
    q, f, l = _encoded(model)
    with torch.no_grad():
        logits, attention = model.forward_features(q, f, l)
        assert torch.allclose(logits, model.forward_features(q, l, l)[0], atol=1e-7)
        assert not torch.allclose(logits, model.forward_features(q, l, f)[0], atol=1e-5)   # I_stop moves it
    assert torch.equal(attention, torch.tensor([[0.0, 1.0]] * 3))


def test_answer_probs_contract_and_round_trip(tmp_path):
    torch.manual_seed(0)
    model = VQAModel(VOCAB, ANSWERS, pool="classes")
    q, first, last = _batch(model, b=2)
    hwc = (first.permute(0, 2, 3, 1).contiguous(), last.permute(0, 2, 3, 1).contiguous())
    probs = model.answer_probs(q, *hwc)
    assert probs.shape == (2, 6) and probs.dtype == torch.float32 and torch.allclose(probs.sum(-1), torch.ones(2))
    assert model.training                                          # answer_probs leaves the mode as it was
    small = model.answer_probs(q, hwc[0][:, ::2, ::2].contiguous(), hwc[1][:, ::2, ::2].contiguous())
    assert small.shape == (2, 6)                                   # other image sizes are resized
    save_vqa(model, tmp_path / "run" / "vqa.pt", meta={"system": "random"})
    for where in (tmp_path / "run", tmp_path / "run" / "vqa.pt"):
        loaded = load_vqa(where)
        assert loaded.answers == list(ANSWERS) and not loaded.training and loaded.meta["system"] == "random"
        assert torch.allclose(loaded.answer_probs(q, *hwc), model.eval().answer_probs(q, *hwc), atol=1e-6)
    assert not list((tmp_path / "run").glob(".*"))                 # nothing half-written left behind


class Payload:
    """Any pickled object: unpickling it would import and run code named by the file."""


def test_clear_errors_for_checkpoints_and_questions(tmp_path):
    model = VQAModel(VOCAB, ANSWERS)
    with pytest.raises(FileNotFoundError, match="train_vqa.py"):
        load_vqa(tmp_path / "nowhere")
    path = save_vqa(model, tmp_path / "vqa.pt")
    data = path.read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated"):
        load_vqa(tmp_path / "cut.pt")
    torch.save({"policy": torch.zeros(3)}, tmp_path / "dqn.pt")
    with pytest.raises(ValueError, match="not a VQA checkpoint"):
        load_vqa(tmp_path / "dqn.pt")
    (tmp_path / "noise.pt").write_bytes(bytes(range(256)) * 8)
    torch.save({"format": "mqa_rl.vqa", "payload": Payload()}, tmp_path / "pickled.pt")   # an object: code on load
    for name, reason in (("noise.pt", "not a file of tensors"), ("pickled.pt", "never unpickled")):
        with pytest.raises(ValueError, match=reason) as refused:
            load_vqa(tmp_path / name)
        assert "weights_only" not in str(refused.value)               # never the advice to run the file's code
    blob = torch.load(path, weights_only=True)
    blob["config"]["dim"] = 32                                       # weights of another architecture
    torch.save(blob, tmp_path / "mismatch.pt")
    with pytest.raises(ValueError, match="does not fit"):
        load_vqa(tmp_path / "mismatch.pt")
    with pytest.raises(ValueError, match="unknown question word 'zebras'"):
        model.tokenize("How many zebras are there in the bin?")
    img = torch.zeros(1, 224, 224, 3, dtype=torch.uint8)
    with pytest.raises(ValueError, match="unknown word"):
        model.answer_probs(torch.tensor([[1, 3]]), img, img)
    with pytest.raises(ValueError, match="another dataset"):
        model.answer_probs(torch.tensor([[len(VOCAB) + 5]]), img, img)
    with pytest.raises(ValueError, match="uint8"):
        model.answer_probs(model.tokenize("How many cans are there in the bin?"), img.float(), img)


def test_the_demos_default_vqas_load_and_answer_a_counting_question(small_dataset):
    """recipes/conf/demo.yaml's VQAs (the shipped counting heads, the learned student's system first): each loads
    with the question types it learnt and answers through the public contract."""
    from omegaconf import OmegaConf

    from mqa_rl.demo.vqa_adapter import trained_types

    paths = [REPO / p for p in OmegaConf.load(REPO / "recipes" / "conf" / "demo.yaml").vqa]
    assert paths and paths[0].name == "dqn_student"
    frame = torch.full((1, 224, 224, 3), 128, dtype=torch.uint8)
    for folder in paths:
        model = load_vqa(folder)
        assert model.meta["system"] == folder.name and model.answers == list(small_dataset.answers)
        assert trained_types(model, folder) == ["counting"]
        probs = model.answer_probs(model.tokenize(["How many cans are there in the bin?"]), frame, frame)
        assert probs.shape == (1, len(model.answers)) and torch.allclose(probs.sum(-1), torch.ones(1))


@pytest.mark.parametrize("name, head_width", [("vqa_encoder", 0), ("vqa_encoder_scenes", 64)])
def test_the_shipped_encoders_load_and_encode(name, head_width):
    """checkpoints/vqa_encoder{,_scenes}: what `encoder.weights=` points users at loads as the encoder it was
    pretrained as (the scenes one with its context heads) and gives the VQA's bottleneck and class maps."""
    from mqa_rl.modules.answering.vqa_encoder import load_encoder, standardise

    encoder, meta = load_encoder(REPO / "checkpoints" / name / "encoder.pt")
    assert encoder.head_width == head_width and encoder.out_shape == (32, 10, 10)
    frame = torch.randint(0, 256, (2, 3, 224, 224), dtype=torch.uint8)
    with torch.no_grad():
        assert encoder.eval().encode(frame).shape == (2, 32, 10, 10)
        maps = encoder.class_maps(standardise(frame, encoder.image_size))
    k = encoder.num_classes
    assert maps.shape == (2, 2 * k, 24, 24) and torch.allclose(maps[:, :k].exp().sum(1), torch.ones(2, 24, 24), atol=1e-4)
    assert (maps[:, k:] >= 0).all()                                      # densities
