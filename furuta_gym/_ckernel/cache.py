"""The C compiler and the on-disk cache of compiled kernels.

Libraries are cached by a hash of the C source and the compiler command, in a private (0700)
directory; one is loaded only when it and its directory belong to this user and are not group-
or world-writable (loading a library runs its code). A lock makes concurrent workers compile a
kernel once, and only the newest :data:`MAX_CACHED_KERNELS` are kept.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import hashlib
import os
import shlex
import shutil
import stat
import subprocess
import tempfile
import warnings
from pathlib import Path

from .._paths import cache_root
from .errors import CKernelError, CKernelWarning

__all__ = ["c_compiler", "require_compiler", "compile_and_load", "is_verified", "mark_verified"]


def _compiler_command() -> list[str] | None:
    """``$CC`` (or ``cc``) as a command line, its program resolved on PATH; None when absent.
    Parsed as a shell would: ``CC="ccache gcc"`` is a launcher and its compiler."""
    try:
        words = shlex.split(os.environ.get("CC") or "cc")
    except ValueError:  # unbalanced quotes: no usable command
        return None
    program = shutil.which(words[0]) if words else None
    return None if program is None else [program, *words[1:]]


def c_compiler() -> str | None:
    """The C compiler command used (``$CC`` or ``cc``), or None when there is none on PATH."""
    command = _compiler_command()
    return None if command is None else shlex.join(command)


def require_compiler() -> list[str]:
    """The compiler command, or the CKernelError saying why there is none (checked before the
    step is translated: no work is wasted on a machine that cannot build it)."""
    if os.name == "nt":  # the cache's ownership checks and the flags below are POSIX-only
        raise CKernelError(
            "the C kernel is built on POSIX systems only (not on Windows); kernel='xla' works everywhere"
        )
    command = _compiler_command()
    if command is None:
        raise CKernelError(
            f"kernel='c' needs a C compiler: none found as {os.environ.get('CC', 'cc')!r} on PATH "
            "(install gcc or clang, or set CC); kernel='xla' needs none"
        )
    return command


#: compiled kernels kept in a cache directory (the most recently used); older ones are removed
MAX_CACHED_KERNELS = 64

_CFLAGS = ("-O2", "-std=c99", "-shared", "-fPIC", "-fno-math-errno", "-fopenmp-simd")


def _untrusted(path: Path, directory: bool) -> str | None:
    """Why ``path`` may have been written by someone else (so loading code from it would run
    their code), or None. POSIX: ours, not a symbolic link, not group- or world-writable."""
    info = os.lstat(path)
    if stat.S_ISLNK(info.st_mode):
        return "is a symbolic link"
    if directory != stat.S_ISDIR(info.st_mode) or (not directory and not stat.S_ISREG(info.st_mode)):
        return "is not a " + ("directory" if directory else "regular file")
    if info.st_uid != os.getuid():
        return f"is owned by uid {info.st_uid}, not by this user (uid {os.getuid()})"
    if info.st_mode & 0o022:
        return f"is group- or world-writable (mode {stat.S_IMODE(info.st_mode):o})"
    return None


def _usable_dir(path: Path) -> bool:
    """Make ``path`` (mode 0700) if needed; True when it is ours, private and writable."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileExistsError):
            path.mkdir(mode=0o700)
        info = os.lstat(path)
        if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and info.st_mode & 0o077:
            os.chmod(path, 0o700)  # ours, made loose by an older version: tighten, keep the kernels
        problem = _untrusted(path, directory=True)
        if problem:
            warnings.warn(f"not using the C kernel cache {path}: it {problem}", CKernelWarning, stacklevel=4)
            return False
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):  # unique: no race on the name
            pass
        return True
    except OSError:  # read-only or missing home, full disk
        return False


_PRIVATE_DIR: Path | None = None


def _private_dir() -> Path:
    """A fresh directory only this process knows (mkdtemp: 0700, unpredictable name), removed at
    exit: the last resort when no shared cache directory can be trusted."""
    global _PRIVATE_DIR
    if _PRIVATE_DIR is None:
        _PRIVATE_DIR = Path(tempfile.mkdtemp(prefix="furuta_gym_c_kernels_"))
        atexit.register(shutil.rmtree, _PRIVATE_DIR, ignore_errors=True)
    return _PRIVATE_DIR


def _cache_dir() -> Path:
    for path in (
        cache_root() / "c_kernels",
        Path(tempfile.gettempdir()) / f"furuta_gym_c_kernels_{os.getuid()}",
    ):  # read-only home
        if _usable_dir(path):
            return path
    return _private_dir()


@contextlib.contextmanager
def _locked(directory: Path):
    """Hold the cache directory's lock: concurrent workers wanting the same kernel compile it
    once (the others wait, then find it). Without fcntl there is no lock, only duplicate work."""
    try:
        import fcntl  # noqa: PLC0415  POSIX only: elsewhere no lock
    except ImportError:
        yield
        return
    try:
        fd = os.open(directory / ".lock", os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
    except OSError:  # no lock file possible: correct still (atomic replace), maybe duplicate work
        yield
        return
    try:
        with contextlib.suppress(OSError):  # a file system without flock (some NFS): as above
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def _evict(directory: Path, keep: int | None = None) -> None:
    """Keep the ``keep`` most recently used kernels (a hit refreshes its mtime). A library a
    running process has loaded stays mapped in it after removal."""
    keep = MAX_CACHED_KERNELS if keep is None else keep
    kernels = sorted(directory.glob("kernel_*.so"), key=_mtime, reverse=True)
    for old in kernels[keep:]:
        for path in (old, old.with_suffix(".verified")):
            with contextlib.suppress(OSError):
                path.unlink()


def _compiler_works(command: list[str], directory: Path) -> bool:
    """Whether ``command`` compiles a trivial file (a stub ``cc``, as on a Mac without the
    command line tools, does not)."""
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        c_file = Path(tmp) / "trial.c"
        c_file.write_text("int fg_trial(int x) { return x + 1; }\n")
        try:
            result = subprocess.run(
                [*command, *_CFLAGS, str(c_file), "-o", str(Path(tmp) / "trial.so")], capture_output=True, timeout=120
            )
        except (OSError, subprocess.SubprocessError):
            return False
        return result.returncode == 0


def _build(command: list[str], source: str, directory: Path, library: Path) -> None:
    cc = shlex.join(command)
    try:
        with tempfile.TemporaryDirectory(dir=directory) as tmp:
            c_file = Path(tmp) / "kernel.c"
            c_file.write_text(source)
            partial = Path(tmp) / "kernel.so"
            result = subprocess.run(
                [*command, *_CFLAGS, str(c_file), "-o", str(partial), "-lm"],
                capture_output=True,
                text=True,
                timeout=600,
            )
            if result.returncode != 0:
                # tell a broken compiler from a kernel it rejects
                why = (
                    ""
                    if _compiler_works(command, directory)
                    else " (it fails on a trivial test file too: not a working C compiler)"
                )
                raise CKernelError(f"the C compiler {cc} failed on the generated kernel{why}:\n{result.stderr[-2000:]}")
            os.chmod(partial, 0o700)
            os.replace(partial, library)  # atomic: a process without the lock sees all of it or none
    except (OSError, subprocess.SubprocessError) as exc:
        raise CKernelError(f"compiling the C kernel with {cc} failed: {type(exc).__name__}: {exc}") from exc


def compile_and_load(source: str) -> tuple[Path, ctypes.CDLL]:
    """The kernel's library (cached by a hash of the source and the compiler command), checked
    to be ours and private before it is loaded: loading a library runs its code."""
    command = require_compiler()
    digest = hashlib.sha256((" ".join([*command, *_CFLAGS]) + "\n" + source).encode()).hexdigest()[:24]
    directory = _cache_dir()
    library = directory / f"kernel_{digest}.so"
    with _locked(directory):
        if os.path.lexists(library):
            with contextlib.suppress(OSError):
                os.utime(library, follow_symlinks=False)  # recently used: eviction keeps it
        else:
            _build(command, source, directory, library)
            _evict(directory)
        try:
            problem = _untrusted(library, directory=False)
        except OSError as exc:  # removed under us by a process that ignored the lock
            raise CKernelError(f"the compiled C kernel {library} vanished: {exc}") from exc
        if problem:
            message = f"refusing to load the cached C kernel {library}: it {problem}; XLA steps this model"
            warnings.warn(message, CKernelWarning, stacklevel=4)
            raise CKernelError(message)
        try:
            return library, ctypes.CDLL(str(library))
        except OSError as exc:
            raise CKernelError(f"loading the compiled C kernel {library} failed: {exc}") from exc


#: library file names already checked against XLA in this process (same source, same function)
_VERIFIED: set[str] = set()


def _verified_on_disk(marker: Path) -> bool:
    try:
        return _untrusted(marker, directory=False) is None
    except OSError:  # none
        return False


def is_verified(library: Path) -> bool:
    """Whether ``library`` was checked against XLA: in this process, or marked on disk."""
    return library.name in _VERIFIED or _verified_on_disk(library.with_suffix(".verified"))


def mark_verified(library: Path) -> None:
    """Record that ``library`` agrees with XLA (for this process and, if possible, on disk)."""
    with contextlib.suppress(OSError):
        library.with_suffix(".verified").touch()
    _VERIFIED.add(library.name)
