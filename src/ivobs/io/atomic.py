"""Atomic writes: every file ivobs writes goes to a temporary file in the same folder and is
then renamed, so that a crash or an error never leaves a half-written file behind.

A leaf module (it imports nothing of ivobs but its errors): the result and plot modules use it
without importing the estimators.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

from ..errors import IvobsError

__all__ = [
    "atomic_path",
    "check_distinct",
    "check_output_path",
    "same_file",
    "write_error",
    "write_text_atomic",
]


def _file_mode(path: Path) -> int:
    """The mode a plain ``open(path, "w")`` gives: the existing file's, else ``0o666`` less the
    umask (``tempfile.mkstemp`` creates ``0o600`` files)."""
    with contextlib.suppress(OSError):
        return stat.S_IMODE(path.stat().st_mode)
    return 0o666 & ~_umask()


def _umask() -> int:
    """The process umask: from ``/proc/self/status`` where it exists (reading it with
    ``os.umask`` sets it for a moment, which other threads creating files could see)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output_path(path: str | os.PathLike[str], what: str | None = None) -> Path:
    """Check that ``path`` can be written as a file (its folder exists, it is no folder itself),
    before any work is done. ``what`` names the argument in the error (e.g. ``"--csv"``)."""
    path = Path(path)
    prefix = f"{what}: " if what else ""
    folder = path.parent if str(path.parent) else Path(".")
    if str(path) in ("", "."):
        raise IvobsError(f"{prefix}expected a file name, got {str(path)!r}")
    if path.is_dir():
        raise IvobsError(f"{prefix}{str(path)!r} is a directory; expected a file name")
    if not folder.is_dir():
        why = "is not a directory" if folder.exists() else "does not exist"
        raise IvobsError(f"{prefix}cannot write {str(path)!r}: the folder {str(folder)!r} {why}")
    if not os.access(folder, os.W_OK):
        raise IvobsError(f"{prefix}cannot write {str(path)!r}: the folder is not writable")
    return path


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name the same file: by device and inode when both exist (symbolic and
    hard links included), else by their resolved paths (symbolic links followed)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, RuntimeError):  # pragma: no cover - a symbolic link loop
        return os.path.abspath(a) == os.path.abspath(b)


def check_distinct(
    outputs: Mapping[str, str | os.PathLike[str] | None],
    inputs: Mapping[str, str | os.PathLike[str] | None] | None = None,
) -> None:
    """Refuse an output that is the same file as an input, or as another output (also through
    symbolic or hard links), before anything is written. Keys name the options (``"--out"``,
    ``"--log"``); ``None`` values are skipped."""
    outs = [(k, v) for k, v in outputs.items() if v is not None and str(v) != ""]
    ins = [(k, v) for k, v in (inputs or {}).items() if v is not None and str(v) != ""]
    for i, (name, path) in enumerate(outs):
        for other, src in ins:
            if same_file(path, src):
                raise IvobsError(
                    f"{name}, {other}: {str(path)!r} is the input {other} ({str(src)!r}); "
                    f"writing {name} there would overwrite it: give another file for {name}"
                )
        for other, dst in outs[i + 1 :]:
            if same_file(path, dst):
                raise IvobsError(
                    f"{name}, {other}: both write {str(path)!r}; give two different files"
                )


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix); rename it to ``path`` on success,
    delete it on any error. Readers never see a half-written file. The file gets the mode a
    plain ``open(path, "w")`` would give (the umask's, or the replaced file's).

    An operating-system error while writing (a full disk, a quota, a folder removed) raises
    :class:`~ivobs.IvobsError` naming the file and saying that its previous version, if any,
    is intact (the rename never happened)."""
    path = check_output_path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(
            dir=folder, prefix=f".{path.name}.", suffix=path.suffix or ".tmp"
        )
    except OSError as exc:
        raise IvobsError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    os.close(fd)
    try:
        os.chmod(tmp, _file_mode(path))
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise write_error(path, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_error(path: Path, exc: OSError) -> IvobsError:
    """The error of a write that failed (``exc``) before the rename: nothing was replaced."""
    before = (
        "its previous version is intact"
        if path.exists()
        else "nothing was written there (no file existed before)"
    )
    return IvobsError(f"cannot write {str(path)!r}: {exc.strerror or exc}; {before}")


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file, then rename)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
