"""Speed and error benchmarks."""
