"""Networks: shapes and gradient flow; config validation."""

import math

import pytest
import torch
import yaml
from torch import nn

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.networks.nets import Discriminator, Encoder, Generator, NetConfig, VolumeDiscriminator, init_weights


def build_networks(cfg: NetConfig, volume_discriminator: bool = False) -> nn.ModuleDict:
    """E, G, D (and D3) for ``cfg``, initialised as every network starts (``init_weights``)."""
    nets = nn.ModuleDict({"E": Encoder(cfg), "G": Generator(cfg), "D": Discriminator(cfg)})
    if volume_discriminator:
        nets["D3"] = VolumeDiscriminator(cfg)
    nets.apply(init_weights)
    return nets


@pytest.mark.parametrize("resolution,channels,norm", [(16, 4, "batch"), (32, 1, "instance"), (64, 4, "none")])
def test_shapes_and_gradient_flow(resolution, channels, norm):
    cfg = NetConfig(resolution=resolution, volume_channels=channels, image_channels=channels, latent=8,
                    width=4, norm=norm)
    nets = build_networks(cfg, volume_discriminator=True)
    x = torch.rand(2, channels, resolution, resolution)
    z = nets["E"](x)
    assert z.shape == (2, 8)
    v = nets["G"](z)
    assert v.shape == (2, channels, resolution, resolution, resolution)
    assert v.min() >= 0 and v.max() <= 1
    logit, logit3 = nets["D"](x), nets["D3"](v)
    assert logit.shape == (2,) and logit3.shape == (2,)
    (logit.sum() + logit3.sum() + v.mean()).backward()
    for name, net in nets.items():
        for pname, p in net.named_parameters():
            assert p.grad is not None and torch.isfinite(p.grad).all(), f"{name}.{pname}"
            assert p.grad.abs().sum() > 0, f"no gradient reaches {name}.{pname}"


def test_paper_generator_widths_at_64():
    g = build_networks(NetConfig(resolution=64, width=64, latent=200, norm="batch"))["G"]
    convs = [m for m in g.modules() if isinstance(m, torch.nn.ConvTranspose3d)]
    assert [c.out_channels for c in convs] == [512, 256, 128, 64, 4]


RESOLUTIONS = [(16, 4), (32, 1), (64, 4), (128, 1)]     # every supported R; narrow nets keep 128³ quick


@pytest.mark.parametrize("resolution,channels", RESOLUTIONS)
def test_generator_output_shape_range_and_dependence_on_z(resolution, channels):
    """G: (B, latent) → (B, C, R, R, R) in [0, 1], different for different z; with its last layer
    scaled up the output saturates at both ends of (0, 1) without leaving it (a sigmoid, not an
    unbounded or one-sided output)."""
    g = build_networks(NetConfig(resolution=resolution, volume_channels=channels, image_channels=channels,
                                 latent=8, width=2, norm="batch"))["G"].train()
    z = torch.randn(4, 8)
    with torch.no_grad():
        v = g(z)
        assert v.shape == (4, channels, resolution, resolution, resolution) and torch.isfinite(v).all()
        assert v.min() >= 0 and v.max() <= 1
        a = torch.logit(v.double())                      # pre-activations (VH/AO start at logit(1/R))
        for i in range(1, 4):                            # at initialisation they differ by ≈ 0.04
            assert (a[0] - a[i]).abs().mean() > 4e-3, f"G(z_0) ≈ G(z_{i}): G ignores z"
        last = [m for m in g.modules() if isinstance(m, torch.nn.ConvTranspose3d)][-1]
        last.weight.mul_(50.0)                           # pre-activations ≈ ±15
        s = g(z)
    assert s.min() >= 0 and s.max() <= 1
    assert s.min() < 1e-3 and s.max() > 1 - 1e-3


@pytest.mark.parametrize("encoder_hidden", [0, 16])
@pytest.mark.parametrize("resolution,channels", RESOLUTIONS)
def test_encoder_maps_images_to_codes(resolution, channels, encoder_hidden):
    """E (plain Linear head or the authors' hidden layer): (B, C, R, R) → (B, latent); each code
    depends on its own image only (eval mode) and differs between images."""
    e = build_networks(NetConfig(resolution=resolution, volume_channels=channels, image_channels=channels,
                                 latent=8, width=2, encoder_hidden=encoder_hidden, norm="batch"))["E"].eval()
    x = torch.rand(3, channels, resolution, resolution)
    with torch.no_grad():
        codes = e(x)
        assert codes.shape == (3, 8) and torch.isfinite(codes).all()
        scale = float(codes.abs().max())                              # DCGAN initialisation: codes are small
        assert scale > 0
        torch.testing.assert_close(e(x[[0, 2]]), codes[[0, 2]], rtol=1e-4, atol=1e-4 * scale)  # no mixing
        assert (codes[0] - codes[1]).abs().max() > 0.1 * scale
        assert (codes[1] - codes[2]).abs().max() > 0.1 * scale


def test_bad_inputs():
    nets = build_networks(NetConfig(resolution=16, latent=8, width=4, norm="batch"))
    with pytest.raises(ValueError, match="expects images"):
        nets["D"](torch.rand(2, 4, 32, 32))
    with pytest.raises(ValueError, match="expects z"):
        nets["G"](torch.rand(2, 9))
    with pytest.raises(ValueError, match="resolution"):
        NetConfig(resolution=24).validate()


@pytest.mark.parametrize("override,match", [
    ("train.batch_size=eight", r"train\.batch_size: expected int"),
    ("train.bogus=1", r"train\.bogus: unknown key"),
    ("bogus.key=1", r"bogus: unknown key"),
    ("model.resolution=24", r"model\.resolution: expected one of"),
    ("train.lr_d=abc", r"train\.lr_d: expected a number"),
    ("train.betas=[0.5]", r"train\.betas"),
    ("render.backend=optix", r"render\.backend"),
    ("train.mode=gan3d", r"train\.rec_target"),
    ("render.model=vh", r"render\.model"),
    ("run.steps=true", r"run\.steps: expected int"),
    ("model.precision=fp16", r"model\.precision: expected one of"),
    ("trainsteps", r"key=value"),
])
def test_config_errors_name_the_key(override, match):
    with pytest.raises(ConfigError, match=match):
        load_config(None, [override])


def test_photos64_is_the_photo_recipe_at_64(tmp_path):
    # one recipe: the 64³ config differs from photos.yaml in its run's name and the resolution only
    a = load_config("photos", [f"data.path={tmp_path}"]).to_dict()
    b = load_config("photos64", [f"data.path={tmp_path}"]).to_dict()
    assert (a["run"].pop("name"), b["run"].pop("name")) == ("photos", "photos64")
    assert (a["model"].pop("resolution"), b["model"].pop("resolution")) == (32, 64)
    assert a == b


def test_config_files_load(tmp_path):
    from pathlib import Path
    configs = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
    assert configs
    for path in configs:
        if path.name in ("photos.yaml", "photos64.yaml", "photos_generate.yaml"):   # templates for the user's folder
            with pytest.raises(ConfigError, match="data.path"):
                load_config(path)
            cfg = load_config(path, [f"data.path={tmp_path}"])
        else:
            cfg = load_config(path)
        again = tmp_path / "again.yaml"                          # the resolved config reads back as itself
        again.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
        assert load_config(again).to_dict() == cfg.to_dict(), path.name
    bad = tmp_path / "bad.yaml"
    bad.write_text("train:\n  batch_size: [1, 2]\n")
    with pytest.raises(ConfigError, match="train.batch_size"):
        load_config(bad)
    assert load_config(None, ["train.lr_d=1e-5"]).train.lr_d == 1e-5   # YAML 1.1 reads 1e-5 as a string


@pytest.mark.parametrize("norm", ["batch", "none"])
def test_encoder_hidden_layer(norm):
    """encoder_hidden = H: E's trunk → Conv2d(k4) to H channels at 1² → Linear(H → latent); 0 keeps
    the plain Linear (and its state-dict keys)."""
    plain = build_networks(NetConfig(resolution=16, latent=8, width=4, norm=norm))["E"]
    assert not list(plain.hidden.parameters()) and plain.head.in_features == 8 * 16
    e = build_networks(NetConfig(resolution=16, latent=8, width=4, norm=norm, encoder_hidden=12))["E"]
    assert (e.hidden[0].in_channels, e.hidden[0].out_channels, e.hidden[0].kernel_size) == (8, 12, (4, 4))
    assert (e.head.in_features, e.head.out_features) == (12, 8)
    z = e(torch.rand(3, 4, 16, 16))
    assert z.shape == (3, 8)
    z.sum().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in e.hidden.parameters())
    with pytest.raises(ValueError, match="encoder_hidden"):
        NetConfig(encoder_hidden=-1).validate()
    with pytest.raises(ConfigError, match=r"model\.encoder_hidden"):
        load_config(None, ["model.encoder_hidden=-1"])


@pytest.mark.slow
def test_paper_config_builds_the_published_networks_and_trains(tmp_path):
    """configs/paper.yaml loads with the published values, builds the authors' shapes (G 512 → 256
    → 128 → 64, E ending in Conv(512 → 1024) and Linear(1024 → 200), D 64 → … → 512, BatchNorm)
    and makes 2 training steps on a CPU at 64³, batch 8 (tiny data: one shape, two views)."""
    from pathlib import Path

    import numpy as np
    from torch import nn

    from mitsuba_platonic.data import shapes
    from mitsuba_platonic.train.data import load_training_data
    from mitsuba_platonic.train.trainer import Trainer
    from mitsuba_platonic.volume import voxel_centres

    def ball(rng, n):
        density = torch.sigmoid((0.6 - voxel_centres(n).norm(dim=-1)) * n / 2.0)
        rgb = torch.tensor(rng.uniform(0.2, 0.9, size=3))[:, None, None, None].expand(3, n, n, n)
        return torch.cat([rgb, density[None]]).float()

    path = Path(__file__).resolve().parents[1] / "configs" / "paper.yaml"
    with shapes.registered("paper_test_ball", ball):
        cfg = load_config(path, [f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data",
                                 "data.shape_class=paper_test_ball", "data.n_shapes=1", "data.views_per_shape=2",
                                 "run.steps=2"])
        m, t = cfg.model, cfg.train
        assert (m.resolution, m.latent, m.width, m.norm, m.encoder_hidden) == (64, 200, 64, "batch", 1024)
        assert (t.batch_size, t.lr_g, t.lr_e, t.lr_d, t.betas, t.d_gate) == (8, 2.5e-3, 2.5e-3, 1e-5, [0.5, 0.9], 0.6)
        assert (t.loss, t.rec_weight, t.random_views, cfg.render.model) == ("nonsaturating", 8.0, 1, "ea")
        trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))

    E, G, D = trainer.nets["E"], trainer.nets["G"], trainer.nets["D"]
    assert [c.out_channels for c in G.modules() if isinstance(c, nn.ConvTranspose3d)] == [512, 256, 128, 64, 4]
    e_convs = [(c.in_channels, c.out_channels) for c in E.modules() if isinstance(c, nn.Conv2d)]
    assert e_convs == [(4, 64), (64, 128), (128, 256), (256, 512), (512, 1024)]
    assert (E.head.in_features, E.head.out_features) == (1024, 200)
    assert [c.out_channels for c in D.modules() if isinstance(c, nn.Conv2d)] == [64, 128, 256, 512, 1]
    for net in (E, G, D):
        assert any(isinstance(x, (nn.BatchNorm2d, nn.BatchNorm3d)) for x in net.modules())

    before = {k: [p.detach().clone() for p in trainer.nets[k].parameters()] for k in ("E", "G")}
    for step in range(2):
        out = trainer.step(step)
        assert all(np.isfinite(v) for v in out.values()), out
    for k, params in before.items():
        assert any(not torch.equal(a, b) for a, b in zip(params, trainer.nets[k].parameters())), k


def test_the_resize_generator_alternates_less_along_depth():
    """Transposed convolutions (k4, s2) give even and odd output layers different kernel taps, so
    a randomly initialised G's pre-sigmoid volume alternates along depth; nearest ×2 and a k3
    convolution do not, in every stage or in the last one only ('resize_last': the period-2
    alternation at R³ is the last stage's). Mean depth_stripes over 5 seeded inits."""
    from mitsuba_platonic.evaluate.metrics import depth_stripes
    from mitsuba_platonic.networks.nets import Generator, NetConfig
    mean = {}
    for up in ("transposed", "resize", "resize_last"):
        scores = []
        for seed in range(5):
            torch.manual_seed(seed)
            g = Generator(NetConfig(resolution=16, volume_channels=1, image_channels=1, latent=8, width=4,
                                    norm="none", upsample=up))
            with torch.no_grad():
                x = g.net[:-1](torch.randn(1, 8)[:, :, None, None, None])[0, 0, 3:13, 3:13, 3:13]
            scores.append(depth_stripes((x - x.min()) / (x.max() - x.min())))   # away from the faces
        mean[up] = sum(scores) / len(scores)
    assert mean["resize"] < 0.5 * mean["transposed"], mean
    assert mean["resize_last"] < 0.5 * mean["transposed"], mean
    with pytest.raises(ValueError, match="upsample"):
        NetConfig(upsample="bilinear").validate()


@pytest.mark.parametrize("resolution", [16, 32])
def test_generators_start_half_transparent_and_learn_a_silhouette(resolution):
    """G starts at density ≈ 1/R everywhere (colour ½), so its VH, AO and EA renders start at
    opacity ≈ 1 − e⁻¹ or 1 − (1 − 1/R)^R ≈ 0.63, not saturated at 1. From that start, a
    few Adam steps on the VH reconstruction loss of a disc silhouette fill the disc and keep the
    background empty; from the zero-bias start (every ray opaque, gradients ≈ e^(−R/2)) the same
    steps leave the image saturated or empty — the collapse the initialisation prevents."""
    from mitsuba_platonic import render
    from mitsuba_platonic import views as V

    torch.manual_seed(0)
    nets = build_networks(NetConfig(resolution=resolution, volume_channels=1, image_channels=1, latent=8, width=8, norm="batch"))
    ea = build_networks(NetConfig(resolution=resolution, volume_channels=4, image_channels=4, latent=8, width=8, norm="batch"))
    z = torch.randn(2, 8)
    with torch.no_grad():
        v = nets["G"](z)
        assert abs(float(v.mean()) * resolution - 1) < 0.05 and 0.5 / resolution < v.min() <= v.max() < 2 / resolution
        for model, expected in (("vh", 1 - torch.exp(torch.tensor(-1.0))), ("ao", 1 - (1 - 1 / resolution) ** resolution)):
            img = render(v, V.front_view(2), model, "closed_form")
            assert abs(float(img.mean()) - float(expected)) < 0.02, (model, float(img.mean()))
        rgba = ea["G"](z)
        assert abs(float(rgba[:, :3].mean()) - 0.5) < 0.02 and abs(float(rgba[:, 3].mean()) * resolution - 1) < 0.05
        alpha = render(rgba, V.front_view(2), "ea", "closed_form")[:, 3]
        assert abs(float(alpha.mean()) - (1 - (1 - 1 / resolution) ** resolution)) < 0.02

    yy, xx = torch.meshgrid(torch.linspace(-1, 1, resolution), torch.linspace(-1, 1, resolution), indexing="ij")
    target = ((xx ** 2 + yy ** 2) < 0.5 ** 2).float()[None, None].expand(2, 1, -1, -1)

    def fit(g):
        opt = torch.optim.Adam(g.parameters(), lr=1e-3, betas=(0.5, 0.9))
        for _ in range(80):
            img = render(g(z), V.front_view(2), "vh", "closed_form")
            loss = torch.nn.functional.mse_loss(img, target)
            opt.zero_grad()
            loss.backward()
            opt.step()
        return float(loss.detach())

    if resolution != 16:
        return                                            # the fit: at 16³ only (time)
    assert fit(nets["G"]) < 0.1                           # close to the disc
    torch.manual_seed(0)
    zero = build_networks(NetConfig(resolution=resolution, volume_channels=1, image_channels=1, latent=8, width=8, norm="batch"))
    with torch.no_grad():
        [m for m in zero["G"].modules() if isinstance(m, torch.nn.ConvTranspose3d)][-1].bias.zero_()
    assert fit(zero["G"]) > 0.3                           # still mostly opaque


# -- how E and G start (model.init) --------------------------------------------------------------

@pytest.mark.parametrize("layer", [
    torch.nn.Conv2d(3, 2, 4, 2, 1),                 # E's (and D's) strided k4
    torch.nn.Conv3d(5, 2, 3, 1, 1),                 # G's resize stage
    torch.nn.ConvTranspose3d(3, 2, 4, 2, 1),        # G's transposed ×2 stage
    torch.nn.Linear(7, 2),
])
def test_fan_in_counts_the_inputs_one_output_sums(layer):
    """Counted by the layer itself: all weights 1, bias 0, input all 1s: an interior output is the
    number of inputs it sums."""
    from mitsuba_platonic.networks.nets import fan_in
    with torch.no_grad():
        layer.weight.fill_(1.0)
        layer.bias.zero_()
        shape = (1, 7) if isinstance(layer, torch.nn.Linear) else (1, layer.in_channels, *[8] * (layer.weight.dim() - 2))
        out = layer(torch.ones(shape))
    centre = out[0, 0] if isinstance(layer, torch.nn.Linear) else out[(0, 0, *[out.shape[-1] // 2] * (out.dim() - 2))]
    assert fan_in(layer) == int(centre)


def _spread_through_g(init):
    """Per layer of G (after each activation), the spread over 16 images of G(E(x)) at the start."""
    from mitsuba_platonic.networks.nets import Encoder, Generator, init_he, init_weights
    torch.manual_seed(0)
    cfg = NetConfig(resolution=32, width=16, latent=64, norm="none", upsample="resize_last")
    E, G = Encoder(cfg), Generator(cfg)
    E.apply(init_weights)
    G.apply(init_weights)
    if init == "he":
        init_he(E)
        init_he(G)
    x = torch.rand(16, 4, 32, 32)
    spreads, a = [], E(x)[:, :, None, None, None]
    with torch.no_grad():
        for m in G.net:
            a = m(a)
            if isinstance(m, (torch.nn.ReLU, torch.nn.Sigmoid)):
                spreads.append((float(a.std(0).mean()), a))
    return spreads


def test_he_initialised_e_and_g_carry_the_image_to_the_volume_and_start_in_the_fog():
    """lab/init-and-critic-width.md: with the DCGAN initialisation and no
    normalisation the spread of G's last hidden layer over 16 images is ≈ 3e-6 (every image
    starts with the same volume), with He's it stays ≈ 0.1 through every layer; the first volume
    is still the fog of density 1/R and colour about ½ (G's output layer keeps its start)."""
    dcgan, he = _spread_through_g("dcgan"), _spread_through_g("he")
    assert dcgan[-2][0] < 1e-4
    assert all(0.03 < s < 1.0 for s, _ in he[:-1])
    volume = he[-1][1]
    assert abs(float(volume[:, 3].mean()) * 32 - 1.0) < 0.1
    assert abs(float(volume[:, :3].mean()) - 0.5) < 0.05
    assert float(volume.std(0).mean()) > 10 * dcgan[-1][0]           # and it varies with the image


def test_model_init_he_redraws_e_and_g_and_nothing_else(tmp_path, tiny_class):
    from mitsuba_platonic.train.data import load_training_data
    from mitsuba_platonic.train.trainer import Trainer
    from tiny_shapes import TINY

    def trainer(*extra):
        cfg = load_config(None, [f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data",
                                 f"data.shape_class={TINY}", "data.n_shapes=2", "data.views_per_shape=1",
                                 "model.resolution=16", "model.width=4", "model.latent=8", *extra])
        return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))

    dcgan, he = trainer(), trainer("model.init=he")
    assert all(torch.equal(a, b) for a, b in zip(dcgan.nets["D"].parameters(), he.nets["D"].parameters()))
    first = he.model.G.convolutions()[0]                              # z (8) → 4³ at width 4 · 2²
    assert abs(float(first.weight.detach().std()) - (2.0 / 8) ** 0.5) < 0.1 * (2.0 / 8) ** 0.5
    for name in ("E", "G"):
        assert not torch.equal(next(dcgan.nets[name].parameters()), next(he.nets[name].parameters()))
    last = (m.weight.detach() for m in (dcgan.model.G.convolutions()[-1], he.model.G.convolutions()[-1]))
    assert abs(float(next(last).std()) - 0.02) < 0.004 and abs(float(next(last).std()) - 0.02) < 0.004


@pytest.mark.parametrize("norm, upsample", [("none", "resize_last"), ("batch", "transposed"), ("none", "resize")])
def test_the_channels_last_generator_computes_what_the_usual_layout_does(norm, upsample):
    """G keeps its 3D weights channels-last for speed; the same weights in the usual layout, on the
    usual input, give the same volume (float round-off), and G's volume comes out contiguous, with
    gradients for every weight."""
    import copy
    torch.manual_seed(0)
    G = Generator(NetConfig(resolution=16, width=8, latent=16, norm=norm, upsample=upsample))
    convs = G.convolutions()
    assert all(c.weight.is_contiguous(memory_format=torch.channels_last_3d) for c in convs)
    usual = copy.deepcopy(G.net).to(memory_format=torch.contiguous_format)
    assert all(m.weight.is_contiguous() for m in usual if isinstance(m, (nn.Conv3d, nn.ConvTranspose3d)))
    z = torch.randn(3, 16)
    v = G(z)
    assert v.is_contiguous() and v.shape == (3, 4, 16, 16, 16)
    assert torch.allclose(v, usual(z[:, :, None, None, None]), atol=1e-5)
    v.sum().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in G.parameters())


# -- G's resize stage as one transposed convolution -----------------------------------------------

@pytest.mark.parametrize("layout", [torch.contiguous_format, torch.channels_last_3d])
def test_the_resize_stage_is_a_nearest_upsampling_then_its_k3_convolution(layout):
    """ResizeConv3d against the two operations it replaces (nn.Upsample ×2 nearest, then
    nn.Conv3d k3 p1 with the same weights): the same outputs, including every border voxel (where
    the zero padding enters), and the same gradients for input, weight and bias; also for an input
    of exact 0s and 1s, an odd size and channel counts that are not powers of two."""
    from mitsuba_platonic.networks.nets import ResizeConv3d
    torch.manual_seed(0)
    fused = ResizeConv3d(5, 3, bias=True).to(memory_format=layout)
    plain = nn.Conv3d(5, 3, 3, 1, 1, bias=True)
    with torch.no_grad():
        plain.weight.copy_(fused.weight)
        plain.bias.copy_(fused.bias)
    for x0 in (torch.randn(2, 5, 5, 6, 7), (torch.rand(2, 5, 5, 6, 7) > 0.5).float()):
        x0 = x0.contiguous(memory_format=layout)
        xa, xb = x0.clone().requires_grad_(True), x0.clone().requires_grad_(True)
        ya, yb = fused(xa), plain(nn.functional.interpolate(xb, scale_factor=2, mode="nearest"))
        assert ya.shape == yb.shape == (2, 3, 10, 12, 14)
        assert torch.allclose(ya, yb, atol=1e-5), float((ya - yb).abs().max())
        w = torch.randn_like(yb)
        (ya * w).sum().backward()
        (yb * w).sum().backward()
        assert torch.allclose(xa.grad, xb.grad, atol=1e-4)
        for p, q in ((fused.weight, plain.weight), (fused.bias, plain.bias)):
            assert torch.allclose(p.grad, q.grad, rtol=1e-5, atol=1e-4), float((p.grad - q.grad).abs().max())
            p.grad, q.grad = None, None


@pytest.mark.parametrize("upsample", ["resize", "resize_last"])
def test_a_checkpoint_of_a_generator_whose_resize_stages_upsampled_apart_still_loads(upsample):
    """Before the resize stage was one module, it was nn.Upsample and nn.Conv3d in G's sequence.
    That generator's state dict (the keys a checkpoint holds) loads strictly into today's G, which
    then computes what the older one did."""
    import copy
    from mitsuba_platonic.networks.nets import ResizeConv3d
    torch.manual_seed(0)
    G = Generator(NetConfig(resolution=16, width=8, latent=16, norm="none", upsample=upsample))
    old = copy.deepcopy(G.net)
    for i, m in enumerate(old):
        if isinstance(m, ResizeConv3d):
            plain = nn.Conv3d(m.in_channels, m.out_channels, 3, 1, 1, bias=m.bias is not None)
            plain.load_state_dict(m.state_dict())
            old[i - 1], old[i] = nn.Upsample(scale_factor=2, mode="nearest"), plain
    assert sum(isinstance(m, nn.Upsample) for m in old) == (2 if upsample == "resize" else 1)
    fresh = Generator(NetConfig(resolution=16, width=8, latent=16, norm="none", upsample=upsample))
    fresh.net.load_state_dict(old.state_dict(), strict=True)
    z = torch.randn(3, 16)
    assert torch.allclose(fresh(z), old(z[:, :, None, None, None]), atol=1e-5)


# -- the networks' arithmetic (model.precision) ----------------------------------------------------

def test_bf16_networks_compute_in_bfloat16_and_hand_back_float32():
    """With ``precision='bf16'`` every network's output is float32 and near the float32 network's
    with the same weights (bfloat16's 8-bit mantissa: a relative error of order 2⁻⁸ per layer), but
    not equal to it (so the arithmetic did change); the gradients reach every weight, which stays
    float32. Also at exact 0 and 1 inputs."""
    import dataclasses
    torch.manual_seed(0)
    fp32 = NetConfig(resolution=16, volume_channels=4, image_channels=4, latent=8, width=8, norm="none",
                     upsample="resize_last")
    bf16 = dataclasses.replace(fp32, precision="bf16")
    for x in (torch.rand(3, 4, 16, 16), (torch.rand(3, 4, 16, 16) > 0.5).float()):
        for cls in (Encoder, Generator, Discriminator, VolumeDiscriminator):
            a, b = cls(fp32), cls(bf16)
            b.load_state_dict(a.state_dict())
            inp = {Generator: torch.randn(3, 8), VolumeDiscriminator: torch.rand(3, 4, 16, 16, 16)}.get(cls, x)
            ya, yb = a(inp), b(inp)
            assert yb.dtype == torch.float32 and yb.shape == ya.shape
            scale = float(ya.detach().abs().max())
            assert float((ya - yb).detach().abs().max()) < 0.05 * scale, cls.__name__
            assert not torch.equal(ya, yb), cls.__name__
            yb.sum().backward()
            assert all(p.dtype == torch.float32 and p.grad is not None and p.grad.dtype == torch.float32
                       and torch.isfinite(p.grad).all() for p in b.parameters()), cls.__name__


def test_precision_reaches_every_network_from_the_config():
    """``model.precision`` is the one setting of E's, G's and the critics' arithmetic."""
    from mitsuba_platonic.model import Model, critic_config
    cfg = load_config(None, ["model.precision=bf16", "model.resolution=16", "model.width=4", "model.latent=8",
                             "model.critic_width=8"])
    model = Model.from_config(cfg)
    assert model.E.cfg.precision == model.G.cfg.precision == critic_config(cfg).precision == "bf16"
    assert Model.from_config(load_config(None, [])).G.cfg.precision == "fp32"


# -- a colour read from the photo (model.photo_colour) ---------------------------------------------

def test_photo_colour_is_the_mean_colour_of_the_covered_pixels():
    """Premultiplied RGBA: a half-covered patch of colour (0.8, 0.4, 0.1) at α ½ and a fully
    covered one of (0.2, 0.6, 1.0) average by coverage; an empty image is grey."""
    from mitsuba_platonic.networks.photo_colours import photo_colour
    x = torch.zeros(2, 4, 8, 8)
    x[0, :3, :4] = torch.tensor([0.8, 0.4, 0.1])[:, None, None] * 0.5
    x[0, 3, :4] = 0.5
    x[0, :3, 4:6] = torch.tensor([0.2, 0.6, 1.0])[:, None, None]
    x[0, 3, 4:6] = 1.0
    want = (torch.tensor([0.8, 0.4, 0.1]) * 0.5 * 32 + torch.tensor([0.2, 0.6, 1.0]) * 16) / (0.5 * 32 + 16)
    m = photo_colour(x)
    assert torch.allclose(m[0], want, atol=1e-6)
    assert torch.equal(m[1], torch.full((3,), 0.5))
    with pytest.raises(ValueError, match="premultiplied RGBA"):
        photo_colour(torch.zeros(2, 1, 8, 8))


def test_a_photo_colour_generator_offsets_its_colour_logits_from_the_photos():
    """With G's colour logits at 0 (last layer's colour weights and biases zeroed) every voxel's
    colour is the photo's mean colour m, even at m's extremes (clamped to [1/255, 254/255]: finite
    logits); the density does not depend on m; G without photo_colour refuses a colour, and G with
    it needs one of shape (B, 3)."""
    from mitsuba_platonic.networks.photo_colours import COLOUR_MIN
    torch.manual_seed(0)
    G = Generator(NetConfig(resolution=16, width=8, latent=16, norm="none", upsample="resize_last",
                            photo_colour=True))
    last = G.convolutions()[-1]
    with torch.no_grad():
        last.weight[:3].zero_()
        last.bias[:3].zero_()
    z = torch.randn(3, 16)
    m = torch.tensor([[0.9, 0.3, 0.05], [0.0, 1.0, 0.5], [0.5, 0.5, 0.5]])
    v = G(z, m)
    want = m.clamp(COLOUR_MIN, 1 - COLOUR_MIN)[:, :, None, None, None].expand(-1, -1, 16, 16, 16)
    assert torch.allclose(v[:, :3], want, atol=1e-6)
    assert torch.isfinite(v).all()
    assert torch.equal(v[:, 3], G(z, torch.full((3, 3), 0.5))[:, 3])
    with pytest.raises(ValueError, match="needs the photos' mean colour"):
        G(z)
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        G(z, m[:, :2])
    with pytest.raises(ValueError, match="takes no colour"):
        Generator(NetConfig(resolution=16, width=8, latent=16, norm="batch"))(z, m)
    with pytest.raises(ValueError, match="volume_channels 4"):
        NetConfig(volume_channels=1, image_channels=1, photo_colour=True).validate()


@pytest.mark.parametrize("override", ["train.task=generation", "render.model=vh"])
def test_photo_colour_is_refused_where_there_is_no_photo_or_no_colour(override):
    extra = ["data.formation=vh"] if override == "render.model=vh" else []
    with pytest.raises(ConfigError, match="model.photo_colour"):
        load_config(None, ["model.photo_colour=true", override, *extra])


def test_a_photo_colour_model_reconstructs_in_each_photos_colour():
    """Model.reconstruct hands G each image's mean colour: with the colour logits at 0, a red and a
    blue photo give red and blue volumes from the same E and G; generate() offsets from grey."""
    from mitsuba_platonic.model import Model
    cfg = load_config(None, ["model.photo_colour=true", "model.resolution=16", "model.width=4", "model.latent=8",
                             "model.upsample=resize_last"])
    model = Model.from_config(cfg)
    last = model.G.convolutions()[-1]                         # a k3 convolution: output channels first
    with torch.no_grad():
        last.weight[:3].zero_()
        last.bias[:3].zero_()
    x = torch.zeros(2, 4, 16, 16)
    x[:, 3, 4:12, 4:12] = 1.0
    x[0, 0, 4:12, 4:12] = 1.0                                 # red
    x[1, 2, 4:12, 4:12] = 1.0                                 # blue
    v = model.reconstruct(x)
    assert v[0, 0].min() > 0.99 and v[0, 2].max() < 0.01
    assert v[1, 2].min() > 0.99 and v[1, 0].max() < 0.01
    assert torch.allclose(model.generate(2)[:, :3], torch.full((2, 3, 16, 16, 16), 0.5))


# -- the photo's colour per voxel (model.photo_texture) ----------------------------------------------


def _ramp_photo(n=16, b=2):
    """Premultiplied RGBA photos whose colour is linear in the row and the column (α 1 inside a
    margin of 2 pixels, 0 around): bilinear reads of it are exact."""
    r = torch.linspace(0.2, 0.8, n)
    x = torch.zeros(b, 4, n, n)
    x[:, 0], x[:, 1], x[:, 2] = r[:, None], r[None, :], 0.5 * r[:, None] + 0.3
    x[:, 3] = 0.0
    x[:, 3, 2:-2, 2:-2] = 1.0
    x[:, :3] *= x[:, 3:]
    return x


def test_photo_texture_carries_each_pixel_along_the_input_cameras_ray():
    """At elevation 0 every depth plane is the photo laid over its mean colour m (rgb + (1 − α) m);
    at elevation θ the texture tilted into the input camera's frame (the closed form's tilt, an
    independent resampling) is that same texture, exactly where both read a linear colour
    (a ramp photo, away from the cube's faces), and not the untilted one."""
    from mitsuba_platonic.networks.photo_colours import photo_colour, photo_texture
    from mitsuba_platonic.render.pytorch.closed_form import tilt
    x = _ramp_photo()
    flat = x[:, :3] + (1.0 - x[:, 3:]) * photo_colour(x)[:, :, None, None]
    t0 = photo_texture(x, 16)
    assert t0.shape == (2, 3, 16, 16, 16)
    assert torch.equal(t0, flat[:, :, None].expand(-1, -1, 16, -1, -1))
    x[:, :3], x[:, 3] = x[:, :3] / x[:, 3:].clamp_min(1.0), 1.0   # the whole photo covered: a linear colour
    x[:, 0], x[:, 1] = torch.linspace(0.2, 0.8, 16)[:, None], torch.linspace(0.2, 0.8, 16)[None, :]
    x[:, 2] = 0.5 * x[:, 0] + 0.3
    θ = torch.tensor([0.5, -0.3], dtype=torch.float64)
    t0, c = photo_texture(x, 16), slice(5, 11)
    seen = tilt(photo_texture(x, 16, θ), θ)
    assert (seen[..., c, c, c] - t0[..., c, c, c]).abs().max() < 1e-6
    assert (tilt(t0, θ)[..., c, c, c] - t0[..., c, c, c]).abs().max() > 0.03
    with pytest.raises(ValueError, match=r"one elevation per photo expected, shape \(2,\), got \(3,\)"):
        photo_texture(x, 16, torch.zeros(3))
    with pytest.raises(ValueError, match=r"premultiplied RGBA images"):
        photo_texture(x[:, :3], 16)


def test_a_photo_texture_model_starts_from_the_photo_at_the_input_view():
    """Model.reconstruct hands G the photo's texture as a camera at the pose head's elevation θ̂
    sees it: with G's colour logits at 0 and the head set to θ̂ ≈ 17°, the volume's colour is
    that texture tilted by θ̂ into the input frame, and not the texture of a camera at 0°.
    model.photo_texture needs model.photo_colour."""
    from mitsuba_platonic.model import Model
    from mitsuba_platonic.networks.photo_colours import COLOUR_MIN, photo_texture
    from mitsuba_platonic.render.pytorch.closed_form import tilt
    cfg = load_config(None, ["model.photo_colour=true", "model.photo_texture=true", "model.resolution=16",
                             "model.width=4", "model.latent=8", "model.upsample=resize_last",
                             "train.pose=elevation"])
    model = Model.from_config(cfg)
    last = model.G.convolutions()[-1]
    with torch.no_grad():
        last.weight[:3].zero_()
        last.bias[:3].zero_()
        model.P.bias.fill_(0.2)                               # θ̂ = (π/2) tanh(0.2) ≈ 0.31 rad
    x = _ramp_photo()
    v = model.reconstruct(x)
    with torch.no_grad():
        θ = model.P(model.E(x))
    assert torch.allclose(θ, torch.full((2,), math.pi / 2 * math.tanh(0.2)))
    inside = v[:, 3:] > 0.01
    for elevation, same in ((θ, True), (torch.zeros(2), False)):
        want = tilt(photo_texture(x, 16, elevation).clamp(COLOUR_MIN, 1 - COLOUR_MIN), θ)
        assert torch.allclose(v[:, :3] * inside, want * inside, atol=1e-5) == same
    with pytest.raises(ConfigError, match="model.photo_texture: .*needs model.photo_colour: true"):
        load_config(None, ["model.photo_texture=true"])
    with pytest.raises(ConfigError, match="model.photo_texture: .*orthographic input camera.*got 'perspective'"):
        load_config(None, ["model.photo_colour=true", "model.photo_texture=true", "render.camera=perspective"])


def test_front_transmittance_out_of_a_slab_is_the_product_of_the_voxels_before():
    """A slab of density v across planes 5–10 and columns 3–12 of the input camera's frame: out of
    voxel (k, j) inside it the transmittance towards the camera is (1 − v)^(k−5); 1 in front of the
    slab, (1 − v)^6 behind it. With θ the weight is in the camera's frame: θ = 0 gives the same."""
    from mitsuba_platonic.networks.photo_colours import front_transmittance
    n, v = 16, 0.3
    density = torch.zeros(1, 1, n, n, n, dtype=torch.float64)
    density[:, :, 5:11, :, 3:13] = v
    front = front_transmittance(density)[0, 0, :, 8, :]
    for k in range(5, 11):
        for j in range(3, 13):
            assert front[k, j] == pytest.approx((1 - v) ** (k - 5), abs=1e-12)
    assert torch.all(front[:5] == 1.0)
    assert torch.allclose(front[11:, 3:13], torch.full_like(front[11:, 3:13], (1 - v) ** 6), atol=1e-12)
    assert torch.allclose(front_transmittance(density, torch.zeros(1, dtype=torch.float64)),
                          front_transmittance(density), atol=1e-6)


def test_texture_corrected_adds_the_convolutions_output_to_gs_logits():
    """``model.texture_conv``: on an opaque-ish slab (v = 0.8 in planes 5–10 of 16, 0.1 elsewhere)
    with G's offsets ℓ, the corrected volume is σ(ℓ + δ_c + logit t) and σ(logit ρ + δ_ρ), and the
    offsets returned are ℓ + δ_c, for convolutions whose output is known by hand: a bias alone
    (δ = b), the centre tap of T_front into the density (δ_ρ = w T_front, with T_front written out
    for the slab: Π of (1 − v) over the planes in front), and the centre tap of logit t's red into
    the red offset (channel order ℓ, logit ρ, logit t, T_front)."""
    from mitsuba_platonic.networks.photo_colours import COLOUR_MIN, photo_texture, texture_corrected
    n = 16
    x = _ramp_photo(n, b=1)
    t = photo_texture(x, n)
    ρ = torch.full((1, 1, n, n, n), 0.1)
    ρ[:, :, 5:11] = 0.8
    ℓ = torch.randn(1, 3, n, n, n, generator=torch.Generator().manual_seed(0))
    logit_t = torch.logit(t.clamp(COLOUR_MIN, 1 - COLOUR_MIN))
    volume = torch.cat([torch.sigmoid(ℓ + logit_t), ρ], dim=1)
    conv = nn.Conv3d(8, 4, 3, padding=1)
    with torch.no_grad():
        conv.weight.zero_()
        conv.bias.copy_(torch.tensor([0.3, -0.2, 0.1, 0.5]))
    out, offsets = texture_corrected(conv, volume, ℓ, t)
    b = conv.bias.detach()
    assert torch.allclose(out[:, :3], torch.sigmoid(ℓ + b[:3, None, None, None] + logit_t), atol=1e-5)
    assert torch.allclose(out[:, 3:], torch.sigmoid(torch.logit(ρ) + b[3]), atol=1e-5)
    assert torch.allclose(offsets, ℓ + b[:3, None, None, None], atol=1e-6)
    front = torch.ones(n)                                          # T_front per plane (plane 0 nearest the camera)
    for k in range(1, n):
        front[k] = front[k - 1] * (1.0 - float(ρ[0, 0, k - 1, 0, 0]))
    with torch.no_grad():
        conv.bias.zero_()
        conv.weight[3, 7, 1, 1, 1] = 2.0                           # T_front → the density's logit
        conv.weight[0, 4, 1, 1, 1] = -0.5                          # logit t (red) → the red offset
    out, offsets = texture_corrected(conv, volume, ℓ, t)
    expected_ρ = torch.sigmoid(torch.logit(ρ) + 2.0 * front[None, None, :, None, None])
    assert torch.allclose(out[:, 3:], expected_ρ, atol=1e-5)
    assert torch.allclose(offsets[:, 0], ℓ[:, 0] - 0.5 * logit_t[:, 0], atol=1e-5)
    assert torch.allclose(offsets[:, 1:], ℓ[:, 1:], atol=1e-6)


def test_texture_conv_is_a_layer_of_g_that_training_reaches_and_the_config_checks():
    """G has the layer only with texture_conv; the model's initialisation draws it as G's other
    convolutions (N(0, 0.02), not zero: the configuration measured in lab/texture-conv.md); the
    photo recipe (photo_volume) applies it, and the gradient of the volume reaches its weights;
    the config refuses it without photo_texture."""
    from mitsuba_platonic.model import Model
    from mitsuba_platonic.networks.photo_colours import photo_volume
    base = ["model.resolution=16", "model.width=4", "model.latent=8", "model.photo_colour=true",
            "model.photo_texture=true", "render.model=ea"]
    cfg = load_config(None, base + ["model.texture_conv=true"])
    torch.manual_seed(0)
    model = Model.from_config(cfg)
    assert Model.from_config(load_config(None, base)).G.texture_conv is None
    w = model.G.texture_conv.weight
    assert 0.01 < float(w.detach().std()) < 0.03 and float(model.G.texture_conv.bias.detach().abs().max()) == 0.0
    x, z = _ramp_photo(16, b=2), torch.randn(2, 8)
    v, ℓ = photo_volume(model.G, z, x, cfg.model)
    plain, _ = photo_volume(model.G, z, x, load_config(None, base).model)     # the same G, the recipe without it
    assert v.shape == plain.shape == (2, 4, 16, 16, 16)
    assert (v - plain).abs().max() > 1e-3                                    # the recipe applied the layer
    v.sum().backward()
    assert w.grad is not None and float(w.grad.abs().max()) > 0.0
    with pytest.raises(ConfigError, match="model.texture_conv: .*needs model.photo_texture: true"):
        load_config(None, ["model.photo_colour=true", "model.texture_conv=true"])
