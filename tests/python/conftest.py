"""Fixtures shared by the training test files."""
import os

import pytest

# --precision auto's timed probe (training/precision.py) is off in the tests, so every run's
# precision follows the models' measured policy whatever the load; test_precision_probe.py
# turns it on where it is the subject. (Subprocesses inherit this.)
os.environ.setdefault("BSP_PRECISION_PROBE", "0")


@pytest.fixture(scope="module")
def one_torch_thread():
    """One torch thread for a whole module: the short fits are faster and their numbers
    are the same on every machine (a module asks for it in ``pytestmark``)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
