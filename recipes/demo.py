"""Serve the interactive web demo (Gradio) on this machine.

    python recipes/demo.py                                  # http://127.0.0.1:7860, the shipped policies and VQA
    python recipes/demo.py runs=runs vqa=[runs/vqa/best] port=8080 max_pushes=5
    python recipes/demo.py host=0.0.0.0                     # reachable from the network: think first

Start-up (dataset check, simulators, shader compile, scene images, policies, VQA) happens once here;
then each "Run" plays an episode live. Ctrl-C stops the server.
"""

from __future__ import annotations

import logging

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.demo.backend import DemoBackend, DemoConfig
from mqa_rl.modules.systems import systems_by_id


@hydra.main(config_path="conf", config_name="demo", version_base="1.3")
def main(cfg: DictConfig) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", force=True)
    logging.getLogger("httpx").setLevel(logging.WARNING)            # gradio's own requests to itself
    if cfg.threads:
        torch.set_num_threads(int(cfg.threads))
    from mqa_rl.demo.app import launch                  # gradio: the 'demo' extra

    backend = DemoBackend(DemoConfig(dataset=cfg.dataset, reward=OmegaConf.to_container(cfg.reward, resolve=True),
                                     runs=cfg.runs, vqa=tuple(cfg.vqa), max_pushes=cfg.max_pushes,
                                     sessions=cfg.sessions, cache_dir=cfg.cache_dir, beta_steps=cfg.beta_steps,
                                     policy=cfg.policy, systems=systems_by_id(cfg.systems, cfg.offered)))
    print(f"ready in {backend.startup_s:.1f} s\n{backend.status()}", flush=True)
    try:
        launch(backend, host=cfg.host, port=cfg.port)
    finally:
        backend.close()


if __name__ == "__main__":
    main()
