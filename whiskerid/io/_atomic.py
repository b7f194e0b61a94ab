"""Atomic writes: a file, or a folder of files, appears whole or not at all.

Everything is written to a temporary name in the destination's own folder (the same file
system, so the final rename is atomic), flushed to disk, and renamed over the destination
only when complete. A full disk or a crash therefore leaves the old file as it was, never
a file cut mid-line. No JAX here: the Raspberry Pi side writes through this module too.
"""

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


class WriteError(OSError):
    """An output could not be written; the message names the file, the old one is intact."""


def _write_error(path: Path, err: OSError) -> WriteError:
    reason = err.strerror or str(err) or type(err).__name__
    hint = "" if err.errno == errno.EEXIST else " (free some space or choose another place)"
    new = WriteError(f"could not write {path}: {reason}; nothing was replaced{hint}")
    new.errno = err.errno
    return new


def fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened)."""
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


#: Outputs that must not exist when published (resolved paths): a command refused them if
#: they existed, so one that appears meanwhile (another process) is not overwritten.
_EXPECTED_NEW: set[Path] = set()


def expect_new(path: str | Path) -> None:
    """Publish ``path`` only if it still does not exist then (:func:`atomic_path`)."""
    _EXPECTED_NEW.add(Path(path).absolute())


def clear_expected() -> None:
    """Forget :func:`expect_new`'s paths (a new command starts)."""
    _EXPECTED_NEW.clear()


def _publish(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` over ``path``; for an expected-new path, only if it is still absent,
    atomically (a hard link fails if the name exists, where a rename would replace it)."""
    if path.absolute() not in _EXPECTED_NEW:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(
            errno.EEXIST,
            "it appeared while this command ran (another process wrote it?); "
            "run again with --force to replace it",
        ) from None
    except OSError:  # no hard links here (some FUSE, FAT): create-exclusive, then rename
        os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        os.replace(tmp, path)
        return
    tmp.unlink()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path to write ``path``'s new content to; renamed over it on success.

    On an exception the temporary file is removed and ``path`` is left as it was; an
    :class:`OSError` becomes a :class:`WriteError` naming ``path``.

    Example:
        >>> with atomic_path("out.csv") as tmp:  # doctest: +SKIP
        ...     tmp.write_text("t,x\\n")
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as err:
        raise _write_error(path, err) from err
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        if path.exists():  # keep the old file's permissions
            shutil.copymode(path, tmp)
        else:
            os.chmod(tmp, 0o666 & ~_umask())
        _publish(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise _write_error(path, err) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_folder(path.parent)


def atomic_write(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` atomically; returns ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)
    return path


@contextlib.contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """A temporary folder to fill with ``path``'s new files; put in its place on success.

    A new folder appears by one rename. An existing one is set aside, the new one renamed
    into its place, and the files of the old one that the new one lacks are moved across
    (they are not ours to delete) before the old one is removed: at every moment ``path``
    holds either the complete old set of files or the complete new one.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as err:
        raise _write_error(path, err) from err
    try:
        yield tmp
        for f in tmp.iterdir():
            with open(f, "rb+") as fh:
                os.fsync(fh.fileno())
        os.chmod(tmp, 0o777 & ~_umask())
        if path.absolute() in _EXPECTED_NEW and path.exists():
            raise FileExistsError(errno.EEXIST, "it appeared while this command ran")
        if path.is_dir():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            os.replace(path, old / path.name)
            try:
                os.replace(tmp, path)
            except OSError:
                os.replace(old / path.name, path)  # put the old folder back
                raise
            for f in (old / path.name).iterdir():
                if not (path / f.name).exists():
                    os.replace(f, path / f.name)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except OSError as err:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _write_error(path, err) from err
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    fsync_folder(path.parent)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
