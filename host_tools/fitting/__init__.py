"""Fitting the bias model (fit, cross-validation), the closed-loop diagnosis, the figures of merit and the before/after report with the flight-stack baseline."""
