"""MixedDataModule: each source in its share of every epoch, reproducible for a seed."""
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from bsp_fast.data import ClipDataset  # noqa: E402
from bsp_fast.data.mixed import MixedBatchSampler, MixedDataModule, quotas  # noqa: E402
from bsp_fast.data.testing import write_clip_file  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SHARES = {"jaad": 0.1, "carla_bsp": 0.4, "amass": 0.5}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("mixed")
    out = {}
    for k, (name, n) in enumerate((("jaad", 12), ("carla_bsp", 40), ("amass", 90))):
        write_clip_file(root / f"{name}.h5", clips=(n, 4, 4), clip_length=4, seed=10 + k)
        out[name] = root / f"{name}.h5"
    return out


def _dm(files, **kw):
    torch.set_num_threads(1)
    sources = [dict(name=n, h5_path=str(files[n]), share=s) for n, s in SHARES.items()]
    kw.setdefault("seed", 7)
    return MixedDataModule(sources, "autoencoder", batch_size=50, epoch_size=1000, **kw)


def test_quotas_add_up_and_follow_the_shares():
    assert quotas([0.1, 0.4, 0.5], 1000).tolist() == [100, 400, 500]
    assert quotas([1, 1, 1], 10).tolist() == [4, 3, 3]
    assert quotas([0.1, 0.4, 0.5], 7).sum() == 7


def test_each_source_in_its_share_of_every_epoch(files):
    dm = _dm(files)
    sampler = dm.train_sampler()
    sizes = dict(zip(SHARES, sampler.sizes.tolist()))
    assert sizes["jaad"] < 100  # a small source: its clips repeat, each at most ceil(100/n)
    for epoch in range(3):
        idx = np.concatenate(sampler.batches(epoch))
        source = np.searchsorted(sampler.offsets, idx, side="right") - 1
        assert np.bincount(source, minlength=3).tolist() == [100, 400, 500]
        for k, n in enumerate(sizes.values()):
            uses = np.bincount(idx[source == k] - sampler.offsets[k], minlength=n)
            assert uses.max() - uses.min() <= 1  # permutations: no clip twice before all once
        # and shuffled together: the first half already holds about the shares
        half = np.bincount(source[:500], minlength=3) / 500
        assert np.all(np.abs(half - [0.1, 0.4, 0.5]) < 4 * np.sqrt(0.25 / 500))


def test_batches_hold_the_sources_clips_and_are_reproducible(files):
    dm = _dm(files, augment=False)
    batches = list(dm.train_dataloader())
    assert len(batches) == 20 and all(len(b["meta"]["source"]) == 50 for b in batches)
    total = torch.cat([b["meta"]["source"] for b in batches])
    assert torch.bincount(total, minlength=3).tolist() == [100, 400, 500]
    # a batch's rows are the sources' own clips, in the sampler's order
    b = batches[0]
    for k, name in enumerate(SHARES):
        rows = (b["meta"]["source"] == k).nonzero().flatten()
        if len(rows):
            ref = ClipDataset(files[name], "train", "autoencoder", augment=False)
            local = b["meta"]["index"][rows].tolist()
            torch.testing.assert_close(ref[local]["inputs"], b["inputs"][rows], rtol=0, atol=0)
    again = list(_dm(files, augment=False).train_dataloader())
    assert all(torch.equal(x["inputs"], y["inputs"]) for x, y in zip(batches, again))
    other = next(iter(_dm(files, augment=False, seed=8).train_dataloader()))
    assert not torch.equal(other["meta"]["source"], b["meta"]["source"])
    loader = dm.train_dataloader()
    first, second = next(iter(loader)), next(iter(loader))  # the epoch advances
    assert not torch.equal(first["meta"]["index"], second["meta"]["index"])
    assert torch.equal(first["meta"]["index"], b["meta"]["index"])


def test_val_and_test_read_every_source_in_order(files):
    dm = _dm(files)
    val = list(dm.val_dataloader())
    src = torch.cat([b["meta"]["source"] for b in val])
    assert src.tolist() == sorted(src.tolist()) and len(src) == sum(
        len(ClipDataset(f, "val", "autoencoder")) for f in files.values())


def test_config_and_bad_options(files, tmp_path):
    # the report's table with these files' clip length (from_config checks it)
    table = tmp_path / "autoencoder.yaml"
    text = (REPO / "experiments" / "mix" / "autoencoder.yaml").read_text()
    table.write_text(text.replace("clip_length: 30", "clip_length: 4"))
    dm = MixedDataModule.from_config(table, files, batch_size=50, epoch_size=1000, seed=7)
    assert [s["share"] for s in dm.sources] == [0.1, 0.4, 0.5] and dm.task == "autoencoder"
    with pytest.raises(ValueError, match=r"no clip file given for sources \['amass'\]"):
        MixedDataModule.from_config(table, {"jaad": files["jaad"],
                                            "carla_bsp": files["carla_bsp"]})
    bad = [dict(name="a", h5_path="x", share=0.5), dict(name="b", h5_path="y", share=0.4)]
    with pytest.raises(ValueError, match="shares must add up to 1"):
        MixedDataModule(bad)
    with pytest.raises(ValueError, match="task must be one of"):
        MixedDataModule([dict(name="a", h5_path="x", share=1.0)], task="lifting")
    with pytest.raises(ValueError, match="sources .* have a share but no clips"):
        MixedBatchSampler([5, 0], [0.5, 0.5], 10, 2, seed=1)


def test_lightning_fit_draws_the_shares_every_epoch(files):
    pl = pytest.importorskip("lightning.pytorch")
    from bsp_fast.training.module import AutoencoderTask

    dm = _dm(files, noise=2.0)
    dm.epoch_size, dm.batch_size = 60, 20
    seen = []

    class Record(pl.Callback):
        def on_train_batch_start(self, trainer, module, batch, batch_idx):
            seen.append((trainer.current_epoch, batch["meta"]["source"], batch["meta"]["index"]))

    module = AutoencoderTask("simple_transformer", {"num_layers": 1, "dim_feedforward": 8})
    trainer = pl.Trainer(max_epochs=2, accelerator="cpu", logger=False, callbacks=[Record()],
                         enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, limit_val_batches=1)
    trainer.fit(module, datamodule=dm)
    for epoch in (0, 1):
        src = torch.cat([s for e, s, _ in seen if e == epoch])
        assert torch.bincount(src, minlength=3).tolist() == [6, 24, 30]
    first = [i for e, _, i in seen if e == 0][0]
    assert not torch.equal(first, [i for e, _, i in seen if e == 1][0])  # epoch 1 redraws
