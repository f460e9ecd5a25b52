"""Atomic writes: a file appears whole or not at all."""

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def _atomic_path(path, suffix=""):
    """Yield a temporary path beside ``path``; move it onto ``path`` if the block succeeds.

    The temporary file is created (empty) in the folder of ``path`` with the given suffix,
    so writers that choose a format by extension (Open3D) can write to it. On success it
    is fsynced and renamed onto ``path`` with :func:`os.replace` (atomic on POSIX and
    Windows); on any error it is removed and the error propagates.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise FileNotFoundError(f"{path}: cannot write, folder {str(folder)!r} does not exist.")
    if path.is_dir():
        raise ValueError(f"{path}: cannot write, it is a folder.")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=suffix or ".tmp")
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, _file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def _file_mode(path):
    """The mode of the file being replaced, else the usual ``0o666`` less the umask.

    ``mkstemp`` creates private (``0o600``) files, which would otherwise end up as the
    written file's mode.
    """
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _fsync_folder(folder):
    """Make the rename durable where the platform allows fsync on a folder (POSIX)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path, mode="wb"):
    """Open a file for writing so that ``path`` appears whole or not at all.

    The data go to a temporary file in the same folder as ``path``; when the ``with``
    block ends without error the file is flushed, fsynced and renamed onto ``path`` with
    :func:`os.replace`, which replaces any previous file in one step. When the block
    raises, the temporary file is removed, ``path`` is left as it was, and the error
    propagates.

    Parameters
    ----------
    path : str or path-like
        The file to write. Its folder must exist.
    mode : {"wb", "w"}, default="wb"
        Binary or text (UTF-8) writing.

    Yields
    ------
    file : file object
        Open for writing.

    Raises
    ------
    FileNotFoundError
        If the folder of ``path`` does not exist.
    ValueError
        If ``mode`` is not a writing mode or ``path`` is a folder.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import atomic_write
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "notes.txt"
    ...     with atomic_write(path, "w") as f:
    ...         _ = f.write("all or nothing")
    ...     print(path.read_text(), sorted(p.name for p in Path(folder).iterdir()))
    all or nothing ['notes.txt']
    """
    if mode not in ("wb", "w", "wt"):
        raise ValueError(f"mode must be 'wb' (binary) or 'w' (text); got {mode!r}.")
    with _atomic_path(path, suffix=".tmp") as tmp:
        text = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        handle = open(tmp, "wb" if "b" in mode else "w", **text)  # noqa: SIM115 - closed below
        try:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        finally:
            handle.close()
