"""BLAS threads for the batch generator: ``generate_batch`` runs its matrix products on one BLAS
thread (threadpoolctl, imported on the first batch), restored afterwards; without threadpoolctl the
BLAS is left as it is. Why: docs/generation.md#speed.
"""

from __future__ import annotations

import contextlib
import sys

_controller = (
    None  # threadpoolctl.ThreadpoolController: the BLAS libraries loaded when it was built
)
_modules = -1  # len(sys.modules) then: a BLAS loaded later (SciPy's, JAX's) comes with new modules
_missing = False  # threadpoolctl is not installed


def limited(threads: int | None):
    """A context manager that runs its body with at most ``threads`` BLAS threads (None: unchanged)."""
    global _controller, _modules, _missing
    if threads is None or _missing:
        return contextlib.nullcontext()
    if _controller is None or len(sys.modules) != _modules:
        try:
            import threadpoolctl
        except ImportError:
            _missing = True
            return contextlib.nullcontext()
        # Listing the loaded libraries costs about 1 ms (docs/generation.md#speed): redone only
        # after new imports, which may have loaded another BLAS.
        _controller = threadpoolctl.ThreadpoolController()
        _modules = len(sys.modules)
    return _controller.limit(limits=int(threads), user_api="blas")


def blas_threads() -> list[int]:
    """The thread counts of the BLAS libraries loaded in this process ([] without threadpoolctl)."""
    try:
        import threadpoolctl
    except ImportError:
        return []
    return [
        int(i["num_threads"])
        for i in threadpoolctl.threadpool_info()
        if i.get("user_api") == "blas"
    ]
