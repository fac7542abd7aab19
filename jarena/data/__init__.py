"""Data: an on-device functional buffer, and zarr-backed trajectory datasets.

    buffer = jarena.data.make_buffer(num_arenas=64, capacity=65536, sample_batch_size=256, mode="window", length=8)
    state = buffer.init(jarena.data.experience_spec(arena))
"""

from jarena.data.accessors import Accessors, BufferError
from jarena.data.buffer import Buffer, BufferState, make_buffer
from jarena.data.collect import collect, configs_for, resize_images
from jarena.data.dataset import TrajectoryDataset
from jarena.data.experience import Experience, experience_spec, transition_from
from jarena.data.loader import Loader
from jarena.data.sampling import (
    BufferSample,
    sample_trajectories,
    sample_transitions,
    sample_windows,
)
from jarena.data.schema import DatasetError, Field, Schema
from jarena.data.splits import split_trajectories

__all__ = ["Accessors", "Buffer", "BufferError", "BufferSample", "BufferState", "DatasetError", "Experience",
           "Field", "Loader", "Schema", "TrajectoryDataset", "collect", "configs_for", "experience_spec",
           "make_buffer", "resize_images", "sample_trajectories", "sample_transitions", "sample_windows",
           "split_trajectories", "transition_from"]
