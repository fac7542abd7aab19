"""Transporter Networks: a trainable pick-and-place agent over top-down images, learnt from a TrajectoryDataset."""
