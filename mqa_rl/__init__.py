"""mqa_rl: Manipulation Question Answering on SAPIEN 3 physics and TorchRL.

Importing the package is cheap on purpose (CLIs import it): SAPIEN, torch and torchvision are only
imported by the submodules that need them.
"""

import os

# Idle OpenMP threads sleep instead of spinning: with the simulator (and other jobs) on the same 2
# cores, spinning torch threads made updates 7-40x slower (measured). OpenMP reads this when torch
# loads, so a recipe imports mqa_rl before torch.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
