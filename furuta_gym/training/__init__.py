"""Training learned Lagrangian models: data generation, losses, the training loop, checkpoints, metrics."""
