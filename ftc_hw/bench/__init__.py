"""Benchmarks (``ftc bench ...``): each prints a table and writes its figures as JSON."""
