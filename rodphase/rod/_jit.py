"""The one numba decorator the kernel modules use, with the project's compile options."""

import llvmlite.binding as _llvm
from numba import njit as _njit

# never 'nnan'/'ninf': the stability guard needs its NaN checks
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

# LLVM's loop vectoriser gives up on a loop that would need more than 8 runtime checks that
# its arrays do not overlap ("too many memory checks needed"). numba cannot tell LLVM that
# two arrays never alias, and the kernel's loops read and write a dozen array rows each (the
# contact force pass: 28 rows in, 8 out), so with the default they run scalar at about half
# the speed. The limits are process-wide LLVM options; they only let more loops vectorise.
for _option in ("-runtime-memory-check-threshold=512", "-vectorize-memory-check-threshold=512"):
    _llvm.set_option("rodphase", _option)


def njit(*args, **kwargs):
    # error_model="numpy": no zero-division checks inside loops, so LLVM can vectorise them
    kwargs.setdefault("error_model", "numpy")
    return _njit(*args, **kwargs)
