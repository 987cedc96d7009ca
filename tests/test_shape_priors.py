"""The shape priors a photo run used and the collection's evidence about roundness
(mitsuba_platonic.evaluate.priors): the priors read off a config, the mirror asymmetry, the upper
asymmetry and the width / height of silhouettes with known answers, the warning where a round prior meets photos
that are not round, and that warning in ``platonic quickstart --photos``'s report and console
(tiny sizes: 16² photos, 16³ volumes, 2 steps)."""

import math

import numpy as np
import pytest
import torch
from PIL import Image

from cli_runner import run_cli
from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import priors as P
from mitsuba_platonic.files.resources import config_path

OFF = ["train.turn=0", "model.texture_turns=1", "model.offsets_behind=true"]


def _photos_config(*overrides):
    return load_config(config_path("photos"), ["data.path=photos", *overrides])


def test_photos_yaml_lists_its_round_priors_and_the_three_flags_remove_them():
    listed = {p.key: p for p in P.priors_used(_photos_config())}
    assert {k for k, p in listed.items() if p.round} == {"train.turn", "model.texture_turns", "model.offsets_behind"}
    assert listed["train.turn"].value == 1.0 and listed["model.texture_turns"].value == 4
    assert listed["model.offsets_behind"].value is False
    for key in ("train.solidity", "train.pose", "train.view_distribution", "train.colour_match", "model.photo_texture"):
        assert key in listed and not listed[key].round, key
    assert listed["train.view_distribution"].value == "band -10°…40°"
    assert all(p.assumes for p in listed.values())
    off = P.priors_used(_photos_config(*OFF))
    assert P.round_priors(off) == [] and not {"train.turn", "model.texture_turns", "model.offsets_behind"} & \
        {p.key for p in off}
    assert "train.solidity" in {p.key for p in off}                  # the others stay
    assert tuple(OFF) == P.ROUND_OFF                                  # the overrides the warning names
    plain = {p.key for p in P.priors_used(load_config(None, []))}    # the procedural default: no shape prior but D's views
    assert plain == {"train.view_distribution"}


def _ellipse(size, rx, ry, cx=None, cy=None):
    y, x = np.mgrid[0:size, 0:size] + 0.5
    cx = size / 2 if cx is None else cx
    cy = size / 2 if cy is None else cy
    return torch.tensor((((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0).astype(np.float64))


def _flag(size=32, left=True):
    """A bar 16 × 8 (rows 20–27, columns 8–23) and a block 4 × 10 on its left end (rows 10–19, columns
    8–11): the block's mirror image misses it, the bar is its own mirror image about column 15.5."""
    s = torch.zeros(size, size, dtype=torch.float64)
    s[20:28, 8:24] = 1.0
    s[10:20, 8:12] = 1.0
    return s if left else s.flip(-1)


def _brute_asymmetries(s, search=P.AXIS_SEARCH):
    """A(S) and U(S) by their definitions, one pixel at a time: the mirror line c* minimising
    Σ|S(y, x) − S(y, 2c − x)| / Σ S (the leftmost of a tie), then the same sum over the rows y < ȳ
    about c*, over their Σ S."""
    h, w = s.shape
    area = float(s.sum())
    xbar = float((s.sum(0) * torch.arange(w, dtype=torch.float64)).sum()) / area
    ybar = float((s.sum(1) * torch.arange(h, dtype=torch.float64)).sum()) / area
    centre = round(2 * xbar) / 2                                   # x̄ to the nearest half pixel
    best, upper = math.inf, None
    for k in range(-search, search + 1):
        c = centre + k / 2
        total = top = 0.0
        for y in range(h):
            for x in range(w):
                xm = 2 * c - x
                other = float(s[y, int(xm)]) if 0 <= xm < w else 0.0
                total += abs(float(s[y, x]) - other)
                top += abs(float(s[y, x]) - other) if y < ybar else 0.0
        if total / area < best:
            best, upper = total / area, top / float(s[:math.ceil(ybar)].sum())
    return best, upper


def _lathe(size=32, axis=13.5, soft=False, seed=0):
    """A body of revolution's silhouette: each row a span centred on one vertical line ``axis`` (a
    column or between two), of a random half-width per row (a vase's profile), with soft ends if ``soft``."""
    rng = np.random.default_rng(seed)
    s = torch.zeros(size, size, dtype=torch.float64)
    off = (torch.arange(size, dtype=torch.float64) - axis).abs()
    for y in range(4, size - 3):
        half = int(rng.integers(1, 9))
        s[y, off <= half - 0.5] = 1.0
        if soft:
            s[y, (off > half - 0.5) & (off <= half + 0.5)] = float(rng.uniform(0.1, 0.9))
    return s


def _animal(size=32, left=False):
    """A side view: a body 20 × 8 (rows 12–19, columns 6–25) on four legs 2 × 8 (rows 20–27,
    columns 6–7, 11–12, 19–20, 24–25), both their own mirror image about column 15.5, and a head
    5 × 4 (rows 7–11, columns 22–25) above the body's right end: 244 pixels, the centroid row
    4164 / 244 ≈ 17.07, above it the head's 20 and the body's rows 12–17, 120."""
    s = torch.zeros(size, size, dtype=torch.float64)
    s[12:20, 6:26] = 1.0
    for c in (6, 11, 19, 24):
        s[20:28, c:c + 2] = 1.0
    s[7:12, 22:26] = 1.0
    return s.flip(-1) if left else s


def test_mirror_asymmetry_of_symmetric_and_lopsided_silhouettes():
    sym = torch.stack([_ellipse(32, 10, 6), _ellipse(32, 5, 12, cx=11.5), _ellipse(32, 7, 7, cx=20, cy=12)])
    assert torch.equal(P.mirror_asymmetry(sym), torch.zeros(3, dtype=torch.float64))  # off-centre too
    # the flag: only the block's 40 pixels and their 40 mirrored ones differ, of 168
    a = P.mirror_asymmetry(torch.stack([_flag(), _flag(left=False)]))
    assert a.tolist() == pytest.approx([80 / 168, 80 / 168], abs=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(3):                                            # soft random masks against the definition
        s = torch.tensor(rng.uniform(0, 1, (12, 12)) * (rng.uniform(0, 1, (12, 12)) > 0.5))
        assert float(P.mirror_asymmetry(s)[0]) == pytest.approx(_brute_asymmetries(s)[0], abs=1e-12)
    assert math.isnan(float(P.mirror_asymmetry(torch.zeros(8, 8))[0]))
    with pytest.raises(UserError, match="values in"):
        P.mirror_asymmetry(torch.full((8, 8), 2.0))
    with pytest.raises(UserError, match="masks"):
        P.mirror_asymmetry(torch.zeros(8))


def test_upper_asymmetry_of_a_lathe_a_flag_and_an_animal():
    # a body of revolution: every row centred on its axis, whatever its profile, hard or soft edged
    lathes = torch.stack([_lathe(), _lathe(axis=17.0, seed=1), _lathe(soft=True, seed=2),
                          _lathe(axis=16.0, soft=True, seed=3)])
    assert torch.equal(P.upper_asymmetry(lathes), torch.zeros(4, dtype=torch.float64))
    assert torch.equal(P.mirror_asymmetry(lathes), torch.zeros(4, dtype=torch.float64))
    # the flag (centroid row 3588 / 168 ≈ 21.36): above it the block's 40 and the bar's rows 20–21, 32;
    # about the bar's centre the block's 40 and their 40 mirrored differ
    assert P.upper_asymmetry(torch.stack([_flag(), _flag(left=False)])).tolist() == \
        pytest.approx([80 / 72, 80 / 72], abs=1e-12)
    # the animal: body and legs fix the line at column 15.5; the head's 20 pixels and their 20 mirrored
    # are 40 / 244 of the whole (A), 40 / 140 of the part above the centroid row (U)
    animal = torch.stack([_animal(), _animal(left=True)])
    assert P.mirror_asymmetry(animal).tolist() == pytest.approx([40 / 244] * 2, abs=1e-12)
    assert P.upper_asymmetry(animal).tolist() == pytest.approx([40 / 140] * 2, abs=1e-12)
    assert 40 / 140 > P.UPPER_THRESHOLD                            # not round, though A is low
    rng = np.random.default_rng(0)
    for _ in range(4):                                            # soft random masks against the definition
        s = torch.tensor(rng.uniform(0, 1, (12, 12)) * (rng.uniform(0, 1, (12, 12)) > 0.5))
        assert float(P.upper_asymmetry(s)[0]) == pytest.approx(_brute_asymmetries(s)[1], abs=1e-12)
    one_row = torch.zeros(8, 8, dtype=torch.float64)               # no row above the centroid row
    one_row[3, 2:6] = 1.0
    u = P.upper_asymmetry(torch.stack([torch.zeros(8, 8, dtype=torch.float64), one_row]))
    assert math.isnan(float(u[0])) and math.isnan(float(u[1]))
    assert float(P.mirror_asymmetry(one_row)[0]) == 0.0
    with pytest.raises(UserError, match="values in"):
        P.upper_asymmetry(torch.full((8, 8), -0.5))


def test_aspect_of_ellipses_and_the_spread_of_a_set():
    # a filled ellipse of semi-axes a (across), b (down): σx / σy = a / b
    for a, b in ((12, 6), (6, 12), (9, 9)):
        assert float(P.aspect(_ellipse(40, a, b))[0]) == pytest.approx(a / b, rel=0.03)
    constant = torch.stack([_ellipse(40, 0.6 * b, b) for b in (8, 11, 14, 17)])          # one aspect, four sizes
    ratios = [0.4, 0.7, 1.0, 1.3, 1.6]
    varying = torch.stack([_ellipse(40, 10 * r, 10) for r in ratios])                     # aspects 0.4 … 1.6
    e_const, e_var = P.round_evidence(constant), P.round_evidence(varying)
    assert e_const.aspect_spread < 0.02
    expected = float(np.std(np.log(ratios)))
    assert e_var.aspect_spread == pytest.approx(expected, abs=0.03) and expected > 0.4
    assert e_const.asymmetry == 0.0 and e_var.asymmetry == 0.0     # ellipses are their own mirror images
    assert e_const.upper_asymmetry == 0.0 and e_var.upper_asymmetry == 0.0


def test_the_warning_fires_for_a_round_prior_on_lopsided_photos_only():
    photos = P.priors_used(_photos_config())
    off = P.priors_used(_photos_config(*OFF))
    lopsided = P.round_evidence(torch.stack([_animal(left=i % 2 == 0) for i in range(10)])[:, None])
    rounded = P.round_evidence(torch.stack([_ellipse(32, 6 + i, 9) for i in range(10)])[:, None])
    few = P.round_evidence(torch.stack([_animal() for _ in range(P.MIN_PHOTOS - 1)]))
    assert lopsided.not_round and lopsided.photos == 10
    assert lopsided.upper_asymmetry == pytest.approx(40 / 140) and lopsided.asymmetry == pytest.approx(40 / 244)
    assert not rounded.not_round and not few.not_round and not few.decided
    # the median, not the mean: 4 lopsided of 9 (U 40 / 140) and 5 lathes (0) is round
    mixed = P.round_evidence(torch.stack([_animal()] * 4 + [_lathe(seed=i) for i in range(5)]))
    assert mixed.upper_asymmetry == 0.0 and mixed.decided and not mixed.not_round
    (line,) = P.contradictions(photos, lopsided)
    assert line.startswith(P.WARNING) and "0.29" in line and "0.25" in line and "10 photos" in line
    assert "median" in line
    assert "--set train.turn=0 --set model.texture_turns=1 --set model.offsets_behind=true" in line
    assert P.contradictions(off, lopsided) == [] and P.contradictions(photos, rounded) == []
    assert P.contradictions(photos, few) == []
    text = "\n".join(P.priors_markdown(photos, lopsided))
    assert text.startswith("## Shape priors this run used") and "| `train.turn` | 1 |" in text
    assert "upper mirror asymmetry 0.29" in text and "mirror asymmetry, 0.16 (mean)" in text
    assert "not round" in text and line in text
    assert P.warning_lines(text) == [line.replace("**", "").replace("`", "")]
    assert P.warning_lines("\n".join(P.priors_markdown(photos, rounded))) == []
    results = P.priors_results(photos, lopsided)
    assert results["warnings"] == [line]
    assert results["round_evidence"]["upper_asymmetry"] == pytest.approx(40 / 140)
    assert results["round_evidence"]["not_round"] is True and results["round_evidence"]["threshold"] == 0.25
    empty = P.round_evidence(torch.zeros(0, 16, 16))
    assert empty.photos == 0 and empty.upper_asymmetry is None and not empty.decided
    assert "No silhouette in the photos to measure." in P.priors_markdown(photos, empty)


def _lopsided_photo(seed, size=24):
    """An RGBA photo of a bar with a block at one end (a side view of a chair, roughly), random colour."""
    rng = np.random.default_rng(seed)
    arr = np.zeros((size, size, 4), np.uint8)
    w, h = rng.integers(14, 19), rng.integers(4, 6)
    top = size - 4 - h
    arr[top:top + h, 3:3 + w, :3] = rng.integers(30, 230, 3)
    arr[top:top + h, 3:3 + w, 3] = 255
    bw, bh = rng.integers(3, 5), rng.integers(8, 12)
    arr[top - bh:top, 3:3 + bw, :3] = rng.integers(30, 230, 3)
    arr[top - bh:top, 3:3 + bw, 3] = 255
    if seed % 2:
        arr = arr[:, ::-1].copy()
    arr[0, 0, :3] = seed                                        # distinct bytes per seed (alpha 0 there)
    return Image.fromarray(arr, "RGBA")


TINY = ["model.resolution=16", "model.width=4", "model.latent=8", "model.critic_width=4", "train.batch_size=2",
        "run.steps=2", "run.sample_every=2", "run.checkpoint_every=2", "run.threads=1", "data.split=0.6"]


def test_quickstart_warns_where_its_round_priors_meet_lopsided_photos(tmp_path):
    """The round photos' side (ellipses: no warning) is test_photo_quickstart's; the priors off, with no
    warning, is test_the_warning_fires_for_a_round_prior_on_lopsided_photos_only's."""
    folder = tmp_path / "lopsided"
    folder.mkdir()
    for i in range(10):
        _lopsided_photo(i).save(folder / f"p{i}.png")
    flags = sum((["--set", s] for s in TINY), [])
    code, stdout, err = run_cli(["quickstart", "--photos", str(folder), "--out", str(tmp_path / "q"), "--quiet"]
                                + flags)
    assert code == 0, err
    report = (tmp_path / "q" / "report.md").read_text()
    assert "## Shape priors this run used" in report and "| `train.turn` | 1 |" in report
    (warning,) = [line for line in report.splitlines() if line.startswith(P.WARNING)]
    assert "10 photos" in warning and "--set train.turn=0" in warning
    assert stdout.rstrip().splitlines()[-1] == "platonic quickstart: " + P.warning_lines(warning)[0]
    evaluation = (tmp_path / "q" / "evaluation" / "report.md").read_text()   # platonic evaluate's report too
    assert "### Shape priors this run used" in evaluation and warning in evaluation
