"""The model registry: ``register`` a class under (task, name), ``create`` it by name.

A registered class's keyword-only ``__init__`` arguments (with defaults) ARE its
hyper-parameters: ``hparams_of`` reads them from the signature, ``create`` rejects unknown
ones (listing the allowed names), and the instance keeps the full set in ``hparams`` so
``create(task, name, **model.hparams)`` rebuilds the same model.
"""
from __future__ import annotations

import inspect

__all__ = ["TASKS", "register", "create", "available", "hparams_of", "model_class"]

TASKS = ("classification", "autoencoder", "lifting", "pose_estimation")
_REGISTRY: dict = {task: {} for task in TASKS}


def _check_task(task: str) -> None:
    if task not in _REGISTRY:
        raise ValueError(f"unknown task {task!r}; allowed tasks: {list(TASKS)}")


def register(task: str, name: str, description: str):
    """Class decorator: registers a :class:`BaseModel` subclass as ``(task, name)``."""
    _check_task(task)

    def deco(cls):
        if name in _REGISTRY[task]:
            raise ValueError(f"model {name!r} is already registered for task {task!r}")
        cls.task, cls.name, cls.description = task, name, description
        _REGISTRY[task][name] = cls
        return cls

    return deco


def model_class(task: str, name: str):
    """The class registered as ``(task, name)``; ValueError lists the allowed names."""
    _check_task(task)
    try:
        return _REGISTRY[task][name]
    except KeyError:
        raise ValueError(f"unknown model {name!r} for task {task!r}; allowed: "
                         f"{sorted(_REGISTRY[task])}") from None


def hparams_of(task: str, name: str) -> dict:
    """Default hyper-parameters of a registered model (its keyword-only arguments)."""
    return _defaults(model_class(task, name))


def _defaults(cls) -> dict:
    sig = inspect.signature(cls.__init__)
    return {p.name: p.default for p in sig.parameters.values()
            if p.kind is inspect.Parameter.KEYWORD_ONLY}


def create(task: str, name: str, **hparams):
    """Builds the model registered as ``(task, name)`` with the given hyper-parameters
    (defaults for the rest). Unknown task, name or hyper-parameter -> ValueError listing
    what is allowed; bad values -> ValueError from the model."""
    cls = model_class(task, name)
    allowed = _defaults(cls)
    unknown = sorted(set(hparams) - set(allowed))
    if unknown:
        raise ValueError(f"unknown hyper-parameter(s) {unknown} for {task}/{name}; allowed: "
                         f"{sorted(allowed)}")
    return cls(**hparams)


def available(task: str | None = None) -> dict:
    """``{name: one-line description}`` of the models of ``task`` (all tasks: keys are
    ``"task/name"``)."""
    if task is None:
        return {f"{t}/{n}": c.description for t in TASKS for n, c in sorted(_REGISTRY[t].items())}
    _check_task(task)
    return {n: c.description for n, c in sorted(_REGISTRY[task].items())}
