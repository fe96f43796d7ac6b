"""``BSPDataModule``: :class:`~bsp_fast.data.clip_data.ClipData` as a Lightning
``LightningDataModule`` (``Trainer.fit``/``test`` call its hooks; its options are saved as
hyper-parameters, so ``load_from_checkpoint`` rebuilds the same data).

It subclasses ``lightning.pytorch.LightningDataModule`` when Lightning is importable (else
``pytorch_lightning``'s, else nothing) and works as a plain class either way.
"""
from __future__ import annotations

from .clip_data import ClipData

try:
    from lightning.pytorch import LightningDataModule as _Base
    from lightning.pytorch.utilities import rank_zero_only
    LIGHTNING = True
except ImportError:  # pragma: no cover - depends on the environment
    try:
        from pytorch_lightning import LightningDataModule as _Base
        from pytorch_lightning.utilities import rank_zero_only
        LIGHTNING = True
    except ImportError:
        _Base, LIGHTNING, rank_zero_only = object, False, None

__all__ = ["BSPDataModule", "LIGHTNING"]


class BSPDataModule(ClipData, _Base):
    __doc__ = ClipData.__doc__

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if LIGHTNING:
            self.save_hyperparameters(self.options)

    def _rank_zero(self) -> bool:
        """Lightning's rank (from the launcher's environment, then the Trainer's)."""
        return getattr(rank_zero_only, "rank", 0) == 0
