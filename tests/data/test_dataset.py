import hashlib
import json
import os

import numpy as np
import pytest
from trajectories import ACT, GOAL, OBS, check, length_of, trajectory

from jarena.data import DatasetError, TrajectoryDataset


def _tree_digest(path):
    """A digest of every file under ``path`` (names and bytes)."""
    h = hashlib.sha256()
    for directory, dirs, files in sorted(os.walk(path)):
        dirs.sort()
        for name in sorted(files):
            h.update(os.path.relpath(os.path.join(directory, name), path).encode())
            with open(os.path.join(directory, name), "rb") as f:
                h.update(f.read())
    return h.hexdigest()


@pytest.fixture
def store(tmp_path):
    path = tmp_path / "demos"
    with TrajectoryDataset(path, "w", obs_config=OBS, act_config=ACT, goal_config=GOAL, chunk_bytes=256) as ds:
        for k in range(4):
            assert ds.add_trajectory(**trajectory(k)) == k
    return path


def test_round_trip_needs_no_configs_and_keeps_dtypes(store):
    ds = TrajectoryDataset(store)
    assert ds.num_trajectories() == 4 and ds.num_steps() == sum(map(length_of, range(4)))
    assert ds.schema.observation["rgb"].dtype == "uint8" and ds.schema.observation["rgb"].output_key == "image"
    for k in range(4):
        check(ds, k)
    np.testing.assert_array_equal(ds.episodes(), [100, 101, 102, 103])
    assert [t["length"] for t in ds] == [length_of(k) for k in range(4)]
    with pytest.raises(IndexError, match="out of range for a dataset of 4"):
        ds.get_trajectory(4)
    check(ds, 3, index=-1)


def test_append_resumes_and_several_trajectories_commit_together(store):
    with TrajectoryDataset(store, "a") as ds:
        assert ds.add_trajectories([trajectory(k) for k in (4, 5, 6)]) == [4, 5, 6]
    with TrajectoryDataset(store, "a", obs_config=OBS, act_config=ACT, goal_config=GOAL) as ds:  # same configs: fine
        ds.add_trajectory(**trajectory(7))
    ds = TrajectoryDataset(store)
    assert ds.num_trajectories() == 8
    for k in range(8):
        check(ds, k)


def test_compression_and_scalar_fields(tmp_path):
    obs = {"rgb": {"shape": (8, 8, 3), "dtype": "uint8", "compression": "zstd:5"}, "v": {"shape": (2,),
                                                                                        "compression": "blosc"}}
    act = {"a": {"shape": (), "dtype": "int32"}}
    with TrajectoryDataset(tmp_path / "c", "w", obs_config=obs, act_config=act) as ds:
        rgb = np.zeros((6, 8, 8, 3), np.uint8)
        ds.add_trajectory({"rgb": rgb, "v": np.ones((6, 2))}, np.arange(5))  # one action field: a bare array
    got = TrajectoryDataset(tmp_path / "c").get_trajectory(0)
    assert got["action"]["a"].dtype == np.int32 and got["action"]["a"].tolist() == [0, 1, 2, 3, 4]
    assert got["observation"]["rgb"].dtype == np.uint8 and got["observation"]["v"].dtype == np.float32
    assert got["goal"] == {} and not got["terminated"].any()


def test_add_transition_builds_a_trajectory_until_it_ends(tmp_path):
    with TrajectoryDataset(tmp_path / "t", "w", obs_config=OBS, act_config=ACT, goal_config=GOAL) as ds:
        want = trajectory(2)
        t = length_of(2)
        obs = want["observations"]
        for i in range(t):
            index = ds.add_transition({k: v[i] for k, v in obs.items()}, {"force": want["actions"]["force"][i]},
                                      {k: v[i + 1] for k, v in obs.items()}, reward=want["rewards"][i],
                                      terminated=bool(want["terminated"][i]), goal=want["goal"], episode=102)
            assert index == (0 if i == t - 1 else None)
        ds.add_transition({k: v[0] for k, v in obs.items()}, {"force": np.zeros(2)}, {k: v[1] for k, v in obs.items()},
                          goal=want["goal"])
        assert ds.num_trajectories() == 1  # the unfinished one is in memory only
    ds = TrajectoryDataset(tmp_path / "t")
    assert ds.num_trajectories() == 1
    check(ds, 2, index=0)


def test_a_reader_sees_new_commits_after_refresh(store):
    reader = TrajectoryDataset(store)
    with TrajectoryDataset(store, "a") as writer:
        writer.add_trajectories([trajectory(k) for k in range(4, 40)])  # grows (resizes) every array
    assert reader.num_trajectories() == 4
    reader.refresh()
    assert reader.num_trajectories() == 40
    check(reader, 39)


BAD_TRAJECTORIES = [
    (lambda t: t["observations"].pop("rgb"), r"observations lacks field\(s\) \['rgb'\]"),
    (lambda t: t["observations"].update(state=np.zeros((3, 3))),
     r"observation field 'state': expected shape \(\d+, 3\)"),
    (lambda t: t["observations"].update(rgb=t["observations"]["rgb"].astype(np.float32)),
     "dtype float32 does not convert safely to the field's uint8"),
    (lambda t: t["actions"].update(force=np.zeros((0, 2))), "T >= 1"),
    (lambda t: t.update(goal=None), "missing goal"),
    (lambda t: t.update(rewards=np.zeros(99)), r"reward: expected shape"),
    (lambda t: t.update(actions=np.zeros((1, 3))), r"trajectory 1 of 2: action field 'force': expected shape \(1, 2\)"),
]


@pytest.mark.parametrize("corrupt, match", BAD_TRAJECTORIES)
def test_bad_trajectories_are_rejected_and_the_store_is_unchanged(store, corrupt, match):
    before = _tree_digest(store)
    with TrajectoryDataset(store, "a") as ds:
        bad = trajectory(9)
        corrupt(bad)
        with pytest.raises(DatasetError, match=match):
            ds.add_trajectories([trajectory(8), bad])  # the good one is not written either
        assert ds.num_trajectories() == 4
    assert _tree_digest(store) == before


def test_bad_opens_name_the_problem_and_leave_the_store(store, tmp_path):
    before = _tree_digest(store)
    other = dict(OBS, state={"shape": (5,)})
    mismatch = r"(?s)config mismatch on append.*observation field 'state': store has \{'shape': \[3\]"
    with pytest.raises(DatasetError, match=mismatch):
        TrajectoryDataset(store, "a", obs_config=other, act_config=ACT, goal_config=GOAL)
    with pytest.raises(DatasetError, match="valid modes are"):
        TrajectoryDataset(store, "x")
    with pytest.raises(DatasetError, match="open it with mode='a'"):
        TrajectoryDataset(store).add_trajectory(**trajectory(0))
    with pytest.raises(DatasetError, match="needs obs_config and act_config"):
        TrajectoryDataset(tmp_path / "new", "w")
    with pytest.raises(DatasetError, match="no dataset at"):
        TrajectoryDataset(tmp_path / "missing")
    with TrajectoryDataset(store, "a"), pytest.raises(DatasetError, match="open for writing by another"):
        TrajectoryDataset(store, "a")
    assert _tree_digest(store) == before
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    with pytest.raises(DatasetError, match="not a jarena dataset; refusing to overwrite"):
        TrajectoryDataset(tmp_path / "mine", "w", obs_config=OBS, act_config=ACT)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep me"


def test_corrupt_stores_get_clear_errors(store):
    import zarr

    commit = zarr.open_array(store / "commit", mode="r+")
    commit[1] += 1
    with pytest.raises(DatasetError, match="corrupt dataset.*lengths sum to"):
        TrajectoryDataset(store)
    commit[:] = [10 ** 6, 0]
    with pytest.raises(DatasetError, match="corrupt dataset.*rows, the commit record needs"):
        TrajectoryDataset(store)
    for chunk in os.listdir(store / "commit"):
        if chunk.startswith("c"):
            (store / "commit" / chunk).write_bytes(b"torn")
    with pytest.raises(DatasetError, match="bad commit record"):
        TrajectoryDataset(store)
    os.remove(store / "observation" / "rgb" / "zarr.json")
    with pytest.raises(DatasetError, match="missing array 'observation/rgb'"):
        TrajectoryDataset(store)
    meta = store / "zarr.json"
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "attributes": {}}))
    with pytest.raises(DatasetError, match="not a jarena dataset"):
        TrajectoryDataset(store)
    meta.write_text("{not json")
    with pytest.raises(DatasetError, match="not a readable zarr store"):
        TrajectoryDataset(store)


def test_overwrite_replaces_a_dataset(store):
    with TrajectoryDataset(store, "w", obs_config=OBS, act_config=ACT, goal_config=GOAL) as ds:
        assert ds.num_trajectories() == 0
    assert TrajectoryDataset(store).num_trajectories() == 0
