"""Benchmark suite (``python benchmarks/run.py``); see docs/benchmarks.md."""
