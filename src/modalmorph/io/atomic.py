"""Atomic output: every file of modalmorph is written whole, every output folder too.

A file (:func:`atomic_write`) is written beside its destination and moved into place; a
folder (:func:`atomic_output_dir`) is built in a hidden sibling
``.NAME.modalmorph-tmp-PID-XXXX`` and renamed into place, so the destination is at every
instant the old complete folder, the new complete folder or absent. Temporary files and
folders left by killed runs are removed by the next run writing beside them
(:func:`remove_leftovers`).
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
from contextlib import contextmanager, suppress
from pathlib import Path

__all__ = ["OUTPUT_MARKER", "OUTPUT_MARKERS", "atomic_output_dir", "atomic_write",
           "remove_leftovers"]


# Temporary files and folders are hidden siblings named ".NAME.modalmorph-tmp-PID-XXXX";
# one whose process is gone was left by a killed run and is removed by the next writer.
_TMP_TAG = ".modalmorph-tmp-"
_LEFTOVER = re.compile(r"^\..*\.modalmorph-tmp-(\d+)-[\w-]+$")
# A folder that is replaced as a whole must be empty or hold one of these files (a previous
# result of morph or of track).
OUTPUT_MARKER = "result.json"
OUTPUT_MARKERS = (OUTPUT_MARKER, "track.json", "strain.json")
# Seconds to sleep just before the final rename(s): read only here, set only by the tests
# that kill a run at that moment.
_PAUSE_ENV = "MODALMORPH_TEST_RENAME_PAUSE"


def remove_leftovers(folder) -> list[Path]:
    """Remove the temporary files and folders that killed runs left in ``folder``.

    These are the hidden ``.NAME.modalmorph-tmp-PID-XXXX`` entries whose process ``PID``
    is no longer running (POSIX only; elsewhere nothing is removed). Returns what was
    removed.
    """
    if os.name != "posix":
        return []
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for entry in entries:
        found = _LEFTOVER.match(entry.name)
        if found is None or _alive(int(found.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            with suppress(FileNotFoundError):
                os.unlink(entry.path)
        removed.append(Path(entry.path))
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):  # another user's process; not a PID
        return True
    try:  # a killed process not yet reaped by its parent (a zombie) is dead too
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return fh.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except OSError:  # no /proc (macOS): trust kill(0)
        return True


def _temp_sibling(folder: Path, name: str) -> Path:
    """A new hidden temporary folder in ``folder``, named after ``name`` and this process."""
    remove_leftovers(folder)
    return Path(tempfile.mkdtemp(prefix=f".{name}{_TMP_TAG}{os.getpid()}-", dir=folder))


def _umask() -> int:
    """The process's umask, read without changing it where Linux tells it."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore (not thread-safe, but brief)
    os.umask(mask)
    return mask


def _follow_umask(folder: Path) -> None:
    """Give a folder made by :func:`tempfile.mkdtemp` (0700) the mode ``mkdir`` would."""
    os.chmod(folder, 0o777 & ~_umask())


def _pause_for_tests() -> None:
    seconds = os.environ.get(_PAUSE_ENV)
    if seconds:
        import time

        time.sleep(float(seconds))


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes
    import errno

    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # glibc < 2.28, musl
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # file system or kernel
        return False
    raise OSError(err, os.strerror(err), os.fspath(b))


@contextmanager
def atomic_write(path):
    """Write one file all or nothing: yield a temporary path beside it, then move it.

    The caller writes the file at the yielded path (same name, in a temporary sibling
    folder, so writers that add an extension see the right one). When the block ends
    normally, the file replaces ``path`` with :func:`os.replace` (atomic on one file
    system); when it raises, the temporary file is deleted and ``path`` is untouched.

    Examples
    --------
    >>> with atomic_write("out.npy") as tmp:  # doctest: +SKIP
    ...     np.save(tmp, array)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_dir = _temp_sibling(path.parent, path.name)
    try:
        tmp = tmp_dir / path.name
        yield tmp
        if not tmp.exists():
            raise ValueError(f"{os.fspath(path)}: nothing was written to the temporary "
                             f"file {os.fspath(tmp)}")
        os.replace(tmp, path)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


@contextmanager
def atomic_output_dir(final_dir):
    """Write a folder as a whole: yield a new temporary sibling folder to fill, then rename.

    On entry the destination is checked (a folder that exists must be empty or a previous
    output, holding one of :data:`OUTPUT_MARKERS`) and the temporary folder is created
    beside it: an unwritable destination fails here, before any work. Temporary folders of
    killed runs found there are removed (:func:`remove_leftovers`).

    When the block ends normally, the temporary folder becomes ``final_dir`` by one rename;
    an existing ``final_dir`` is swapped with it in one step (``renameat2`` with
    ``RENAME_EXCHANGE`` on Linux) or, where that is not supported, renamed aside first.
    So at every instant ``final_dir`` is the old complete folder, the new complete folder
    or (only in the fallback, between two renames) absent; the old one is deleted after,
    with every file of the previous run. Missing parent folders are created only then.
    When the block raises, the temporary folder is deleted and ``final_dir`` is left as
    it was.

    Raises
    ------
    ValueError
        If ``final_dir`` exists and is not a folder, is a folder holding other files, or
        its parent cannot be written. The message starts with ``final_dir`` as given.

    Examples
    --------
    >>> with atomic_output_dir("results") as tmp:  # doctest: +SKIP
    ...     save_result(morph, tmp)
    """
    name = os.fspath(final_dir)
    final = Path(os.path.abspath(final_dir))
    tmp = _staging_folder(final, name)
    try:
        yield tmp
        tmp = _put_in_place(tmp, final, name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _staging_folder(final: Path, name: str) -> Path:
    """Check the destination and create the temporary folder that will replace it."""
    if final.is_symlink() or (final.exists() and not final.is_dir()):
        raise ValueError(f"{name}: exists and is not a folder")
    if final.is_dir() and any(final.iterdir()) and not any(
            (final / marker).is_file() for marker in OUTPUT_MARKERS):
        raise ValueError(f"{name}: a folder with other files in it (no "
                         f"{' or '.join(OUTPUT_MARKERS)}); the output folder is replaced "
                         f"as a whole, so give a new or empty one")
    anchor = final.parent  # the nearest existing ancestor holds the temporary folder
    while not anchor.is_dir():
        if anchor.exists() or anchor.parent == anchor:
            raise ValueError(f"{name}: cannot create the folder: {anchor} is not a folder")
        anchor = anchor.parent
    try:
        return _temp_sibling(anchor, final.name or "out")
    except OSError as exc:
        raise ValueError(f"{name}: cannot write the output folder: cannot create a folder in "
                         f"{anchor} ({exc.strerror})") from None


def _put_in_place(tmp: Path, final: Path, name: str) -> Path:
    """Rename the finished ``tmp`` to ``final``; returns what is left to delete."""
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        _follow_umask(tmp)  # the user's umask, as a folder made by mkdir (mkdtemp: 0700)
        _pause_for_tests()
        if not final.is_dir():
            os.rename(tmp, final)
            return tmp
        if _exchange(tmp, final):
            return tmp  # tmp now holds the old folder
        old = tmp.with_name(tmp.name + "-old")
        os.rename(final, old)
        _pause_for_tests()
        os.rename(tmp, final)
        return old
    except OSError as exc:
        raise ValueError(f"{name}: cannot move the output folder into place "
                         f"({exc.strerror})") from None

