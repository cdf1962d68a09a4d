"""The lab: benchmarks, comparisons and instruments run from a checkout (``python -m benchmarks.NAME``)."""
