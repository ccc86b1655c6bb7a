"""The one numba decorator the kernel modules use, with the project's compile options."""

from numba import njit as _njit

# never 'nnan'/'ninf': the stability guard needs its NaN checks
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


def njit(*args, **kwargs):
    # error_model="numpy": no zero-division checks inside loops, so LLVM can vectorise them
    kwargs.setdefault("error_model", "numpy")
    return _njit(*args, **kwargs)
