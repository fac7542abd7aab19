import pytest

from jarena.data import DatasetError, Field, Schema


def test_schema_round_trips_through_json_and_fills_output_keys():
    schema = Schema(observation={"rgb": {"shape": [64, 64, 3], "dtype": "uint8", "compression": "zstd:3"}},
                    action={"a": Field((2,))}, goal={"g": {"shape": (2,), "output_key": "goal"}})
    assert schema.observation["rgb"] == Field((64, 64, 3), "uint8", "rgb", "zstd:3")
    assert schema.action["a"].output_key == "a" and schema.goal["g"].output_key == "goal"
    assert Schema.from_json(schema.to_json()) == schema
    assert schema.observation["rgb"].itemsize == 64 * 64 * 3
    other = Schema(observation={"rgb": {"shape": [32, 32, 3], "dtype": "uint8", "compression": "zstd:3"}},
                   action={"b": Field((2,))})
    diff = schema.differences(other)
    assert any("'rgb'" in d and "[64, 64, 3]" in d for d in diff)
    assert "action field 'a' is in the store but not in the given config" in diff
    assert "action field 'b' is in the given config but not in the store" in diff
    assert "goal field 'g' is in the store but not in the given config" in diff


@pytest.mark.parametrize("config, match", [
    ({"shape": (2,), "dtype": "complex64"}, "bool, int, uint or float"),
    ({"shape": (2,), "dtype": "nonsense"}, "unknown dtype"),
    ({"shape": (2,), "compression": "bzip9"}, "unknown compression"),
    ({"shape": (-1,)}, "must not be negative"),
    ({"dtype": "float32"}, "needs 'shape'"),
    ({"shape": (2,), "colour": "red"}, "needs 'shape'"),
])
def test_bad_field_configs(config, match):
    with pytest.raises(DatasetError, match=match):
        Schema(observation={"x": config}, action={"a": {"shape": ()}})


def test_schema_needs_observations_and_actions_with_distinct_keys():
    with pytest.raises(DatasetError, match="action config needs at least one field"):
        Schema(observation={"x": {"shape": ()}}, action={})
    with pytest.raises(DatasetError, match="share an output key"):
        Schema(observation={"x": {"shape": ()}, "y": {"shape": (), "output_key": "x"}}, action={"a": {"shape": ()}})
