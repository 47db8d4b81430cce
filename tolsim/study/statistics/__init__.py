"""Streamed statistics of a study: accumulators, interval estimators, quality figures."""
