"""Experiments behind the paper's tables and the metrics they report."""
