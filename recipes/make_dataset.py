"""Make the MQA dataset (objects, settled scenes, questions) unless a valid one is already there,
then print its summary and draw its answer statistics.

    python recipes/make_dataset.py                          # the default 100-scene dataset
    python recipes/make_dataset.py dataset.seed=1 dataset.out_dir=data/mqa_seed1
    python recipes/make_dataset.py 'dataset.num_scenes={easy: 3, medium: 0, hard: 2}'
    python recipes/make_dataset.py workers=1                 # settle the scenes in this process alone
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from mqa_rl.data import DatasetError, MQADataset, generate_dataset
from mqa_rl.data.stats import plot_statistics
from mqa_rl.data.storage import recover_leftovers


@hydra.main(config_path="conf", config_name="make_dataset", version_base="1.3")
def main(cfg: DictConfig) -> None:
    d = cfg.dataset
    out = Path(d.out_dir)
    ds = None
    recover_leftovers(out)            # an interrupted earlier run: restore or clean up, with a warning
    if out.exists() and not d.overwrite:
        try:
            ds = MQADataset(out)
            print(f"[make_dataset] a valid dataset is already at {out}; keeping it (dataset.overwrite=true regenerates)")
        except DatasetError as e:
            sys.exit(f"[make_dataset] {e}\n[make_dataset] or pass dataset.overwrite=true to replace it")
    if ds is None:
        t0 = time.perf_counter()
        ds = generate_dataset(
            out,
            seed=d.seed,
            num_scenes=OmegaConf.to_container(d.num_scenes),
            library=d.library,
            train_fraction=d.train_fraction,
            bin_spec=OmegaConf.to_container(d.bin),
            overwrite=d.overwrite,
            progress=True,
            workers=cfg.workers,
        )
        print(f"[make_dataset] generated {out} in {time.perf_counter() - t0:.1f} s")
    print(ds.summary())
    plot_statistics(ds.stats, cfg.plot)
    print(f"[make_dataset] answer statistics figure: {cfg.plot}")


if __name__ == "__main__":
    main()
