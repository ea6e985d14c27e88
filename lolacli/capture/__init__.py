"""Capture reading (pcap, pcapng; streaming) and analysis.

``analyze_file(path, eni=None, progress=None, ...) -> CaptureReport`` is the entry point;
``CaptureReport.to_dict()`` follows the ``lolacli.capture/1`` JSON contract. numpy is
imported only when :func:`analyze_file` is called.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lolacli.capture.analyze import CaptureReport

__all__ = ["analyze_file"]


def analyze_file(path: Any, **kwargs: Any) -> CaptureReport:
    """See :func:`lolacli.capture.analyze.analyze_file`."""
    from lolacli.capture.analyze import analyze_file as _analyze

    return _analyze(path, **kwargs)
