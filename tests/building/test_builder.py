import pytest

import jarena
from jarena.building import ArenaStringError


def test_build_with_tools_tasks_and_time_limit():
    arena = jarena.build_arena("classic|domain:cartpole,task:balance,action:repeat(2),time_limit:100,"
                               "wrap:[reward_scale(0.1),success_bonus(1)]")
    assert arena.max_episode_steps == 50 and arena.tool.substeps == 2
    assert arena.name == "classic-cartpole-balance"
    assert arena.build_string.startswith("classic|domain:cartpole")


@pytest.mark.parametrize("text, message", [
    ("nosuch|domain:cartpole", "unknown arena builder 'nosuch'.*valid choices: .*classic"),
    ("classic|domian:cartpole", "unknown key for builder 'classic': 'domian' \\(did you mean 'domain'\\?\\)"),
    ("classic|task:balance", "needs key\\(s\\) \\['domain'\\]"),
    ("classic|domain:cartpol", "unknown classic domain 'cartpol' \\(did you mean 'cartpole'\\?\\); valid choices"),
    ("classic|domain:cartpole,task:swingup", "unknown task of classic domain 'cartpole': 'swingup'.*balance"),
    ("classic|domain:cartpole,action:repeet(2)", "unknown action tool 'repeet'.*valid choices: .*repeat"),
    ("classic|domain:cartpole,action:repeat(2,3)", "bad arguments in repeat\\(2,3\\)"),
    ("classic|domain:cartpole,action:repeat(0)", "invalid action tool repeat\\(0\\): repeat needs times >= 1"),
    ("classic|domain:cartpole,action:3", "invalid action tool '3'"),
    ("classic|domain:cartpole,wrap:nosuch", "unknown task transform 'nosuch'"),
    ("classic|domain:cartpole,time_limit:-5", "time_limit must be a positive integer"),
    ("classic|domain:cartpole,action:rescale", "rescale needs a bounded float Box"),
])
def test_errors_name_the_bad_part_and_the_choices(text, message):
    with pytest.raises(ArenaStringError, match=message):
        jarena.build_arena(text)


def test_register_builder_and_list():
    def build(size: int = 3):
        return jarena.build_arena("classic|domain:cartpole,time_limit:" + str(size))

    jarena.register_arena_builder("toy_test_builder", build, variants=lambda: [("toy_test_builder|size:3", ("toy",))])
    try:
        assert jarena.build_arena("toy_test_builder|size:4").max_episode_steps == 4
        assert "toy_test_builder|size:3" in jarena.list_arenas("toy")
        with pytest.raises(KeyError, match="already registered"):
            jarena.register_arena_builder("toy_test_builder", build)
    finally:
        from jarena.building.builder import BUILDERS
        BUILDERS._entries.pop("toy_test_builder")


def test_list_arenas_tags():
    assert "classic|domain:cartpole,task:balance" in jarena.list_arenas("benchmark")
    assert set(jarena.list_arenas("benchmark")) <= set(jarena.list_arenas())
