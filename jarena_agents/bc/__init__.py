"""Behaviour cloning: a trainable agent that imitates the demonstrations in a TrajectoryDataset."""
