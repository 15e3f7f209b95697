"""Contact detection on the external wrench."""
from .detector import ContactDetector, Detection, chi2_isf6, chi2_sf6

__all__ = ["ContactDetector", "Detection", "chi2_isf6", "chi2_sf6"]
