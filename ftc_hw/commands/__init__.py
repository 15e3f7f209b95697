"""Implementations of the ``ftc`` subcommands."""
