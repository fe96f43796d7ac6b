"""Fixtures shared by the training test files."""
import pytest


@pytest.fixture(scope="module")
def one_torch_thread():
    """One torch thread for a whole module: the short fits are faster and their numbers
    are the same on every machine (a module asks for it in ``pytestmark``)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
