"""Networks: shapes and gradient flow; config validation."""

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.models import NetConfig, build_networks


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
    g = build_networks(NetConfig(resolution=64, width=64, latent=200))["G"]
    convs = [m for m in g.modules() if isinstance(m, torch.nn.ConvTranspose3d)]
    assert [c.out_channels for c in convs] == [512, 256, 128, 64, 4]


def test_bad_inputs():
    nets = build_networks(NetConfig(resolution=16, latent=8, width=4))
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
    ("train.mode=gan3d", r"train\.task"),
    ("render.model=vh", r"render\.model"),
    ("run.steps=true", r"run\.steps: expected int"),
    ("trainsteps", r"key=value"),
])
def test_config_errors_name_the_key(override, match):
    with pytest.raises(ConfigError, match=match):
        load_config(None, [override])


def test_config_files_load(tmp_path):
    from pathlib import Path
    configs = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
    assert configs
    for path in configs:
        cfg = load_config(path)
        assert cfg.run.steps > 0
    bad = tmp_path / "bad.yaml"
    bad.write_text("train:\n  batch_size: [1, 2]\n")
    with pytest.raises(ConfigError, match="train.batch_size"):
        load_config(bad)
    assert load_config(None, ["train.lr_d=1e-5"]).train.lr_d == 1e-5   # YAML 1.1 reads 1e-5 as a string
