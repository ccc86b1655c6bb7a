"""The one numba decorator the kernel modules use, with the project's compile options and cache key."""

import hashlib
from pathlib import Path

import llvmlite.binding as _llvm
from numba import njit as _njit
from numba.core.caching import FunctionCache as _FunctionCache

# never 'nnan'/'ninf': the stability guard needs its NaN checks
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

# LLVM's loop vectoriser gives up on a loop that would need more than 8 runtime checks that
# its arrays do not overlap ("too many memory checks needed"). numba cannot tell LLVM that
# two arrays never alias, and the kernel's element loops read and write a dozen array rows
# each, so with the default some of them ran scalar (n = 400 without contact: 13.2 µs per
# step before raising the limits, 9.4 after, same results to round-off). The limits are
# process-wide LLVM options; they only let more loops vectorise. LLVM accepts an unknown
# option silently. They are part of the cache key (KERNEL_SOURCE_HASH).
LLVM_OPTIONS = ("-runtime-memory-check-threshold=512", "-vectorize-memory-check-threshold=512")
for _option in LLVM_OPTIONS:
    _llvm.set_option("rodphase", _option)

# The modules whose source ends up in the compiled kernel. numba keys a function's disk cache
# on its own file and bytecode only, so an edit of contact.py (or of the options above) alone
# would leave kernel.advance running the old machine code from its cache, silently; the same
# for a user who upgrades in place. Every cached function of these modules is keyed on the
# hash of all of them instead (tests/test_kernel_cache.py). result.py holds the history
# table the kernel's slot indices come from. Paths are relative to the package.
KERNEL_MODULES = ("rod/_jit.py", "rod/kernel.py", "rod/contact.py", "rod/rotation.py",
                  "rod/neo_hookean.py", "rod/static.py", "result.py")


def _kernel_source_hash() -> str:
    digest = hashlib.sha256()
    package = Path(__file__).resolve().parent.parent
    for name in KERNEL_MODULES:
        digest.update(name.encode())
        digest.update((package / name).read_bytes())
    digest.update("\n".join(LLVM_OPTIONS).encode())
    return digest.hexdigest()


KERNEL_SOURCE_HASH = _kernel_source_hash()


class _KernelCache(_FunctionCache):
    """numba's per-function disk cache, with the kernel modules' source hash in the index key."""

    def _index_key(self, sig, codegen):
        return super()._index_key(sig, codegen) + (KERNEL_SOURCE_HASH,)


def _cached(dispatcher):
    # what Dispatcher.enable_caching does, with the key above
    dispatcher._cache = _KernelCache(dispatcher.py_func)
    return dispatcher


def njit(*args, **kwargs):
    # error_model="numpy": no zero-division checks inside loops, so LLVM can vectorise them
    kwargs.setdefault("error_model", "numpy")
    cache = kwargs.pop("cache", False)
    if args and callable(args[0]):  # @njit used bare
        dispatcher = _njit(*args, **kwargs)
        return _cached(dispatcher) if cache else dispatcher
    decorate = _njit(*args, **kwargs)
    return (lambda func: _cached(decorate(func))) if cache else decorate
