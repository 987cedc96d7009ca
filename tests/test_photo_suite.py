"""The photo suite's collections and table (benchmarks/photo_suite.py): the specs it renders and the columns
it prints, without rendering or training anything."""

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from mitsuba_platonic.data.render_collection import CollectionSpec

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import photo_suite as S  # noqa: E402


def test_the_round_collections_keep_the_spec_they_were_rendered_with():
    """pt-mushroom and pt-tree are reused where already rendered: their specs are those of before."""
    for name, cls in (("pt-mushroom", "mushroom"), ("pt-tree", "tree")):
        assert S.suite_spec(name) == CollectionSpec(cls, n_shapes=62, views_per_shape=1, resolution=64,
                                                    formation="physical", views="band", elevation=(-10.0, 40.0),
                                                    seed=0)


def _azimuths(spec):
    v = torch.stack([spec.view(i, 0) for i in range(spec.n_shapes)])
    return np.degrees(np.arctan2(v[:, 0].numpy(), v[:, 2].numpy()))


@pytest.mark.parametrize("name", ["pt-chair", "pt-airplane", "pt-animal", "pt-animal-sides"])
def test_the_new_collections_are_not_round_classes_at_their_measured_settings(name):
    spec = S.suite_spec(name).validate()
    assert spec.shape_class == {"pt-chair": "chair", "pt-airplane": "airplane"}.get(name, "animal")
    assert (spec.n_shapes, spec.resolution, spec.spp, spec.formation) == (62, 48, 16, "physical")
    assert S.suite_spec(name, shapes=5, resolution=32).resolution == 32
    az = _azimuths(spec)
    near_side = np.minimum(np.abs(az - 90.0), np.abs(az + 90.0))
    if name == "pt-animal-sides":
        assert spec.views == "sides" and near_side.max() <= 30.0 + 1e-3
        assert 15 < int((az > 0).sum()) < 47                       # both sides
    else:
        assert spec.views == "band" and near_side.max() > 60.0     # end-on views too: uniform azimuths
    assert S.suite_spec("pt-animal-sides").shape_seed(3) == S.suite_spec("pt-animal").shape_seed(3)  # same animals


def test_the_table_has_the_width_ratio_columns():
    row = {k: 0.5 for k, _, _ in S.JUDGE + S.TRUTH}
    row.update(truth_width_ratio=0.98, truth_width_ratio_truth=0.41, truth_width_ratio_error=0.57)
    lines = S.table("pt-animal-sides", "photos", {0: row, 1: dict(row, truth_width_ratio=0.9)}, truth=True)
    header = [c.strip() for c in lines[2].split("|")]
    assert header[-4:-1] == ["width ±90°/0°", "truth's", "abs. Δ width"]
    cells = [c.strip() for c in lines[4].split("|")]
    assert cells[-4:-1] == ["0.98", "0.41", "0.57"]
    mean = [c.strip() for c in lines[-1].split("|")]
    assert mean[-4] == "0.94 (0.08)"
