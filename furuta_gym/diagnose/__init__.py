"""Residual diagnosis of measured data: fit, residual, trace the missing effect, refit, report."""
