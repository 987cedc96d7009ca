"""Sizes that cannot fit are refused up front, in one line naming the flag or key (issue 46):
``generate -n``, ``train.batch_size``, ``make-dataset --views/--shapes`` (memory and disk), and the
checks share one owner of "available memory" (:mod:`mitsuba_platonic.runtime.budget`)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from mitsuba_platonic.runtime import budget
from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.memory_fit import batch_bytes, check_batch_fits
from cli_runner import one_line, run_cli
from tiny_shapes import TINY, tiny_run_overrides

pytestmark = pytest.mark.usefixtures("tiny_class")

GB = 10 ** 9


def _fake_memory(monkeypatch, gigabytes: float = 8.0):
    monkeypatch.setattr(budget, "available_memory", lambda: (int(gigabytes * GB), "MemAvailable in /proc/meminfo"))


def _fake_disk(monkeypatch, gigabytes: float = 50.0):
    monkeypatch.setattr(budget, "free_disk", lambda path: (int(gigabytes * GB), f"free on the disk of {path}"))


# --------------------------------------------------------------------------- train.batch_size


def test_a_batch_that_cannot_fit_is_refused_naming_the_key(tmp_path, monkeypatch):
    _fake_memory(monkeypatch)
    monkeypatch.chdir(tmp_path)
    code, _, stderr = run_cli(["train", "--quiet", "--set", "train.batch_size=1000000",
                               "--set", f"data.cache={tmp_path}/data"])
    assert code == 2
    err = one_line(stderr, "train", "error")
    assert err.startswith("platonic train: error: train.batch_size: a batch of 1000000 volumes of 32³ needs at least ")
    assert "more than the 8.0 GB available (MemAvailable in /proc/meminfo); lower train.batch_size (at most about" in err
    assert list(tmp_path.iterdir()) == []                               # no data, no run folder


def test_the_batch_estimate_grows_with_the_batch_and_a_default_batch_fits(monkeypatch):
    cfg = load_config(None)
    assert batch_bytes(cfg, 16) == 2 * batch_bytes(cfg, 8) > 0
    _fake_memory(monkeypatch)
    check_batch_fits(cfg)                                               # 8 volumes of 32³ fit in 8 GB
    monkeypatch.setattr(budget, "available_memory", lambda: (1000, "a test"))
    with pytest.raises(ConfigError, match=r"^train\.batch_size: .*not even a batch of 1 fits"):
        check_batch_fits(cfg)


# --------------------------------------------------------------------------- generate -n


def _overrides(out: Path, data: Path):
    return tiny_run_overrides(out, data)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory, tiny_class):
    root = tmp_path_factory.mktemp("run")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r"


def test_generate_refuses_more_samples_than_memory_holds(tiny_run, tmp_path, monkeypatch):
    from mitsuba_platonic.model import Model

    _fake_memory(monkeypatch)
    monkeypatch.setattr(Model, "generate", lambda *a, **k: pytest.fail("generated before the size check"))
    out = tmp_path / "gen"
    code, _, stderr = run_cli(["generate", "--run", str(tiny_run), "-n", "100000000", "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert "-n 100000000: generating 100000000 volumes of 16³ at once needs at least 1.31e+04 GB of memory" in err, err
    assert "lower -n (at most about 61035 fit)" in err and not out.exists()


def test_generate_refuses_more_samples_than_the_disk_holds(tiny_run, tmp_path, monkeypatch):
    _fake_memory(monkeypatch, 1e6)
    _fake_disk(monkeypatch, 1.0)
    out = tmp_path / "gen"
    code, _, stderr = run_cli(["generate", "--run", str(tiny_run), "-n", "100000", "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert "-n 100000: writing the .vol files of 100000 samples alone needs at least 6.56 GB of disk space" in err, err
    assert "or choose another --out" in err and not out.exists()


def test_generate_says_how_many_before_generating_and_quiet_says_nothing(tiny_run, tmp_path, monkeypatch):
    import sys
    from mitsuba_platonic.model import Model

    before = []                                                   # stderr (run_cli's) when G starts
    real = Model.generate
    monkeypatch.setattr(Model, "generate", lambda self, *a: before.append(sys.stderr.getvalue()) or real(self, *a))
    code, _, stderr = run_cli(["generate", "--run", str(tiny_run), "-n", "2", "--out", str(tmp_path / "a")])
    assert code == 0 and before[0].strip() == "generate: 0/2 sample (0%)"
    assert stderr.strip().splitlines()[-1].startswith("generate: 2/2 sample (100%)")
    code, _, stderr = run_cli(["generate", "--run", str(tiny_run), "-n", "2", "--out", str(tmp_path / "b"), "--quiet"])
    assert code == 0 and stderr == ""


def test_free_disk_reads_the_nearest_existing_folder(tmp_path):
    have, source = budget.free_disk(tmp_path / "not" / "yet")
    assert have == shutil.disk_usage(tmp_path).free or have > 0
    assert str(tmp_path) in source


# --------------------------------------------------------------------------- make-dataset


@pytest.mark.parametrize("flags, what", [
    (["--views", "100000000"], "--shapes 100 --views 100000000: holding the records of 10000000000 images needs"),
    (["--views", "1000000"], "--shapes 100 --views 1000000: holding the records of 100000000 images needs"),
    (["--shapes", "100000000"], "--shapes 100000000 --views 10: holding the records of 1000000000 images needs"),
])
def test_make_dataset_refuses_sizes_whose_records_cannot_fit(tmp_path, monkeypatch, flags, what):
    from mitsuba_platonic.data import shapes
    _fake_memory(monkeypatch)
    _fake_disk(monkeypatch, 1e9)
    monkeypatch.setattr(shapes, "generate", lambda *a: pytest.fail("a shape was made before the size check"))
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", TINY, *flags, "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "make-dataset", "error")
    assert what in err and "more than the 8.0 GB available (MemAvailable" in err, err
    assert "at most about 13333333 images (--shapes × --views) fit" in err
    assert not out.exists()


def test_make_dataset_refuses_what_the_disk_cannot_hold_for_every_class(tmp_path, monkeypatch):
    _fake_memory(monkeypatch, 1e6)
    _fake_disk(monkeypatch, 1.0)
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", f"{TINY},chair", "--views", "10000", "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "make-dataset", "error")
    assert "--shapes 100 --views 10000 for 2 classes: writing 2000000 images of 64² and their volumes needs" in err
    assert "of disk space" in err and "images per class (--shapes × --views) fit; lower them, or write elsewhere (--out)" in err
    assert not out.exists()


def test_make_dataset_renders_a_shape_in_chunks_and_says_its_size_first(tmp_path, monkeypatch, capsys, tiny_class):
    from mitsuba_platonic.data import render_collection as C
    from mitsuba_platonic.data.render_collection import CollectionSpec, make_collection

    monkeypatch.setattr(C, "VIEW_CHUNK", 2)
    batches, seen = [], []
    real = C._render_shape

    def counting(spec, vol, views, lights, *rest):
        seen.append(capsys.readouterr().err)                   # what was printed before this render
        batches.append(len(views))
        return real(spec, vol, views, lights, *rest)

    monkeypatch.setattr(C, "_render_shape", counting)
    spec = CollectionSpec(shape_class=TINY, n_shapes=2, views_per_shape=5, resolution=16)
    make_collection(tmp_path / "d", spec, progress=True)
    assert batches == [2, 2, 1, 2, 2, 1]                       # never more than a chunk at once
    assert seen[0].strip() == f"{TINY} ea: 0/10 img (0%)"         # the size, before the first render
    assert len(list((tmp_path / "d" / "images").glob("*.png"))) == 10


def test_finished_images_are_counted_from_the_records_not_every_index(tmp_path, monkeypatch, tiny_class):
    from mitsuba_platonic.data import render_collection as C
    from mitsuba_platonic.data.render_collection import CollectionSpec, make_collection

    spec = CollectionSpec(shape_class=TINY, n_shapes=2, views_per_shape=2, resolution=16)
    make_collection(tmp_path / "d", spec, progress=False)
    asked = []
    records = {C.image_id(i, k): {} for i in range(2) for k in range(2)}
    assert C._finished(records, 2, 2, lambda i, k: asked.append((i, k)) or True) == 4
    assert C._finished(records, 10 ** 8, 10 ** 8, lambda i, k: True) == 4      # instant at any size
    assert C._finished({**records, "junk": {}}, 1, 2, lambda i, k: True) == 2
    assert sorted(asked) == [(0, 0), (0, 1), (1, 0), (1, 1)]


def test_a_resumed_collection_counts_the_images_already_on_disk(tmp_path, monkeypatch):
    from mitsuba_platonic.data.render_collection import CollectionSpec, check_collection_fits, collection_needs, recorded_images

    spec = CollectionSpec(shape_class=TINY, n_shapes=10, views_per_shape=10, resolution=16)
    _, disk = collection_needs(spec)
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "records.jsonl").write_text("{}\n" * 60)
    assert recorded_images(folder) == 60 and recorded_images(tmp_path / "none") == 0
    _fake_memory(monkeypatch, 1e6)
    monkeypatch.setattr(budget, "free_disk", lambda path: (int(disk * 0.5), "a test"))
    check_collection_fits(spec, folder, done=60)                        # 40 % left: fits in half the need
    with pytest.raises(ValueError, match=r"^n_shapes 10 views_per_shape 10: writing 100 images of 16² .*"
                                         r"\(n_shapes × views_per_shape\) fit; lower them, or write elsewhere$"):
        check_collection_fits(spec, folder, done=40)
