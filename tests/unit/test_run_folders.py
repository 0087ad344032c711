"""run= must name a train_dqn.py run folder: another recipe's folder, or an export given to export_policy, is
named as such before anything is built (it used to fail deep inside with `Missing key reward` or
`missing=['trainer_state']`)."""

import pytest
from conftest import REPO, compose_recipe_config, load_recipe

from mqa_rl.modules.push.trained_policy import read_run_config


def test_another_recipes_folder_is_named_not_a_missing_key(tmp_path):
    (tmp_path / "eval").mkdir()
    (tmp_path / "eval" / "config.yaml").write_text("run: runs/x\npolicies: [greedy]\nepisodes_per_level: 3\n")
    with pytest.raises(ValueError, match="has no dataset, env, model, reward: .*another recipe's folder"):
        read_run_config(tmp_path / "eval")
    with pytest.raises(FileNotFoundError, match="run= must be a recipes/train_dqn.py output folder"):
        read_run_config(tmp_path / "nothing")
    assert read_run_config(REPO / "checkpoints" / "dqn_local").reward.name == "local"


def test_export_policy_refuses_an_export(tmp_path):
    export = load_recipe("export_policy")
    cfg = compose_recipe_config("export_policy", [f"run={REPO / 'checkpoints' / 'dqn_local'}", f"out_dir={tmp_path / 'x'}"])
    with pytest.raises(ValueError, match="is already an export of .* use it as it is"):
        export.export(cfg)
    with pytest.raises(ValueError, match="export=polcy: one of policy, recognition"):
        export.export(compose_recipe_config("export_policy", ["export=polcy", f"run={REPO / 'checkpoints' / 'dqn_local'}",
                                                              f"out_dir={tmp_path / 'x'}"]))
    assert not (tmp_path / "x").exists()


def test_evaluate_policy_plots_only_training_runs_and_learning_curves(tmp_path):
    """plot=[...]: a folder that is neither a train_dqn.py run nor a snapshots=true folder is named, with how to make a
    learning curve, before anything is drawn."""
    evaluate_policy = load_recipe("evaluate_policy")
    (tmp_path / "eval").mkdir()
    cfg = compose_recipe_config("evaluate_policy", [f"plot=[{tmp_path / 'eval'}]", f"out_dir={tmp_path / 'figures'}"])
    with pytest.raises(FileNotFoundError, match="is neither a train_dqn.py run .* snapshots=true out_dir="):
        evaluate_policy.plot(cfg)
    assert not (tmp_path / "figures").exists()


def test_an_evaluation_logs_into_a_training_runs_dashboards_never_into_an_exported_policy(tmp_path):
    from mqa_rl.training.policy_export import has_dashboards

    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    assert has_dashboards(run)
    export = tmp_path / "export"
    (export / "checkpoints").mkdir(parents=True)
    (export / "provenance.json").write_text('{"source_run": "runs/x"}')
    assert not has_dashboards(export) and not has_dashboards(None) and not has_dashboards(tmp_path / "none")
