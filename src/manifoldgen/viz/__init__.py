"""Plots: training curves, generated samples (paper Fig. 2), residual histograms."""
