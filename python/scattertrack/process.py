"""Settings of the ``scattertrack`` process itself (not applied when the package is imported as a library).

:func:`prefer_small_pages` turns transparent huge pages off for the
process. ``track`` allocates its batch arrays afresh for every 0.2 s batch
(numpy columns, the engine's rows, the formatted text); with huge pages
each fresh 2 MB region is zeroed whole on its first touch, which on the
10,000-tag recordings cost 4–8 % of the CPU (``clear_page_erms``) and
5–6 s of the 60 s recording's 15 s of system time; with 4 kB pages the
run is about 5 % faster and its peak RSS 0.1 GB lower
(docs/notes/glac-many-tags-cost.md, "Page faults").
"""

from __future__ import annotations

import ctypes
import sys

PR_SET_THP_DISABLE = 41
"""``prctl`` option (linux/prctl.h): no transparent huge pages for this process and its children."""


def prefer_small_pages() -> bool:
    """Ask Linux for 4 kB pages for the rest of this process; False where that is not possible (harmless)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
