"""One-command scans: a scan file → projections → FDK → labels (docs/scan.md), and the metrics
that compare a scan with another (docs/compare.md).

The orchestration layer: it may import every stage and no stage imports it; it runs without the
command line (``xr.scan``), which stays a thin layer on top (``xrayraster scan``).
"""

from .compare import Comparison, compare
from .scan import ScanResult, check_scan_output, scan
from .scan_file import ScanFile, ScanOptions, load_scan_file

__all__ = ["Comparison", "ScanFile", "ScanOptions", "ScanResult", "compare", "check_scan_output", "load_scan_file", "scan"]
