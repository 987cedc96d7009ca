"""Config keys and types (pydantic on the config dataclasses): each error is one line naming the key."""

import pytest

from mitsuba_platonic.config import Config, ConfigError, RenderConfig, TrainConfig, config_from_dict, load_config


def _error(*overrides: str) -> str:
    with pytest.raises(ConfigError) as info:
        load_config(None, list(overrides))
    message = str(info.value)
    assert "\n" not in message
    return message


def test_an_unknown_key_lists_the_known_keys():
    message = _error("train.bogus=1")
    assert message.startswith("train.bogus: unknown key (known: batch_size, betas, colour_match, colour_offset, "
                              "colour_tv, d_augment, d_gate, d_roll, d_steps, depth_spread, elevation, ema, "), message
    assert "lr_d" in message and "weight_3d" in message
    assert _error("bogus.key=1") == "bogus: unknown key (known: data, model, render, run, train)"


@pytest.mark.parametrize("override, message", [
    ("train.batch_size=true", "train.batch_size: expected int, got True"),     # a bool is not an int
    ("run.steps=2.0", "run.steps: expected int, got 2.0"),
    ("train.batch_size='8'", "train.batch_size: expected int, got '8'"),
    ("data.clean=1", "data.clean: expected true or false, got 1"),
    ("run.name=3", "run.name: expected a string, got 3"),
])
def test_scalar_types_are_strict(override, message):
    assert _error(override) == message


@pytest.mark.parametrize("override, message", [
    ("train.lr_d=abc", "train.lr_d: expected a number, got 'abc'"),
    ("train.lr_d='0.5'", "train.lr_d: expected a number, got '0.5'"),           # a quoted number is a string
    ("train.lr_d=true", "train.lr_d: expected a number, got True"),
])
def test_a_string_or_bool_is_not_a_float(override, message):
    assert _error(override) == message


def test_floats_accept_ints_and_yaml_1_1_exponents():
    cfg = load_config(None, ["train.lr_d=1e-4", "train.lr_g=2E-3", "render.fov=30", "train.betas=[0, 9e-1]"])
    assert cfg.train.lr_d == 1e-4 and cfg.train.lr_g == 2e-3
    assert isinstance(cfg.render.fov, float) and cfg.render.fov == 30.0
    assert cfg.train.betas == [0.0, 0.9] and all(isinstance(b, float) for b in cfg.train.betas)
    # a run's config.yaml is read with yaml.safe_load and passed on as a dict: the string is a number there too
    assert config_from_dict({"train": {"lr_d": "1e-4", "elevation": ["1e1", 20]}}).train.elevation == [10.0, 20.0]
    assert _error("train.lr_d=1e-4x") == "train.lr_d: expected a number, got '1e-4x'"


@pytest.mark.parametrize("override, message", [
    ("train.lr_g=.inf", "train.lr_g: expected a finite number, got inf"),
    ("train.lr_d=.nan", "train.lr_d: expected a finite number, got nan"),
    ("train.rec_weight=.inf", "train.rec_weight: expected a finite number, got inf"),
    ("train.gp_weight=-.inf", "train.gp_weight: expected a finite number, got -inf"),
    ("data.threshold=.nan", "data.threshold: expected a finite number, got nan"),
    ("render.fov=-.inf", "render.fov: expected a finite number, got -inf"),
    ("train.elevation=[0, .inf]", "train.elevation[1]: expected a finite number, got inf"),
    ("data.elevation=.nan", "data.elevation: expected a finite number or a list or null, got nan"),
])
def test_non_finite_numbers_name_the_key(override, message):
    assert _error(override) == message


def test_a_nested_wrong_type_names_the_item():
    assert _error("train.betas=[0.5, x]") == "train.betas[1]: expected a number, got 'x'"
    assert _error("data.elevation=[1, 2, x]") == "data.elevation[2]: expected a number, got 'x'"
    assert _error("train.betas=x") == "train.betas: expected a list, got 'x'"


def test_optional_and_union_fields_say_what_they_accept():
    assert _error("data.elevation=x") == "data.elevation: expected a number or a list or null, got 'x'"
    assert _error("train.d_gate=x") == "train.d_gate: expected a number or null, got 'x'"
    assert _error("data.path=3") == "data.path: expected a string or null, got 3"
    cfg = load_config(None, ["train.d_gate=null", "data.elevation=12", "render.distance=null"])
    assert (cfg.train.d_gate, cfg.data.elevation, cfg.render.distance) == (None, 12.0, None)


def test_mappings_sections_and_code_built_configs():
    with pytest.raises(ConfigError, match=r"^config: expected a mapping, got \['a'\]$"):
        config_from_dict(["a"])
    with pytest.raises(ConfigError, match=r"^train: expected a mapping, got \[\]$"):
        config_from_dict({"train": []})
    assert config_from_dict({"train": None, "run": {}}) == Config()              # `train:` alone: the defaults
    assert config_from_dict({"train": {"betas": (0.5, 0.8)}}).train.betas == [0.5, 0.8]
    saved = Config().to_dict()
    assert config_from_dict(saved) == Config()
    with pytest.raises(ConfigError, match=r"^train\.lr_d: expected a finite number, got inf$"):
        Config(train=TrainConfig(lr_d=float("inf"))).validate()                   # built in code, not loaded


@pytest.mark.parametrize("value, ok", [("auto", True), (1, True), (3, True), (0, False), ("many", False)])
def test_drjit_threads_is_auto_or_a_count(value, ok):
    if ok:
        assert config_from_dict({"run": {"drjit_threads": value}}).run.drjit_threads == value
    else:
        with pytest.raises(ConfigError, match="run.drjit_threads"):
            config_from_dict({"run": {"drjit_threads": value}})


# -- each section owns its settings and checks itself (issue 26) ------------------------------

def test_each_section_checks_itself_with_the_configs_messages():
    """A section's validate() raises what the whole config's does, without a Config around it."""
    from mitsuba_platonic.data.settings import DataConfig
    from mitsuba_platonic.networks.settings import ModelConfig
    from mitsuba_platonic.config.run_settings import RunConfig
    from mitsuba_platonic.config.train_settings import TrainConfig as OwnTrainConfig

    assert OwnTrainConfig is TrainConfig                    # the config re-exports the owner's class
    for section, key, bad in [(RunConfig(steps=0), "run.steps", "run.steps=0"),
                              (DataConfig(split=0.0), "data.split", "data.split=0"),
                              (ModelConfig(resolution=24), "model.resolution", "model.resolution=24"),
                              (TrainConfig(batch_size=0), "train.batch_size", "train.batch_size=0")]:
        with pytest.raises(ConfigError) as info:
            section.validate()
        assert str(info.value).startswith(key + ":") and str(info.value) == _error(bad)
        assert type(section)().validate() == type(section)()


def test_cross_section_checks_stay_with_the_config():
    """colour needs the EA formation: a check of two sections, which the train section alone passes."""
    cfg = Config(render=RenderConfig(model="vh"))
    cfg.train.colour_tv, cfg.data.formation = 0.1, "vh"
    assert cfg.train.validate() is cfg.train
    with pytest.raises(ConfigError, match=r"^train\.colour_tv: colour needs render\.model 'ea', got 'vh'$"):
        cfg.validate()


def test_the_model_section_builds_the_networks_config():
    """The keys ModelConfig shares with NetConfig are handed over as they are; the rest come from
    the other sections (channels, view codes, pose) or are the critics' (critic_width)."""
    import dataclasses

    from mitsuba_platonic.model import critic_config, net_config
    from mitsuba_platonic.networks.settings import NET_KEYS, ModelConfig
    from mitsuba_platonic.networks.nets import NetConfig

    shared = {f.name for f in dataclasses.fields(NetConfig)} & {f.name for f in dataclasses.fields(ModelConfig)}
    assert set(NET_KEYS) == shared
    cfg = load_config(None, ["model.width=8", "model.latent=16", "model.critic_width=24", "model.norm=instance",
                             "model.upsample=resize", "model.encoder_hidden=32", "render.model=vh",
                             "data.formation=vh"])
    net = net_config(cfg)
    assert net == NetConfig(resolution=32, volume_channels=1, image_channels=1, latent=16, width=8, norm="instance",
                            encoder_hidden=32, upsample="resize", view_codes=0, pose=False)
    assert critic_config(cfg) == dataclasses.replace(net, width=24)
    assert critic_config(load_config(None, ["model.width=8"])).width == 8
