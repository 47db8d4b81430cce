"""Analyses built on the pipeline: sensitivity, worst case, rare events, the paper's data."""
