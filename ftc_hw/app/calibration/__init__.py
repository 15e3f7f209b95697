"""Calibration and identification: the bench wizard (``ftc calibrate``) and its device session,
``ftc identify`` and the planned excitation driven through the arm, their fits drawn to a PNG."""
