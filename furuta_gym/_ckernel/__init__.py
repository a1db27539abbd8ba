"""A small JAX function lowered to C and compiled with the system's C compiler.

Why: one XLA:CPU execution has a fixed cost per call and per kernel, whatever the arithmetic, and
a single learned-model env step (one RK4 step of a small DeLaN, many tiny operations) spends most
of its time there. The same program written out as one C function avoids both (docs/envs.md and
BENCHMARKS.md have the numbers).

The spine is unchanged: JAX still derives the dynamics (forward dynamics by autodiff of the
Lagrangian, the integrator), and :class:`CKernel` only translates the resulting jaxpr, primitive by
primitive, with every shape static. Nothing is re-derived by hand; a primitive this package does
not know is one clear error naming it.

The translation keeps XLA's arithmetic (float64, no fast-math, NaN propagating through
max/min/sign; only a dot product's sum may be split into SIMD lanes, as XLA's own blocked sums
are) so results agree with the jitted function to round-off; the tests compare them. Equal
subexpressions are computed once and values known before the step runs (index arithmetic) are
folded by JAX itself. Shared libraries are cached on disk by a hash of the C source and the
compiler command.

Nothing is trusted blindly: every new kernel is run against XLA on the example inputs and a few
random ones near them, and one that disagrees is refused (a :class:`CKernelWarning`, then XLA);
a primitive parameter the translation does not implement is refused, not ignored. The cache
directory is made 0700 and a library is loaded only when it and its directory belong to this
user and are not group- or world-writable (loading a library runs its code); a lock makes
concurrent workers compile a kernel once, and only the newest :data:`.cache.MAX_CACHED_KERNELS` are
kept. POSIX only: on Windows, or without a working compiler, the callers take XLA. A form of
jaxpr the translation does not know (a new primitive or parameter, a structure from a newer JAX)
is a :class:`CKernelTranslationError`, on which an env takes XLA with one warning.

The package's parts: :mod:`.translate` (a jaxpr to C source: the jaxpr walk, on
:mod:`.c_syntax`, :mod:`.primitive_params`, :mod:`.c_writer` and one ``ops_*`` module per family
of primitives), :mod:`.cache` (the compiler and the on-disk cache of compiled libraries) and
:mod:`.kernel` (:class:`CKernel`: trace, translate, build, check against XLA, call). The env uses
only the names exported here.
"""

from .cache import c_compiler
from .errors import CKernelError, CKernelTranslationError, CKernelWarning
from .kernel import CKernel

__all__ = ["CKernel", "CKernelError", "CKernelTranslationError", "CKernelWarning", "c_compiler"]
