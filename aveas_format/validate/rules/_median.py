"""The median of each run of a segmented array, compiled (numba, the ``jit`` extra): one
selection per segment (numba's ``np.median``: quickselect, O(n)) instead of sorting the whole
array by segment and value. The NumPy path (:func:`.uncertainty.seg_median`) is the reference and
the fallback; both give the same numbers (the middle value, or the mean of the two middle values
as ``0.5 * (a + b)``, which is ``(a + b) / 2`` exactly). Imported only where
:func:`aveas_format.numeric.kernel_backend` picks numba; compiled once per environment and
cached next to this module.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def segment_medians(values, starts, ends):
    """The median of ``values[starts[k]:ends[k]]`` for every k (no NaN in them)."""
    out = np.empty(starts.size)
    for k in range(starts.size):
        out[k] = np.median(values[starts[k]:ends[k]])
    return out
