"""Core types shared by every layer: status codes, errors, the RangeScan currency."""
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan

__all__ = ["Status", "RangesimError", "RangeScan"]
