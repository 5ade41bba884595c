"""Regenerate ``driven_csf8.csv`` alone (and its key of ``truth.json``; the other keys are
kept) from :func:`hdid.reference.logs.make_driven_log`, deterministically::

    python data/synthetic/driven.py

``python data/synthetic/generate.py`` regenerates it with every other shipped log.
"""

from generate import _HERE, build_driven, report_driven

if __name__ == "__main__":
    report_driven(build_driven(_HERE))
