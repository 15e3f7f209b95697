"""The application: rig start-up, the monitor session, the calibration wizard, evaluation against
ground truth, the live view."""
