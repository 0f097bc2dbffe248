"""Experiments: calibration of the scenario and, later, the reproduction of the paper."""
