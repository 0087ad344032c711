"""A fixture for tests that run torch models: one torch thread.

The machines are shared: two torch threads on a busy 2-core machine spin-wait (measured 40× slower).
Import it into a test module (``from torch_threads import one_torch_thread  # noqa: F401``); it is autouse.
"""

import pytest
import torch


@pytest.fixture(autouse=True)
def one_torch_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
