"""What can go wrong when a function is lowered to C; the callers then take XLA."""

from __future__ import annotations

__all__ = ["CKernelError", "CKernelTranslationError", "CKernelWarning"]


class CKernelError(RuntimeError):
    """The function cannot be lowered to C or the C compiler failed."""


class CKernelWarning(RuntimeWarning):
    """A C kernel was built but not trusted (it disagrees with XLA, or its cached library is not
    safely ours): the caller falls back to XLA."""


class CKernelTranslationError(CKernelError):
    """The function's jaxpr has a form the translation does not know (a primitive, a parameter, a
    structure from a newer JAX): not a fault of the function, XLA runs it as it is."""
