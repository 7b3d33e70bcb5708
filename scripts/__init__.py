"""Benchmarks and accuracy measurements of xrayraster, run from the repository root as ``python -m scripts.NAME``."""
