"""Benchmarks: Table II, figures, timing; run each as ``python -m benchmarks.<name> --help``."""
