"""Multi-process (DDP) loading on CPU with gloo: two ranks read disjoint shares of every
epoch, through torch.distributed directly and through Lightning's DDP strategy."""
import json
import os

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from bsp_fast.data import BSPDataModule, ClipDataset
from bsp_fast.data.testing import write_clip_file

BATCH, BLOCK = 7, 4


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("ddp") / "clips.h5"
    write_clip_file(path, clips=(84, 14, 14), clip_length=6)
    return path


def _plain_rank(rank, h5, init_file, out_dir):
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=2)
    try:
        torch.manual_seed(100 + rank)  # unseeded-like: the ranks still agree on rank 0's order
        ds = ClipDataset(h5, "train", "classification", noise=5.0)
        loader = ds.loader(batch_size=BATCH, block_size=BLOCK)
        epochs = [[b["meta"]["index"].tolist() for b in loader] for _ in range(2)]
        val = [b["meta"]["index"].tolist() for b in ClipDataset(h5, "val").loader(4)]
        with open(os.path.join(out_dir, f"{rank}.json"), "w") as f:
            json.dump({"train": epochs, "val": val, "len": len(loader)}, f)
    finally:
        dist.destroy_process_group()


def _check_shares(ranks: list, n: int) -> None:
    a, b = ranks
    assert len(a) == len(b)  # same number of steps on every rank
    flat_a, flat_b = [i for x in a for i in x], [i for x in b for i in x]
    assert not set(flat_a) & set(flat_b)  # disjoint ...
    assert sorted(flat_a + flat_b) == list(range(n))  # ... and together the whole epoch


def _runs(batch) -> int:
    return 1 + sum(1 for x, y in zip(batch, batch[1:]) if y != x + 1)


def test_two_gloo_ranks_read_disjoint_contiguous_shares(h5file, tmp_path):
    mp.start_processes(_plain_rank, args=(str(h5file), str(tmp_path / "pg"), str(tmp_path)),
                       nprocs=2, start_method="fork")
    r = [json.load(open(tmp_path / f"{k}.json")) for k in (0, 1)]
    n = len(ClipDataset(h5file, "train"))
    assert n % 2 == 0 and r[0]["len"] == r[1]["len"] == -(-n // 2 // BATCH)
    for epoch in (0, 1):
        shares = [r[0]["train"][epoch], r[1]["train"][epoch]]
        _check_shares(shares, n)
        assert all(_runs(b) <= -(-BATCH // BLOCK) + 2 for s in shares for b in s)
    assert r[0]["train"][0] != r[0]["train"][1]  # reshuffled per epoch
    _check_shares([r[0]["val"], r[1]["val"]], len(ClipDataset(h5file, "val")))


class _Probe:
    """Built lazily: Lightning is optional for the rest of this file."""

    @staticmethod
    def make(out_dir):
        import lightning.pytorch as pl

        class Probe(pl.LightningModule):
            def __init__(self):
                super().__init__()
                self.layer = torch.nn.Linear(6 * 26 * 2, 2)
                self.seen = {"train": [], "val": []}

            def on_train_epoch_start(self):
                self.seen["train"].append([])

            def training_step(self, batch, _):
                self.seen["train"][-1].append(batch["meta"]["index"].tolist())
                logits = self.layer(batch["inputs"].flatten(1))
                return torch.nn.functional.cross_entropy(logits, batch["targets"])

            def on_validation_epoch_start(self):
                self.seen["val"].append([])

            def validation_step(self, batch, _):
                self.seen["val"][-1] += batch["meta"]["index"].tolist()

            def on_train_end(self):
                with open(os.path.join(out_dir, f"pl{self.global_rank}.json"), "w") as f:
                    json.dump(self.seen, f)

            def configure_optimizers(self):
                return torch.optim.SGD(self.parameters(), lr=0.01)

        return Probe()


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_lightning_ddp_keeps_the_contiguous_sampler(h5file, tmp_path):
    pl = pytest.importorskip("lightning.pytorch")
    torch.set_num_threads(1)
    dm = BSPDataModule(h5_path=h5file, task="classification", batch_size=BATCH, block_size=BLOCK)
    trainer = pl.Trainer(accelerator="cpu", devices=2, strategy="ddp_fork", max_epochs=2,
                         logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, num_sanity_val_steps=0)
    trainer.fit(_Probe.make(str(tmp_path)), datamodule=dm)
    r = [json.load(open(tmp_path / f"pl{k}.json")) for k in (0, 1)]
    n = len(ClipDataset(h5file, "train"))
    for epoch in (0, 1):
        shares = [r[0]["train"][epoch], r[1]["train"][epoch]]
        _check_shares(shares, n)
        assert all(_runs(b) <= -(-BATCH // BLOCK) + 2 for s in shares for b in s)
    assert r[0]["train"][0] != r[0]["train"][1]
    n_val = len(ClipDataset(h5file, "val"))
    v0, v1 = r[0]["val"][-1], r[1]["val"][-1]  # sequential halves, padded to equal size
    assert len(v0) == len(v1) == -(-n_val // 2) and set(v0 + v1) == set(range(n_val))
