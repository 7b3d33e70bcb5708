"""One-command scans: a scan file → projections → FDK → labels (docs/scan.md).

The orchestration layer: it may import every stage and no stage imports it; it runs without the
command line (``xr.scan``), which stays a thin layer on top (``xrayraster scan``).
"""

from .scan import ScanResult, is_scan_output, scan
from .scan_file import ScanFile, ScanOptions, load_scan_file

__all__ = ["ScanFile", "ScanOptions", "ScanResult", "is_scan_output", "load_scan_file", "scan"]
