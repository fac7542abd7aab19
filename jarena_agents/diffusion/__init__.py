"""Diffusion Policy: a trainable agent that generates action sequences by denoising, learnt from a TrajectoryDataset."""
