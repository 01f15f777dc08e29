"""Benchmarks (not part of the product's behaviour; figures in docs/BENCHMARKS.md)."""
