"""Plots (matplotlib) and meshcat visualisation of results."""
