"""The one atomic writer: every output of this package is written here, all or nothing.

A run writes its files into a hidden temporary folder beside the targets, named
``.swa-imesh-<pid>@<host>-<random>`` after the process that owns it, then publishes them:

- without ``force``, each file is hard-linked onto its target name (``link`` fails if the
  name exists, whoever made it in the meantime) and a store folder is published by
  creating the target folder first (``mkdir`` fails the same way) and renaming onto that
  empty folder; on a file system without hard links a file claims its name with an
  exclusive create (``O_EXCL``) before it is renamed onto it. Targets are published in
  the order of their absolute paths, so of two runs wanting the same names exactly one
  gets them all. If any target appeared while the run was working, the targets this run
  already published (the very same file, by inode) are removed again and the run is
  refused;
- with ``force``, each file is renamed over its target (a replaced store is set aside
  first, then removed).

On any exception the temporary folder is removed. A run stopped by SIGKILL cannot clean
up: the next run writing into the same folder removes temporary folders of this program
whose owner process, on this host and of this user, is no longer alive (never one of a
live process). A full disk (``ENOSPC``/``EDQUOT``, also when a library wraps it) becomes
one sentence naming the folder.
"""

from __future__ import annotations

import errno
import io
import os
import re
import shutil
import signal
import socket
import stat
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

__all__ = ["check_writable", "atomic_write", "is_store", "hdf5_file", "scratch_folder",
           "remove_stale_temporaries", "TEMP_PREFIX"]

TEMP_PREFIX = ".swa-imesh-"
_UMASK_LOCK = threading.Lock()
_MB = 1024 * 1024


def _host() -> str:
    """The name of this host, and on Linux its process-id namespace: a container sharing the
    host name and the folder counts pids apart, so its folders are never judged here."""
    name = re.sub(r"[^A-Za-z0-9.]", "_", socket.gethostname())[:64] or "host"
    try:
        return f"{name}.ns{os.stat('/proc/self/ns/pid').st_ino}"
    except OSError:
        return name


#: a temporary folder's name: prefix, owner pid, host, mkdtemp's random part
_TEMP_NAME = re.compile(re.escape(TEMP_PREFIX) + r"(\d+)@([A-Za-z0-9._]+)-[a-z0-9_]+")


def _temp_prefix() -> str:
    """The temporary-folder prefix of this process: the name :data:`_TEMP_NAME` parses."""
    return f"{TEMP_PREFIX}{os.getpid()}@{_host()}-"


def check_writable(path, *, force: bool = False, folder: bool = False) -> Path:
    """Check that `path` may be written (before any work); return it as a Path.

    A symbolic link counts as existing even when it points nowhere.

    Raises
    ------
    FileExistsError
        `path` exists and `force` is false.
    IsADirectoryError
        `path` is a folder, other than a store (:func:`is_store`) or a `folder` output
        (one the caller writes as a whole, such as a mesh's folder of pieces).
    FileNotFoundError
        Its folder does not exist.
    """
    p = Path(path)
    if p.is_dir() and not (is_store(p) or folder):
        raise IsADirectoryError(f"{p} is a folder; give a file name to write.")
    if os.path.lexists(p) and not force:
        what = "already exists" if p.exists() else "already exists (a link to nothing)"
        raise FileExistsError(
            f"{p} {what}; choose another output name, or allow replacing it "
            "(--force on the command line)."
        )
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(
            f"folder {parent} does not exist; create it or choose another output path."
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write in folder {parent}; choose another output path.")
    return p


def is_store(path) -> bool:
    """Whether `path` names a store (a folder written as one output): a ``.zarr`` name."""
    return Path(path).name.lower().endswith(".zarr")


def _umask() -> int:
    # os.umask can only be read by setting it; the lock keeps other threads of this
    # process from creating files in between
    with _UMASK_LOCK:
        mask = os.umask(0o077)
        os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    import psutil  # not os.kill(pid, 0): on Windows that kills

    return psutil.pid_exists(pid)


def remove_stale_temporaries(folder) -> list[Path]:
    """Remove temporary folders in `folder` left by runs of this program that died.

    Only folders named by :func:`atomic_write` (owner pid and host in the name), owned by
    this user, made on this host, whose owner process is no longer alive; a live
    process's folder, this process's own and any other name are kept.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed: list[Path] = []
    host, me = _host(), os.getpid()
    uid = os.geteuid() if hasattr(os, "geteuid") else None
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        match = _TEMP_NAME.fullmatch(entry.name)
        if not match or match.group(2) != host or int(match.group(1)) == me:
            continue
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        mine = uid is None or st.st_uid == uid
        if not stat.S_ISDIR(st.st_mode) or not mine or _alive(int(match.group(1))):
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(Path(entry.path))
    return removed


def _appeared(target: Path) -> FileExistsError:
    return FileExistsError(
        f"{target} appeared while this run was working (another run or program wrote it); "
        "choose another output name, or allow replacing it (--force on the command line).")


def _claim(tmp: Path, target: Path) -> None:
    """Publish `tmp` as `target` only if no `target` exists (FileExistsError otherwise)."""
    if tmp.is_dir():
        os.mkdir(target)        # the claim; FileExistsError if the name is taken
        try:
            os.rename(tmp, target)   # onto the empty folder just made
        except OSError as exc:
            try:
                os.rmdir(target)     # still empty: ours
            except OSError:
                pass
            if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):   # filled meanwhile
                raise _appeared(target) from None
            raise
        return
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise
    except OSError:             # no hard links on this file system: claim the name
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        claim = os.fstat(fd)
        os.close(fd)
        try:
            os.replace(tmp, target)
        except BaseException:
            _withdraw(target, claim)
            raise


def _withdraw(target: Path, published: os.stat_result) -> None:
    """Remove `target` if it is still the very file this run published."""
    try:
        now = os.lstat(target)
    except OSError:
        return
    if (now.st_dev, now.st_ino) != (published.st_dev, published.st_ino):
        return
    if stat.S_ISDIR(now.st_mode):
        shutil.rmtree(target, ignore_errors=True)
    else:
        os.unlink(target)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGTERM and SIGINT back (this thread) while targets are placed: a stop
    arriving then is handled right after, with every target placed or none."""
    held = {signal.SIGTERM, signal.SIGINT}
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _publish(temps: list[Path], targets: list[Path], force: bool) -> None:
    if force:
        for tmp, t in zip(temps, targets):
            if t.is_dir() and not t.is_symlink():   # a store being replaced: set aside
                os.replace(t, tmp.with_name(tmp.name + ".old"))
            os.replace(tmp, t)
        return
    # in one global order (by absolute path): two runs with overlapping targets then meet
    # first at the same name, and exactly one of them gets every name
    order = sorted(zip(temps, targets), key=lambda pair: os.path.abspath(pair[1]))
    done: list[tuple[Path, os.stat_result]] = []
    try:
        for tmp, t in order:
            try:
                _claim(tmp, t)
            except FileExistsError:
                raise _appeared(t) from None
            done.append((t, os.lstat(t)))
    except BaseException:
        for path, st in reversed(done):
            _withdraw(path, st)
        raise


def _disk_full(exc: BaseException | None, folders) -> bool:
    """Whether `exc` (or an error it wraps) says a disk holding `folders` is full."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT):
            return True
        text = str(exc)
        if "No space left on device" in text or "Disk quota exceeded" in text \
                or "errno = 28" in text:
            return True
        if isinstance(exc, OSError) and exc.errno is None and " requested and " in text:
            return True         # numpy's tofile: "4096 requested and 3968 written"
        exc = exc.__cause__ or exc.__context__
    return False


def _size(folder: Path) -> int:
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                pass
    return total


def _full_error(parent: Path, folder: Path | None) -> OSError:
    written = _size(folder) if folder is not None else 0
    amount = f"{written / _MB:.1f} MB" if written >= _MB / 10 else f"{written / 1024:.0f} kB"
    err = OSError(f"the disk holding {parent} is full (it filled after {amount} of output); "
                  "free space there or write elsewhere. Nothing was written.")
    err.errno = errno.ENOSPC
    return err


@contextmanager
def atomic_write(paths: Sequence, *, force: bool = False,
                 folders: Sequence = ()) -> Iterator[list[Path]]:
    """Write several files all or nothing: yield temporary paths, then move them in place.

    The temporary files lie in a hidden folder beside each target and carry the target's
    own file name (so twins such as ``.xdmf``/``.h5`` name each other right). A store
    (:func:`is_store`, a ``.zarr`` folder) is written there as a folder and moved the same
    way (a replaced store is set aside first, then removed). When the block ends without
    an exception every file is given the mode a normal file would get (``0o666`` less the
    umask) and published: without `force` no target is ever replaced, even one that
    another run created while this one worked (then the targets this run already
    published are taken back and FileExistsError is raised); with `force` each is moved
    over its target. On any exception the temporary folder is removed and no target is
    touched. Every output of this package goes through here (the module notes say how).

    Parameters
    ----------
    paths : sequence of str or Path
        The files to write (checked with :func:`check_writable` first).
    force : bool
        Replace existing files.
    folders : sequence of str or Path
        Those of `paths` that are folders the caller makes and fills (published like a
        store).

    Yields
    ------
    list of Path
        One temporary path per target, in order; the caller writes each (a file not
        written is an error).

    Raises
    ------
    FileExistsError
        A target exists, or appeared while the block ran, and `force` is false.
    OSError
        The disk filled up (one sentence; nothing is left behind).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_write([folder / "a.txt"]) as (tmp,):
    ...     _ = tmp.write_text("hello")
    >>> (folder / "a.txt").read_text()
    'hello'
    """
    as_folder = {Path(f) for f in folders}
    targets = [check_writable(p, force=force, folder=Path(p) in as_folder) for p in paths]
    if len({t.resolve() for t in targets}) != len(targets):
        raise ValueError(f"two outputs name the same file ({', '.join(map(str, targets))}); "
                         "give each output its own name.")
    temp_dirs: dict[Path, Path] = {}
    temps: list[Path] = []
    prefix = _temp_prefix()
    parent = Path(".")
    try:
        for t in targets:
            parent = (t.parent if str(t.parent) else Path(".")).resolve()
            if parent not in temp_dirs:
                remove_stale_temporaries(parent)
                temp_dirs[parent] = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
            temps.append(temp_dirs[parent] / t.name)
        yield temps
        missing = [str(t) for t, tmp in zip(targets, temps)
                   if not (tmp.is_dir() if is_store(t) or t in as_folder else tmp.is_file())]
        if missing:
            raise RuntimeError(f"internal error: {', '.join(missing)} not written.")
        mode = 0o666 & ~_umask()
        for tmp in temps:
            os.chmod(tmp, mode | (0o111 & ~_umask() if tmp.is_dir() else 0))
        with _signals_held():
            _publish(temps, targets, force)
    except Exception as exc:
        if isinstance(exc, FileExistsError) or not _disk_full(exc, temp_dirs):
            raise
        full = next((p for p, f in temp_dirs.items() if _size(f)), parent)
        raise _full_error(full, temp_dirs.get(full)) from exc
    finally:
        for folder in temp_dirs.values():
            shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def scratch_folder(parent) -> Iterator[Path]:
    """A hidden folder in `parent`, named and cleaned up like :func:`atomic_write`'s (a
    stale one of a dead owner is removed by a later run), removed when the block ends."""
    folder = Path(tempfile.mkdtemp(prefix=_temp_prefix(),
                                   dir=parent))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def hdf5_file(path) -> Iterator:
    """An h5py ``File`` built in memory, then written to `path` with plain writes.

    HDF5 writing straight onto a disk that fills up keeps failing while its objects are
    released and can crash the interpreter (a segmentation fault); in memory it cannot
    fail that way, and the final write fails with an ordinary ``OSError`` (ENOSPC). Costs
    memory of the file's (compressed) size.
    """
    from ._extras import require

    require("h5py", purpose="writing an HDF5 file")
    import h5py

    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as h5:
        yield h5
    with open(path, "wb") as fh:
        fh.write(buffer.getbuffer())
