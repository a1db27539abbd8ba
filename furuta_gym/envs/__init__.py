"""Gymnasium envs over interchangeable dynamics backends."""
