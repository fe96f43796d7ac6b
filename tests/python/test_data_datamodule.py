"""BSPDataModule: existing files, option checks, Lightning, and conversion on first use."""
import importlib

import numpy as np
import pytest
import torch

from bsp_fast.data import BSPDataModule, ClipDataset
from bsp_fast.data.testing import write_clip_file


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("dm") / "clips.h5"
    write_clip_file(path, clips=(64, 16, 16), clip_length=6)
    return path


def test_existing_file_setup_and_loaders(h5file):
    dm = BSPDataModule(h5_path=h5file, task="autoencoder", noise=5.0, mjp=0.2944, batch_size=16,
                       balance=True)
    dm.prepare_data()  # the file exists: nothing to convert
    dm.setup("fit")
    assert set(dm.datasets) == {"train", "val"} and dm.clip_length == 6
    assert dm.datasets["train"].augment and not dm.datasets["val"].augment
    n0, n1 = dm.datasets["train"].class_counts
    assert n0 == n1 > 0
    batch = next(iter(dm.train_dataloader()))
    assert batch["inputs"].shape == (16, 6, 26, 2) and batch["targets"].shape == (16, 6, 26, 2)
    seen = [i for b in dm.test_dataloader() for i in b["meta"]["index"].tolist()]
    assert seen == list(range(len(dm.datasets["test"])))  # eval order is sequential


def test_option_checks(h5file, tmp_path):
    with pytest.raises(ValueError, match="task must be one of"):
        BSPDataModule(h5_path=h5file, task="segmentation")
    with pytest.raises(ValueError, match="needs dataset_dir"):
        BSPDataModule()
    dm = BSPDataModule(h5_path=h5file, clip_length=16)
    with pytest.raises(ValueError, match="converted with other options: --clip-length 16 vs 6 "
                                         "in the file"):
        dm.setup()
    with pytest.raises(FileNotFoundError, match="no dataset_dir"):
        BSPDataModule(h5_path=tmp_path / "missing.h5").prepare_data()


def test_messages_only_on_lightnings_rank_zero(h5file, monkeypatch, capsys):
    from lightning.pytorch.utilities import rank_zero_only

    dm = BSPDataModule(h5_path=h5file, verbose=True)
    monkeypatch.setenv("RANK", "3")  # read by Lightning when a launcher starts it, not here
    dm._say("first")
    monkeypatch.setattr(rank_zero_only, "rank", 1)  # as a Trainer sets it on rank 1
    dm._say("second")
    assert capsys.readouterr().err == "bsp_fast.data: first\n"


def test_benchmark_constructor_uses_the_report_setup(tmp_path):
    (tmp_path / "data.csv").write_text("")
    dm = BSPDataModule.benchmark(tmp_path, batch_size=32)
    assert (dm.clip_length, dm.clip_offset, dm.benchmark_windows, dm.balance) == (16, 6, True, True)
    assert dm.h5_path.parent == tmp_path / "bsp_fast-cache"
    assert dm.h5_path.name.startswith("clips-L16-o6-benchmark-balanced-")
    assert BSPDataModule.benchmark(tmp_path, clip_offset=8).clip_offset == 8


@pytest.mark.filterwarnings("ignore:You passed in a `val_dataloader`")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.filterwarnings("ignore::FutureWarning")
def test_lightning_fit_runs_and_reshuffles_per_epoch(h5file):
    pl = pytest.importorskip("lightning.pytorch")

    class Probe(pl.LightningModule):
        def __init__(self):
            super().__init__()
            self.layer = torch.nn.Linear(6 * 26 * 2, 2)
            self.orders = []

        def on_train_epoch_start(self):
            self.orders.append([])

        def training_step(self, batch, _):
            self.orders[-1] += batch["meta"]["index"].tolist()
            logits = self.layer(batch["inputs"].flatten(1))
            return torch.nn.functional.cross_entropy(logits, batch["targets"])

        def configure_optimizers(self):
            return torch.optim.SGD(self.parameters(), lr=0.01)

    dm = BSPDataModule(h5_path=h5file, task="classification", batch_size=16, sampler_seed=1)
    probe = Probe()
    trainer = pl.Trainer(max_epochs=2, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False,
                         num_sanity_val_steps=0, limit_val_batches=0)
    trainer.fit(probe, datamodule=dm)
    n = len(dm.datasets["train"])
    assert [sorted(o) for o in probe.orders] == [list(range(n))] * 2
    sampler = dm.train_dataloader().sampler
    assert probe.orders == [sampler.order(0).tolist(), sampler.order(1).tolist()]


def _synth_pipeline():
    """bsp-synth (a failure to import it is a test failure, not a skip)."""
    return importlib.import_module("bsp_fast.synth")


@pytest.fixture(scope="module")
def synth_sample(tmp_path_factory):
    synth = _synth_pipeline()
    data = tmp_path_factory.mktemp("synth") / "sample"
    # the sample preset cut to 12 clips at 320x120 (20 at 640x240): the same path, both
    # classes in every split, a sixth of the pixels to draw and convert
    synth.generate(data, preset="sample", clips=12, size="320x120", progress=False)
    return data


def test_datamodule_converts_a_synth_sample_on_first_use(synth_sample):
    dm = BSPDataModule(synth_sample, task="lifting", clip_length=8, batch_size=8)
    assert not dm.h5_path.exists()
    dm.prepare_data()
    assert dm.h5_path.is_file() and dm.conversion_report is not None
    dm.setup()
    for split in ("train", "val", "test"):
        ds = dm.datasets[split]
        assert isinstance(ds, ClipDataset) and ds.clip_length == 8 and len(ds) > 0
    batch = next(iter(dm.val_dataloader()))
    t = batch["targets"].numpy()
    np.testing.assert_allclose(t[:, :, 1], 0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(t[:, :, 8], axis=-1), 1, rtol=1e-4)
    mtime = dm.h5_path.stat().st_mtime_ns
    again = BSPDataModule(synth_sample, task="classification", clip_length=8)
    again.setup()  # second use: the cached file is reused, not reconverted
    assert again.h5_path == dm.h5_path and dm.h5_path.stat().st_mtime_ns == mtime
    assert again.conversion_report is None


def test_pose_estimation_on_media_converted_from_a_synth_sample(synth_sample):
    dm = BSPDataModule(synth_sample, task="pose_estimation", clip_length=8, batch_size=4,
                       convert_options={"crop_size": 32},
                       dataset_options={"with_mask": True, "with_pixels": True})
    assert dm.h5_path.name.startswith("clips-L8-o8-media-")
    dm.setup("fit")
    ds = dm.datasets["train"]
    batch = next(iter(dm.train_dataloader()))
    assert batch["inputs"].shape == (4, 8, 3, 32, 32) and batch["inputs"].dtype == torch.uint8
    t, vis = batch["targets"].numpy(), batch["visible"].numpy()
    assert vis.mean() > 0.5  # most joints of a walking pedestrian are visible
    inside = (t >= -1) & (t <= 33)
    assert inside[vis].all()  # visible joints lie in their crop
    # the crop mask shows the pedestrian (tag 4) at most visible joints
    mask = batch["mask"].numpy()
    b, f, j = np.nonzero(vis)
    u = np.clip(t[b, f, j, 0].astype(int), 0, 31)
    v = np.clip(t[b, f, j, 1].astype(int), 0, 31)
    assert (mask[b, f, v, u] == 4).mean() > 0.5
    box = batch["crop_box"].numpy()
    px = batch["pixels"].numpy()
    size = box[..., None, 2:] - box[..., None, :2]
    np.testing.assert_allclose((px - box[..., None, :2]) * 32 / size, t, rtol=1e-5, atol=1e-3)
    assert len(ds) > 0


def test_two_workers_over_a_converted_synth_sample_yield_each_clip_once(synth_sample, tmp_path):
    h5 = tmp_path / "clips.h5"
    dm = BSPDataModule(synth_sample, h5, task="autoencoder", clip_length=10, clip_offset=5,
                       noise=5.0, mjp=0.2944, batch_size=5, num_workers=2)
    dm.setup("fit")
    n = len(dm.datasets["train"])
    loader = dm.train_dataloader()
    for _ in range(2):
        seen = []
        for b in loader:
            seen += b["meta"]["index"].tolist()
            assert b["inputs"].shape[1:] == (10, 26, 2)
            assert torch.isfinite(b["inputs"]).all() and torch.isfinite(b["targets"]).all()
        assert sorted(seen) == list(range(n))


def test_plain_class_without_lightning(h5file, monkeypatch):
    import sys

    import bsp_fast.data.datamodule as dmod

    for name in ("lightning", "lightning.pytorch", "pytorch_lightning"):
        monkeypatch.setitem(sys.modules, name, None)  # makes the import fail
    try:
        plain = importlib.reload(dmod)
        assert plain.LIGHTNING is False and plain.BSPDataModule.__mro__[2] is object
        dm = plain.BSPDataModule(h5_path=h5file, task="lifting", batch_size=8)
        dm.prepare_data()
        dm.setup()
        batch = next(iter(dm.test_dataloader()))
        assert batch["targets"].shape == (8, 6, 26, 3)
    finally:
        monkeypatch.undo()
        importlib.reload(dmod)


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_checkpoint_round_trip_rebuilds_the_same_data(h5file, tmp_path):
    pl = pytest.importorskip("lightning.pytorch")

    class Lift(pl.LightningModule):
        def __init__(self):
            super().__init__()
            self.layer = torch.nn.Linear(2, 3)

        def training_step(self, batch, _):
            return (self.layer(batch["inputs"]) - batch["targets"]).square().mean()

        def configure_optimizers(self):
            return torch.optim.SGD(self.parameters(), lr=0.01)

    options = dict(lifting_target="camera", with_pixels=True)
    dm = BSPDataModule(h5_path=h5file, task="lifting", batch_size=8, noise=2.0, mjp=0.1,
                       seed=4, sampler_seed=5, block_size=8, dataset_options=options,
                       convert_options={"label": "any:0.5", "seed": 3})
    trainer = pl.Trainer(max_epochs=1, limit_train_batches=2, logger=False,
                         enable_progress_bar=False, enable_model_summary=False,
                         default_root_dir=tmp_path, num_sanity_val_steps=0, limit_val_batches=0)
    trainer.fit(Lift(), datamodule=dm)
    ckpt = next(tmp_path.rglob("*.ckpt"))
    back = BSPDataModule.load_from_checkpoint(ckpt)
    for name in ("task", "batch_size", "noise", "mjp", "seed", "sampler_seed", "block_size",
                 "h5_path"):
        assert getattr(back, name) == getattr(dm, name), name
    assert back.convert_options == {"label": "any:0.5", "seed": 3, "media": False}
    assert back.dataset_options == {"lifting_target": "camera", "with_pixels": True}
    back.setup("fit")
    assert back.datasets["train"].lifting_target == "camera"
    a = dm.datasets["val"][[0, 1]]
    b = back.datasets["val"][[0, 1]]
    assert torch.equal(a["targets_m"], b["targets_m"]) and torch.equal(a["inputs"], b["inputs"])
    # callables (transforms) cannot be saved: left out of the hyper-parameters, not an error
    with_fn = BSPDataModule(h5_path=h5file, dataset_options={"transform": abs, "seed": 1})
    assert with_fn.hparams["dataset_options"] == {"seed": 1}
