"""The one numba decorator the kernel modules use, with the project's compile options."""

import llvmlite.binding as _llvm
from numba import njit as _njit

# never 'nnan'/'ninf': the stability guard needs its NaN checks
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

# LLVM's loop vectoriser gives up on a loop that would need more than 8 runtime checks that
# its arrays do not overlap ("too many memory checks needed"). numba cannot tell LLVM that
# two arrays never alias, and the kernel's element loops read and write a dozen array rows
# each, so with the default some of them ran scalar (n = 400 without contact: 13.2 µs per
# step before raising the limits, 9.4 after, same results to round-off). The limits are
# process-wide LLVM options; they only let more loops vectorise. LLVM accepts an unknown
# option silently, and numba's disk cache does not key on them: after changing these,
# delete the __pycache__ folders under rodphase/rod.
for _option in ("-runtime-memory-check-threshold=512", "-vectorize-memory-check-threshold=512"):
    _llvm.set_option("rodphase", _option)


def njit(*args, **kwargs):
    # error_model="numpy": no zero-division checks inside loops, so LLVM can vectorise them
    kwargs.setdefault("error_model", "numpy")
    return _njit(*args, **kwargs)
