"""Contact detection on the external wrench."""
from .detector import ContactDetector, Detection, chi2_isf6, chi2_sf6
from .joint import JointDetector, chi2_isf, chi2_sf

__all__ = ["ContactDetector", "Detection", "JointDetector", "chi2_isf", "chi2_isf6", "chi2_sf", "chi2_sf6"]
