"""Compensation: raw sensor wrench -> external contact wrench."""
from .pipeline import Compensator

__all__ = ["Compensator"]
