"""Accuracy and speed benchmarks: ``python -m benchmarks [--quick] [NAME ...]`` (or ``make bench``)."""
