"""Model-based controllers (PFL, energy swing-up, LQR) designed from any Lagrangian-system model."""
