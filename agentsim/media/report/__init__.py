"""An HTML report of a run that a researcher watches and hears: audio, a 3D skeleton, a timeline and the
per-gesture error table, on the run's one time axis, opened from ``file://`` with no network.

:func:`write_report` (in :mod:`~agentsim.media.report.page`) writes the page and its folder;
:mod:`~agentsim.media.report.data` builds what the page is given; :mod:`~agentsim.media.report.browser`
opens a report in headless Chromium over the DevTools protocol (screenshots, the page's ``window.report``
API). three.js is vendored in ``vendor/`` by ``scripts/vendor_three.sh``.
"""

from agentsim.media.report.page import write_report

__all__ = ["write_report"]
