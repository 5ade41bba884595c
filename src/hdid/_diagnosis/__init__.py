"""Diagnosis: candidates from the effects' registry, refits, verdicts and their calibrated false-alarm rates."""
