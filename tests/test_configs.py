import pytest

import jarena


def test_retrieve_config(tmp_path, monkeypatch):
    (tmp_path / "myagent" / "classic-cartpole-balance").mkdir(parents=True)
    (tmp_path / "myagent" / "classic-cartpole-balance" / "default.yaml").write_text("lr: 0.001\nlayers: [64, 64]\n")
    (tmp_path / "myagent" / "default.yaml").write_text("lr: 0.01\n")
    monkeypatch.setenv("JARENA_CONFIGS", str(tmp_path))
    arena = jarena.build_arena("classic|domain:cartpole")
    assert jarena.retrieve_config("myagent", arena) == {"lr": 0.001, "layers": [64, 64]}
    assert jarena.retrieve_config("myagent", "classic|domain:cartpole,task:balance")["lr"] == 0.001
    assert jarena.retrieve_config("myagent", "other-arena") == {"lr": 0.01}
    with pytest.raises(FileNotFoundError, match="no config 'tuned'.*available: .*default.yaml"):
        jarena.retrieve_config("myagent", arena, "tuned")
    import jarena_agents  # noqa: F401  (registers the agents: retrieve_config refuses unknown names)

    assert jarena.retrieve_config("random", arena) == {}  # a registered agent without configs


def test_shipped_configs_are_valid():
    import jarena_agents
    from jarena.configs import config_roots

    for root in config_roots():
        for path in root.rglob("*.yaml"):
            agent, *rest = path.relative_to(root).parts
            if agent in jarena_agents.AGENTS:
                arena = rest[0] if len(rest) == 2 else None
                jarena_agents.build_agent(agent, jarena.retrieve_config(agent, arena, path.stem))
