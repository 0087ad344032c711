"""mqa_rl: Manipulation Question Answering on SAPIEN 3 physics and TorchRL.

Importing the package is cheap on purpose (CLIs import it): SAPIEN, torch and torchvision are only
imported by the submodules that need them.
"""

__version__ = "0.1.0"
