"""The dataset doctor: a user's own data checked before the GPU time.

``tools/analysis_tools/check_dataset.py CONFIG`` runs it; the library
behind it checks, per sample and over the split, one family per module:
:mod:`.calibration` (and :mod:`.edge_alignment`), :mod:`.labels_lidar`
(and :mod:`.grid`), :mod:`.masks`, :mod:`.sequence` and
:mod:`.class_histogram`; :mod:`.pictures` draws a sample, :mod:`.report`
writes the markdown and JSON report, :mod:`.doctor` runs everything.
"""
from .doctor import CHECKS, DoctorReport, run_doctor, sample_indices
from .report import write_report
from .verdict import FAIL, PASS, SKIP, WARN, CheckResult, CheckSummary

__all__ = [
    'CHECKS', 'CheckResult', 'CheckSummary', 'DoctorReport', 'FAIL', 'PASS',
    'SKIP', 'WARN', 'run_doctor', 'sample_indices', 'write_report'
]
