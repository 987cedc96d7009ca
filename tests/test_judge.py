"""The judge of novel views without ground truth (evaluate/judge.py, evaluate/image_stats.py):
known cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import image_stats as S
from mitsuba_platonic.evaluate import judge as J
from mitsuba_platonic.evaluate.protocol import billboard
from mitsuba_platonic.render import RenderSettings, render
from mitsuba_platonic.views import front_view
from mitsuba_platonic.volume import voxel_centres

N = 16
SETTINGS = RenderSettings.for_call("closed_form", "ea")


def spheroids(count: int, seed: int) -> torch.Tensor:
    """``(count, 4, N, N, N)``: spheroids symmetric about the vertical axis (r_x = r_z), each in one
    random colour, so every turntable view of one is the same picture."""
    rng = np.random.default_rng(seed)
    p = voxel_centres(N)
    out = []
    for _ in range(count):
        rxz, ry = rng.uniform(0.35, 0.75), rng.uniform(0.35, 0.85)
        r = torch.tensor([rxz, ry, rxz])
        density = torch.sigmoid(-(((p / r) ** 2).sum(-1).sqrt() - 1.0) * N / 2.0)
        colour = torch.tensor(rng.uniform(0.1, 0.9, size=3), dtype=torch.float32)
        out.append(torch.cat([colour[:, None, None, None].expand(3, N, N, N), density[None].float()]))
    return torch.stack(out)


def photos_of(volumes: torch.Tensor) -> torch.Tensor:
    return render(volumes, front_view(len(volumes)), model="ea", backend="closed_form").clamp(0, 1)


def lookup(volumes: torch.Tensor, photos: torch.Tensor):
    """A perfect reconstruction: each photo's own spheroid (found by the nearest photo)."""
    def reconstruct(x: torch.Tensor) -> torch.Tensor:
        d = ((x[:, None] - photos[None]) ** 2).flatten(2).sum(-1)
        return volumes[d.argmin(1)]
    return reconstruct


def billboards(x: torch.Tensor) -> torch.Tensor:
    """The photo extruded through the depth of the cube (evaluate.protocol.billboard)."""
    return torch.stack([billboard(i) for i in x])


def cards(x: torch.Tensor) -> torch.Tensor:
    """A painted card: one depth layer at the front, density = the photo's opacity, colour = its
    own colour (RGB / α); renders as the photo at the input view."""
    out = torch.zeros(len(x), 4, N, N, N)
    alpha = x[:, 3]
    out[:, :3, 0] = (x[:, :3] / alpha.clamp_min(1e-6)[:, None]).clamp(0, 1)
    out[:, 3, 0] = alpha
    return out


@pytest.fixture(scope="module")
def data():
    train_v, test_v = spheroids(32, seed=1), spheroids(12, seed=2)
    return train_v, photos_of(train_v), test_v, photos_of(test_v)


# -- the two-sample test -----------------------------------------------------------------------

def test_a_render_set_against_itself_is_indistinguishable(data):
    _, train, _, test = data
    out = J.two_sample_test(train, train, test, {"input": test, "side": test}, steps=50, repeats=2)
    assert out["accuracy"] == {"input": 0.5, "side": 0.5}
    assert out["auc"] == {"input": 0.5, "side": 0.5}              # each pair ranked both ways, ties halved
    assert out["train_accuracy"] == 0.5


def test_each_critic_learns_from_its_own_render_set(data):
    """With one render set per critic, critic r learns from the r-th: a critic whose set is the
    photos themselves cannot tell them apart (training accuracy exactly ½), one whose set is grey
    can (≥ 0.85), and the mean over the two lies between. A count of sets other than the critics'
    is refused."""
    _, train, _, test = data
    grey = train.clone()
    grey[:, :3] = grey[:, :3].mean(1, keepdim=True)
    alike = J.two_sample_test(train, [train], test, {"input": test}, steps=300, repeats=1)
    apart = J.two_sample_test(train, [grey], test, {"input": test}, steps=300, repeats=1)
    both = J.two_sample_test(train, [train, grey], test, {"input": test}, steps=300, repeats=2)
    assert alike["train_accuracy"] == 0.5 and apart["train_accuracy"] >= 0.85, (alike, apart)
    assert both["train_accuracy"] == pytest.approx(0.5 * (alike["train_accuracy"] + apart["train_accuracy"]),
                                                   abs=0.1)
    with pytest.raises(UserError, match="3 render sets for 2 critics"):
        J.two_sample_test(train, [train, train, grey], test, {"input": test}, steps=1, repeats=2)


def test_a_perfect_reconstruction_is_near_chance_in_every_band(data):
    train_v, train, test_v, test = data
    j = J.judge(lookup(torch.cat([train_v, test_v]), torch.cat([train, test])), train, test, SETTINGS,
                steps=150, repeats=2)
    for band, acc in j.c2st["accuracy"].items():
        assert 0.3 <= acc <= 0.7, (band, acc)


def test_billboards_are_told_apart_from_the_side_but_not_at_the_input_view(data):
    _, train, _, test = data
    j = J.judge(billboards, train, test, SETTINGS, steps=300, repeats=2)
    acc = j.c2st["accuracy"]
    # edge-on a card is a sliver; at 60–75° it is a narrower object, which a narrow spheroid can also be
    assert acc["side"] >= 0.85, acc
    assert acc["input"] <= 0.7, acc                             # the billboard is its photo there
    # (from the back a billboard shows its photo mirrored, and mirrored photos train as photos: no claim)
    assert j.c2st["train_accuracy"] >= 0.8                      # the critic learnt what a billboard looks like


def test_cards_are_told_apart_from_the_side_and_vanish_there(data):
    _, train, _, test = data
    j = J.judge(cards, train, test, SETTINGS, steps=300, repeats=2)
    acc = j.c2st["accuracy"]
    assert acc["side"] >= 0.9 and acc["input"] <= 0.7, acc
    assert j.c2st["auc"]["side"] >= 0.9 and j.c2st["auc"]["input"] <= 0.7, j.c2st["auc"]
    assert j.means["coverage_side"] < 0.3                       # edge-on, one voxel thick
    assert j.means["coverage_back"] == pytest.approx(1.0, abs=0.1)


def test_an_empty_reconstruction_is_told_apart_everywhere(data):
    _, train, _, test = data
    j = J.judge(lambda x: torch.zeros(len(x), 4, N, N, N), train, test, SETTINGS, steps=150, repeats=1)
    assert min(j.c2st["accuracy"].values()) >= 0.95, j.c2st["accuracy"]
    assert j.c2st["photo_pass"] >= 0.95                          # unseen photos of the class pass as photos
    assert min(j.c2st["auc"].values()) >= 0.95, j.c2st["auc"]
    assert j.means["coverage_side"] is None and j.means["roughness_side"] is None


def test_the_turntable_turns_about_the_objects_vertical_axis_at_the_input_cameras_elevation():
    """A vertical rod (x = 0.3, z = 0) seen from 30° above: given upright with its elevation, the
    judge's side views show it upright (one column of pixels, the same in every covered row), and
    at 0° its view is the input camera's (the rod tilted into that camera's frame, from the
    front). Given the same rod tilted into the input camera's frame, with no elevation, the
    turntable turns about that camera's vertical axis and the side view shows it leaning (its
    column moves by rows). Elevations are checked: one per volume."""
    from mitsuba_platonic.render.pytorch.closed_form import tilt
    p = voxel_centres(N)
    rod = torch.exp(-((p[..., 0] - 0.3) ** 2 + p[..., 2] ** 2) / (2 * 0.08 ** 2)) * (p[..., 1].abs() < 0.7)
    volume = torch.cat([torch.full((3, N, N, N), 0.5), rod[None].float()])[None].expand(2, -1, -1, -1, -1)
    θ = torch.full((2,), 30.0)
    leaning = tilt(volume, torch.deg2rad(θ)).clamp(0, 1)
    photos = photos_of(leaning)

    def side(answer):
        j = J.judge(lambda x: answer, photos, photos, SETTINGS, steps=1, repeats=1, n_examples=1)
        views = j.examples[0][2]                                  # at FIGURE_AZIMUTHS
        return {a: views[i] for i, a in enumerate(J.FIGURE_AZIMUTHS)}

    def columns(image):
        """The alpha-weighted mean column of each row the rod covers."""
        a = image[3]
        rows = a.sum(1) > 0.5
        return (a[rows] * torch.arange(N)).sum(1) / a[rows].sum(1)

    upright = side((volume, θ))
    assert torch.allclose(upright[0.0], photos[0], atol=0.05)
    assert float(columns(upright[90.0]).std()) < 0.05            # upright: the same column in every row
    tilted = side(leaning)
    assert float(columns(tilted[90.0]).max() - columns(tilted[90.0]).min()) > 2.0    # leaning by 30°
    with pytest.raises(UserError, match=r"one finite elevation per volume expected, shape \(2,\)"):
        side((volume, torch.zeros(3)))


def test_a_critic_whose_unseen_photos_look_like_renders_calls_them_renders_and_the_report_says_so(data):
    """The critic learns the training photos (the spheroids as they are) against 'renders' that are
    the same spheroids in grey. Held-out 'photos' that are grey too (photos the critic never learnt
    to call photos) are called renders (p ≤ 0.2; the true held-out photos p ≥ 0.75), and the report
    flags that row; against renders of their own kind they rank alike (AUC exactly 0.5, a set
    against itself), where the true held-out photos rank above them (AUC ≥ 0.9)."""
    from mitsuba_platonic.evaluate.photos import PhotoSection, judge_markdown
    _, train, _, test = data

    def grey(x):
        y = x.clone()
        y[:, :3] = y[:, :3].mean(1, keepdim=True)                # grey: the critic's cue is colour
        return y

    renders = {"input": grey(test)}
    out = J.two_sample_test(train, grey(train), grey(test), renders, steps=300, repeats=2)
    well = J.two_sample_test(train, grey(train), test, renders, steps=300, repeats=2)
    assert out["photo_pass"] <= 0.2 and well["photo_pass"] >= 0.75, (out, well)
    assert out["auc"]["input"] == 0.5 and well["auc"]["input"] >= 0.9, (out["auc"], well["auc"])
    section = PhotoSection("r", "photos", SETTINGS, [], judgements=[("memorised", J.Judgement(out)),
                                                                    ("learnt", J.Judgement(well))])
    text = "\n".join(judge_markdown(section))
    assert "**memorised: the critic calls" in text and "**learnt: the critic calls" not in text
    assert "| memorised | " in text and f"| {out['photo_pass']:.2f} | {len(test)} |" in text


def test_the_critic_is_seeded_and_leaves_the_global_generator_alone(data):
    _, train, _, test = data
    upside_down = train.flip(-2)
    state = torch.get_rng_state()
    a = J.two_sample_test(train, upside_down, test, {"x": test.flip(-2)}, seed=3, steps=20, repeats=1)
    assert torch.equal(state, torch.get_rng_state())
    b = J.two_sample_test(train, upside_down, test, {"x": test.flip(-2)}, seed=3, steps=20, repeats=1)
    assert a == b


def test_the_two_sample_test_refuses_what_it_cannot_use(data):
    _, train, _, test = data
    with pytest.raises(UserError, match="test_renders"):
        J.two_sample_test(train, train, test, {})
    with pytest.raises(UserError, match="shape"):
        J.two_sample_test(train, train[:, :, :8, :8], test, {"x": test})
    with pytest.raises(UserError, match="NaN"):
        J.two_sample_test(train, train * float("nan"), test, {"x": test})
    with pytest.raises(UserError, match="steps"):
        J.two_sample_test(train, train, test, {"x": test}, steps=0)
    with pytest.raises(UserError, match="power-of-two"):
        J.Critic(4, 24)


@pytest.mark.parametrize("azimuth,band", [(0, "input"), (15, "near"), (-45, "near"), (90, "side"),
                                          (-120, "side"), (180, "back"), (-165, "back"), (540, "back"),
                                          (7.5, None), (50, None)])
def test_bands(azimuth, band):
    assert J.band_of(azimuth) == band


def test_every_scored_azimuth_has_a_band():
    assert all(J.band_of(a) is not None for a in J.SCORE_AZIMUTHS)
    assert {J.band_of(a) for a in J.SCORE_AZIMUTHS} == {b[0] for b in J.BANDS}


# -- image statistics on constructed images ---------------------------------------------------

def rgba(rgb: np.ndarray, alpha: np.ndarray) -> torch.Tensor:
    """Premultiplied RGBA from a colour ``(3, H, W)`` and an opacity ``(H, W)``."""
    return torch.from_numpy(np.concatenate([rgb * alpha, alpha[None]]).astype(np.float32))


def test_roughness_of_a_flat_image_is_zero_and_of_a_checkerboard_is_its_laplacian():
    ones = np.ones((8, 8))
    assert S.roughness(rgba(np.full((3, 8, 8), 0.3), ones)) == 0.0
    board = (np.indices((8, 8)).sum(0) % 2).astype(float)           # display values 0 and 1 (sRGB(0), sRGB(1))
    # |ΔD| = 4 inside, 3 on an edge (one neighbour is the pixel itself), 2 in a corner
    expected = (36 * 4 + 24 * 3 + 4 * 2) / 64
    assert S.roughness(rgba(np.stack([board] * 3), ones)) == pytest.approx(expected)


def test_roughness_counts_only_the_foreground_and_is_none_without_one():
    board = (np.indices((8, 8)).sum(0) % 2).astype(float)
    alpha = np.zeros((8, 8))
    alpha[:, :4] = 1.0
    img = rgba(np.stack([board] * 3), alpha)
    full = S.roughness(rgba(np.stack([board] * 3), np.ones((8, 8))))
    assert S.roughness(img) != full
    assert S.roughness(rgba(np.ones((3, 8, 8)), np.zeros((8, 8)))) is None
    assert S.coverage(img) == 0.5


def test_colour_distance_of_white_and_black_is_100_and_of_an_image_with_itself_0():
    ones = np.ones((4, 4))
    white, black = rgba(np.ones((3, 4, 4)), ones), rgba(np.zeros((3, 4, 4)), ones)
    d = S.colour_distance(white, black)
    assert d["delta_e"] == pytest.approx(100.0, abs=1e-3)
    # two single colours: SW₁ = ΔE · mean |⟨u, L̂⟩| over the fixed directions
    # (sRGB white is L*a*b* (100, 0.008, 0.004): the difference lies along L* to 1e-4)
    assert d["sliced_w1"] == pytest.approx(100.0 * np.abs(S._directions()[:, 0]).mean(), abs=0.01)
    assert S.colour_distance(white, white) == {"delta_e": 0.0, "sliced_w1": 0.0}


def test_foreground_colour_is_the_pixels_own_colour_whatever_its_opacity():
    colour = np.array([0.7, 0.2, 0.1])[:, None, None] * np.ones((3, 4, 4))
    opaque, faint = rgba(colour, np.ones((4, 4))), rgba(colour, np.full((4, 4), 0.6))
    assert S.colour_distance(opaque, faint)["delta_e"] == pytest.approx(0.0, abs=1e-4)
    # sRGB (0.5, 0.5, 0.5)'s linear value has L* = 53.39 (CIE: L* = 116 (Y)^(1/3) − 16 with Y = 0.2140)
    grey = rgba(np.full((3, 4, 4), 0.21404114), np.ones((4, 4)))
    assert S.foreground_lab(grey)[0, 0] == pytest.approx(53.39, abs=0.02)
    assert S.colour_distance(grey, rgba(np.ones((3, 4, 4)), np.zeros((4, 4)))) == {"delta_e": None, "sliced_w1": None}


def test_view_statistics_of_a_reconstruction_that_looks_the_same_from_everywhere():
    rng = np.random.default_rng(0)
    photo = rgba(rng.uniform(0, 1, (3, 8, 8)), np.ones((8, 8)))
    stats = J.view_statistics(photo, {a: photo for a in (0.0, 90.0, -90.0, 180.0)})
    assert stats["roughness_input"] == pytest.approx(1.0)
    assert stats["delta_e_input"] == pytest.approx(0.0, abs=1e-6)
    for v in J.STAT_VIEWS:
        assert stats[f"roughness_{v}"] == pytest.approx(1.0)
        assert stats[f"coverage_{v}"] == 1.0
        assert stats[f"delta_e_{v}"] == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(UserError, match="azimuths"):
        J.view_statistics(photo, {0.0: photo})


def test_image_statistics_refuse_bad_images():
    with pytest.raises(UserError, match="shape"):
        S.roughness(torch.zeros(3, 8, 8))
    with pytest.raises(UserError, match="NaN"):
        S.coverage(torch.full((4, 8, 8), float("nan")))
    with pytest.raises(UserError, match="RGBA"):
        S.foreground_lab(torch.zeros(1, 8, 8))
