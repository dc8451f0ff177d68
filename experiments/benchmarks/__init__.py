"""Benchmarks of the MPM solver, the GNS, dataset generation and inverse design.

Run as ``python -m experiments.benchmarks --what=...`` (see ``__main__.py``).
"""
