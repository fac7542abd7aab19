import dataclasses

import pytest

from jarena_agents.config import ConfigError, make_config


@dataclasses.dataclass(frozen=True)
class Example:
    rate: float = 0.1
    count: int = 2
    flag: bool = False
    name: str = "a"
    layers: tuple = (4, 4)
    clip: float | None = 0.5
    segment: int | None = None


def test_values_convert_to_the_annotated_type():
    cfg = make_config(Example, {"rate": "1e-3", "count": 4.0, "layers": [8], "segment": "5", "clip": 1})
    assert cfg == Example(rate=1e-3, count=4, layers=(8,), segment=5, clip=1.0)
    assert isinstance(cfg.clip, float) and isinstance(cfg.segment, int)


def test_optional_fields_take_null_and_others_refuse_it():
    assert make_config(Example, {"clip": None, "segment": None}) == Example(clip=None)
    with pytest.raises(ConfigError, match="'rate' of agent 'x' must be a float, got None"):
        make_config(Example, {"rate": None}, agent="x")


@pytest.mark.parametrize("key, value, message", [
    ("count", 2.5, "must be an int, got 2.5"),
    ("flag", 1, "must be true or false, got 1"),
    ("segment", "five", "must be an int or null, got 'five'"),
    ("clip", True, "must be a float or null, got True"),
    ("name", 3, "must be a str, got 3"),
])
def test_bad_values_name_the_key_and_the_expected_type(key, value, message):
    with pytest.raises(ConfigError, match=f"config key '{key}' .*{message}"):
        make_config(Example, {key: value})
