"""A resumed run must be the same experiment: changed settings are named and refused unless allowed."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from mqa_rl.training.resume_guard import config_changes, refuse_changed_config

RUN = {"seed": 0, "resume": False, "optim": {"lr": 5e-4}, "reward": {"name": "global", "beta": [1.0, 0.5]},
       "collector": {"total_frames": 600, "num_workers": 2}, "logger": {"wandb": True}, "out_dir": "runs/a"}


def _with(**changes) -> dict:
    cfg = OmegaConf.create(RUN)
    for key, value in changes.items():
        OmegaConf.update(cfg, key.replace("__", "."), value)
    return OmegaConf.to_container(cfg)


def test_lengthening_logging_and_paths_are_not_changes():
    new = _with(resume=True, collector__total_frames=1200, logger__wandb=False, out_dir="runs/b")
    assert config_changes(RUN, new) == []


def test_every_changed_added_or_removed_setting_is_named():
    new = _with(optim__lr=1e-4, reward__beta=[1.0, 0.2], collector__num_workers=1)
    new["demos"] = {"weight": 2.0}
    del new["seed"]
    assert config_changes(RUN, new) == ["collector.num_workers: 2 -> 1", "demos.weight: '(unset)' -> 2.0",
                                        "optim.lr: 0.0005 -> 0.0001", "reward.beta: [1.0, 0.5] -> [1.0, 0.2]",
                                        "seed: 0 -> '(unset)'"]


def test_refused_unless_allowed(tmp_path, capsys):
    saved = tmp_path / "config.yaml"
    assert refuse_changed_config(saved, _with(optim__lr=1.0)) == []          # no saved config: nothing to compare
    OmegaConf.save(OmegaConf.create(RUN), saved)
    assert refuse_changed_config(saved, _with(collector__total_frames=900)) == []
    with pytest.raises(ValueError, match=r"(?s)optim\.lr: 0\.0005 -> 1\.0.*resume_allow_changes=true"):
        refuse_changed_config(saved, _with(optim__lr=1.0))
    assert refuse_changed_config(saved, _with(optim__lr=1.0), allow=True) == ["optim.lr: 0.0005 -> 1.0"]
    assert "continuing under changed settings" in capsys.readouterr().out


def test_demonstration_settings_are_free_only_when_neither_run_learns_from_demonstrations(tmp_path):
    """A changed default of demos.* changes no experiment that never reads it; one that does is refused."""
    from conftest import load_recipe

    resumable = load_recipe("train_dqn").resumable
    saved = tmp_path / "config.yaml"
    OmegaConf.save(OmegaConf.create({**RUN, "demos": {"path": None, "loss": "margin"}}), saved)
    plain = {**RUN, "demos": {"path": None, "loss": "push_cross_entropy"}}
    assert refuse_changed_config(saved, plain, free=resumable(saved, plain)) == []
    imitating = {**RUN, "demos": {"path": "runs/demos", "loss": "push_cross_entropy"}}
    with pytest.raises(ValueError, match=r"demos\.loss: 'margin' -> 'push_cross_entropy'"):
        refuse_changed_config(saved, imitating, free=resumable(saved, imitating))


def test_another_recipes_folder_is_named_not_diffed(tmp_path):
    saved = tmp_path / "config.yaml"
    saved.write_text(OmegaConf.to_yaml(OmegaConf.create(RUN)))
    vqa = {"system": "random", "vqa": {"name": "counting"}, "train": {"lr": 1e-3}, "seed": 0, "out_dir": "runs/a"}
    with pytest.raises(ValueError, match=r"holds another recipe's run .*'optim'.*\['system', 'train', 'vqa'\].*choose another out_dir"):
        refuse_changed_config(saved, vqa)
    one_new_section = {**RUN, "demos": {"weight": 2.0}}                     # a changed setting stays a changed setting
    with pytest.raises(ValueError, match="demos.weight"):
        refuse_changed_config(saved, one_new_section)
