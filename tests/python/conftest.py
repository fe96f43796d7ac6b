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


#: The test files that cost the most (CPU seconds on a 2-core machine, issue 55: real
#: processes, signals, training), heaviest first. They run before the others, so that the
#: two workers of ``make test`` (``-n 2 --dist loadfile``: a file stays on one worker) end
#: together, rather than one worker running a long file alone at the end while the other
#: waits (pytest-xdist >= 3.6 would otherwise order the files by their number of tests,
#: which puts these few-test files last).
SLOW_FIRST = ("test_training_lifecycle.py", "test_reproduce_worker.py", "test_readme.py",
              "test_ablations.py", "test_compile_option.py", "test_resume_epochs.py",
              "test_reproduce_runs.py", "test_train_multinode.py", "test_precision_probe.py",
              "test_training.py", "test_command_line.py", "test_experiment_scripts.py",
              "test_crop_policy.py", "test_models_fit.py", "test_preview.py",
              "test_reproduce.py", "test_distributed.py")


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):  # keep the order made below
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
    rank = {name: k for k, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest
