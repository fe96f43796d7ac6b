"""``Task``: what the training side knows about one task, in one object.

A task object says which batch keys it reads, which metrics it scores (with their units,
direction and table format), how a model's output is scored (de-normalisation, the frames
that count), what its trivial baseline is called, which columns its table and curves show,
what ``bsp-predict`` stores, which baselines ``bsp-reproduce`` findings may compare
with and what ``bsp-eval --breakdown`` keeps and bins by. ``bsp-train``, ``bsp-eval``,
``bsp-predict``, the tables, the curves and ``bsp-reproduce`` ask it
(``bsp_fast.training.tasks.get_task(name)``) instead of switching on the task's name.

This module imports neither torch nor Lightning: tables and curves read the declarations
without them; the scoring and prediction methods import torch when called.
"""
from __future__ import annotations

from ...metrics.spec import NORMALISER_FALLBACK, Metric

__all__ = ["Task"]


class Task:
    """Base of the four task objects (see the module docstring). Subclasses set the class
    attributes and implement :meth:`metric_modules`, :meth:`update_metrics` and
    :meth:`predictions`."""

    name: str = ""
    #: one line for help texts and docs
    description: str = ""
    #: keys of a ``ClipDataset`` batch dict the task reads (checked on the first batch)
    batch_keys: tuple = ("inputs", "label", "meta")
    #: what the trivial baseline (``bsp_fast.models.trivial_baseline``) predicts
    baseline: str = ""
    #: every scored metric, in table order (``loss`` is always scored too)
    metrics: tuple = ()
    #: scored and saved in metrics.json too, but not columns of the run's table
    extra_metrics: tuple = ()
    #: keys of the metrics drawn in ``curves.png``
    curves: tuple = ()
    #: inputs can be deformed (``--noise``, ``--mjp``): tables show the setting columns
    deformed_inputs: bool = False
    #: the inputs are pedestrian crops, not 2D joints: ``--noise``/``--mjp`` do not apply
    image_inputs: bool = False
    #: flips/rotations of the train clips apply (``--augment``)
    augments: bool = False
    #: unit of the de-normalised predictions ``bsp-predict`` writes (None: unitless)
    prediction_units: str | None = "pixels"
    #: ``baseline:`` names a ``bsp-reproduce`` finding may use: ``{name: (label, f)}``
    #: with ``f(initial metrics) -> value``; default: the trivial baseline itself
    finding_baselines: dict = {}
    #: what ``bsp-eval --breakdown`` keeps of each test batch: ``"logits"`` (per clip:
    #: crossing score, predicted and true label; no per-joint table), ``"joint_error_mm"``
    #: (per frame and joint: the error in mm of ``metres``, MPJPE) or ``"pose_pairs"``
    #: (per frame: ``pose_pairs``, PCK); ``""``: the task has no breakdown
    breakdown_scores: str = ""
    #: the breakdown's size bins: ``"pixel_height"`` (the ground-truth 2D joints' vertical
    #: extent; per clip: the mean over its frames) or ``"camera_distance"`` (the hips'
    #: depth along the camera's forward axis)
    breakdown_bins: str = "pixel_height"

    def __repr__(self) -> str:
        return f"<task {self.name!r}>"

    # ------------------------------------------------------------------ declarations
    @property
    def declared(self) -> tuple:
        """Every metric the task may save: ``metrics``, ``extra_metrics`` and, for 2D
        inputs, :data:`NORMALISER_FALLBACK`."""
        return self.metrics + self.extra_metrics + (() if self.image_inputs
                                                    else (NORMALISER_FALLBACK,))

    def metric(self, key: str) -> Metric:
        for m in self.declared:
            if m.key == key:
                return m
        raise ValueError(f"task {self.name!r} has no metric {key!r}; allowed: "
                         + ", ".join(m.key for m in self.declared))

    @property
    def curve_metrics(self) -> tuple:
        """The :class:`~bsp_fast.metrics.spec.Metric` of each key of ``curves``: what
        ``curves.png`` draws (:func:`bsp_fast.reporting.curves.plot_curves`)."""
        return tuple(self.metric(k) for k in self.curves)

    @property
    def units(self) -> dict:
        """``{metric key: unit}`` of metrics.json."""
        return {m.key: m.unit for m in self.declared}

    def table_columns(self) -> tuple:
        """``(header, where, key, format)``; where ``c``: a config value, ``m``: a metric."""
        cols = ((("σ (px)", "c", "noise", "g"), ("MJP", "c", "mjp", "mjp"))
                if self.deformed_inputs else ())
        return cols + tuple((m.header, "m", m.key, m.fmt) for m in self.metrics)

    @property
    def breakdown_per_clip(self) -> bool:
        """The breakdown scores whole clips (counts in clips), not frames."""
        return self.breakdown_scores == "logits"

    @property
    def breakdown_missing_joints(self) -> bool:
        """The breakdown has a realised missing-joint table: the inputs are 2D joints,
        some missing, not crops."""
        return not self.image_inputs

    def dataset_options(self, cfg: dict) -> dict:
        """``ClipDataset`` keywords of this task from a bsp-train config."""
        return {}

    # ------------------------------------------------------------------ scoring
    def scored_frames(self, model, L: int) -> slice:
        """The frames of an ``L``-frame clip that the model's per-frame outputs stand for,
        and that are scored and written; the only place that decides it."""
        return model.frame_slice(L)

    def check_batch(self, batch: dict) -> None:
        """A clear error for a batch of another task's data."""
        missing = [k for k in self.batch_keys if k not in batch]
        if missing:
            raise ValueError(f"task {self.name!r}: the batch lacks {missing} (has "
                             f"{sorted(batch)}); build the data for task {self.name!r}")

    def batch_size(self, batch: dict) -> int:
        return int(batch["label"].shape[0])

    def metric_modules(self) -> dict:
        """``{name: torchmetrics Metric}``; a module whose ``compute()`` is a dict adds
        its keys, else ``name`` is the metric's key."""
        raise NotImplementedError

    def update_metrics(self, scores, output, batch: dict, model) -> None:
        """Adds one batch's float32 ``output`` of ``model`` to ``scores``."""
        raise NotImplementedError

    def predictions(self, output, batch: dict, model) -> dict:
        """The de-normalised arrays (tensors) of one batch that ``bsp-predict`` writes,
        besides the clip identifiers (see ``bsp_fast.training.predict``)."""
        raise NotImplementedError
