"""Outputs that cannot half-exist, and the one way every output is written.

A file (:func:`written`) is written under a temporary name made safely beside its place (created with
exclusive creation, ``O_EXCL``, under a random name by :func:`tempfile.mkstemp`, so that a file or a
symbolic link planted at a guessed name is never followed or reused) and renamed there once whole with
:func:`os.replace`: a full disk or a killed run leaves the old file (or none), never a truncated one.

A run's folder (:func:`staged_folder`) is written whole into a staging folder beside it,
``.NAME.staging-XXXX``, and swapped with the old folder only once the run has finished (an atomic exchange
of the two names where the kernel offers one, ``renameat2(RENAME_EXCHANGE)``; else the old folder is renamed
aside to ``.NAME.old-XXXX`` and the new one renamed in). The old run is then deleted. A run that is killed
leaves the previous complete run in place and its staging folder beside it; the next run into the same
folder deletes that staging folder first (and puts an old folder back that a kill between the two renames
left aside); a run holds a lock on its staging folder (:func:`fcntl.flock`), so that the staging folder of
a run still going is never taken for a killed run's.

:func:`check_output` refuses, before any work, an output path that is a device, a FIFO or a socket (a
rename would replace the node itself: as root, ``--wav /dev/null`` would replace the system's
``/dev/null``), a folder where a file is meant, or one of the run's inputs.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import glob
import os
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Callable, Iterable, Iterator

from agentsim.errors import UsageError

__all__ = ["written", "check_output", "save_figure", "png_bytes", "staged_folder", "staged_page", "check_folder", "clear_staged", "clear_stale",
           "scratch_folder", "clear_scratch",
           "clear_partials", "RUN_FILES"]

#: The files one of which a run's folder holds (a run's figures): a folder with none of them that is not
#: empty is someone else's, which a run never replaces.
RUN_FILES = ("metrics.json", "compare.json")


def _kind(mode: int) -> str | None:
    """What a node that is no regular file or folder is, by its mode, or None."""
    for test, name in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return None


def check_output(path: str | Path, inputs: Iterable[str | Path | None] = (), folder: bool = False) -> None:
    """Raise :class:`UsageError` (one line) if ``path`` may not be written as an output: it is a device, a
    FIFO or a socket; a folder where a file is meant (``folder`` false) or a file where a folder is meant;
    or the same file as one of ``inputs`` (:func:`os.path.samefile`), or (for a folder) holds one of them.
    A symbolic link is judged by what it points at."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):  # a file in the way of its folder is said where it is made
        mode = None
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None
    if mode is not None:
        kind = _kind(mode)
        if kind:
            meant = "folder (name a folder)" if folder else "file (name a regular file)"
            raise UsageError(f"cannot write {path}: it is {kind}, not a {meant}")
        if stat.S_ISDIR(mode) and not folder:
            raise UsageError(f"cannot write {path}: it is a folder")
        if not stat.S_ISDIR(mode) and folder:
            raise UsageError(f"cannot make the output folder {path}: a file of that name is in the way")
    for name in inputs:
        if name is None or str(name) == "-":
            continue
        source = Path(name)
        if folder:  # a run's folder is replaced whole: what it holds (or will hold) is lost
            inside = source.resolve()
            if inside == path.resolve() or path.resolve() in inside.parents:
                raise UsageError(f"cannot write the output folder {path}: it holds the run's input {source}")
        elif mode is not None and source.exists() and os.path.samefile(source, path):
            raise UsageError(f"cannot write {path}: it is one of the run's inputs")


@contextlib.contextmanager
def written(path: str | Path) -> Iterator[Path]:
    """Write a file so that it cannot half-exist: the body writes to the temporary file yielded (made
    beside ``path`` with exclusive creation under a random name, with the same suffix), renamed to ``path``
    once it is whole; if the writing fails (a full disk), the temporary file is removed and ``path`` is left
    as it was. ``path`` is refused (:class:`UsageError`) if it is a device, a FIFO or a folder.

    The writer holds a lock on its temporary file (:func:`fcntl.flock`) while it writes: the temporary files
    of ``path`` whose lock can be got are those of killed writers, and are removed first
    (:func:`clear_stale`). The file is made as :func:`open` would make it (``0666`` less the umask), not
    ``0600`` as :func:`tempfile.mkstemp` makes it.

    >>> with written("out.txt") as tmp:  # doctest: +SKIP
    ...     tmp.write_text("whole")
    """
    path = Path(path)
    with _temporary(path) as tmp:
        yield tmp
        os.replace(tmp, path)


@contextlib.contextmanager
def _temporary(path: Path) -> Iterator[Path]:
    """The temporary file of :func:`written` for ``path``, locked while the body runs and removed if it
    raises; the body renames it into place."""
    import fcntl

    check_output(path)
    parent = path.parent if str(path.parent) else Path(".")
    clear_stale(path)
    fd, name = tempfile.mkstemp(dir=parent, prefix=f".{path.stem}.partial-", suffix=path.suffix)
    tmp = Path(name)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # held until the file is renamed into place or removed
        os.fchmod(fd, 0o666 & ~_umask())
        yield tmp
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    finally:
        os.close(fd)


def clear_stale(path: str | Path) -> list[Path]:
    """Remove the temporary files of :func:`written` for ``path`` (``.STEM.partial-XXXX.SUFFIX`` beside it)
    whose writer is dead: those whose lock can be got at once. A writer still going holds its lock, and its
    file is left alone. Returns what was removed."""
    import fcntl

    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    removed = []
    for leftover in parent.glob(f".{glob.escape(path.stem)}.partial-*{glob.escape(path.suffix)}"):
        try:
            fd = os.open(leftover, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:  # gone, a planted link, or not ours to read
            continue
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # its writer is alive
                continue
            leftover.unlink(missing_ok=True)
            removed.append(leftover)
        finally:
            os.close(fd)
    return removed


def clear_partials(folder: str | Path) -> list[Path]:
    """Remove the temporary files of :func:`written` that a killed process left in ``folder``
    (``.NAME.partial-XXXX.SUFFIX``); returns them."""
    removed = []
    for leftover in Path(folder).glob(".*.partial-*"):
        if leftover.is_file() and not leftover.is_symlink():
            leftover.unlink(missing_ok=True)
            removed.append(leftover)
    return removed


@contextlib.contextmanager
def scratch_folder(prefix: str) -> Iterator[Path]:
    """A folder of scratch files in the system's temporary folder (``PREFIXxxxxxxxx``), removed when the body
    has run. The process holds a lock on it (:func:`fcntl.flock`) while it lives; before it is made, the
    scratch folders of the same prefix that killed processes left (those whose lock can be got at once) are
    removed (:func:`clear_scratch`): a killed ``realize --bvh`` leaves its poses' scratch files (gigabytes of a
    long run) only until the next run that makes such a folder."""
    import fcntl

    clear_scratch(prefix)
    while True:
        folder = Path(tempfile.mkdtemp(prefix=prefix))
        try:
            fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
        except OSError:  # another process's clearing took it before its lock was held: make another
            continue
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            kept = os.path.samestat(os.fstat(fd), os.stat(folder))
        except OSError:
            kept = False
        if kept:
            break
        os.close(fd)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        os.close(fd)


def clear_scratch(prefix: str) -> list[Path]:
    """Remove the scratch folders (:func:`scratch_folder`) of ``prefix`` in the system's temporary folder that
    killed processes of this user left: those whose lock can be got at once. Returns what was removed."""
    removed = []
    for leftover in Path(tempfile.gettempdir()).glob(f"{glob.escape(prefix)}*"):
        try:
            info = os.lstat(leftover)
        except OSError:
            continue
        if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():  # a link, a file, another's
            continue
        with _held(leftover, wait=False) as stale:
            if stale:
                shutil.rmtree(leftover, ignore_errors=True)
                removed.append(leftover)
    return removed


def user_cache(name: str) -> Path:
    """The folder ``name`` of agentsim's cache of this user: ``$XDG_CACHE_HOME/agentsim/NAME``
    (``~/.cache/agentsim/NAME`` where that is not set)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "agentsim" / name


#: zlib's compression level of the PNG pictures :func:`save_figure` writes.
PNG_COMPRESSION = 3


def png_bytes(rgba, dpi: float, texts: dict[str, str] | None = None) -> bytes:
    """A PNG file of 8-bit RGBA pixels (an array of rows x columns x 4) at ``dpi``, with ``texts`` (tEXt
    chunks): rows unfiltered, deflated at :data:`PNG_COMPRESSION`.

    A picture of plots is mostly runs of one colour, which zlib packs as well unfiltered as filtered: the
    file is smaller than Pillow's (which tries five filters on every row and keeps the best) and is
    written in a third of the time."""
    import struct
    import zlib

    import numpy as np

    pixels = np.ascontiguousarray(rgba, dtype=np.uint8)
    rows, columns, channels = pixels.shape
    if channels != 4:
        raise ValueError(f"png_bytes takes RGBA pixels, not {channels} channels")
    raw = np.zeros((rows, 1 + 4 * columns), np.uint8)  # each row: filter type 0 (none), then its pixels
    raw[:, 1:] = pixels.reshape(rows, -1)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    per_metre = int(dpi / 0.0254 + 0.5)
    out = [b"\x89PNG\r\n\x1a\n", chunk(b"IHDR", struct.pack(">IIBBBBB", columns, rows, 8, 6, 0, 0, 0)),
           chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1))]
    out += [chunk(b"tEXt", key.encode("latin-1") + b"\0" + value.encode("latin-1", "replace"))
            for key, value in (texts or {}).items() if value is not None]
    out += [chunk(b"IDAT", zlib.compress(raw.tobytes(), PNG_COMPRESSION)), chunk(b"IEND", b"")]
    return b"".join(out)


#: How :func:`save_figure` has FreeType draw the letters of a PNG (matplotlib's ``text.hinting``, unless the
#: program set it): unhinted, the outlines as they are, which takes a fifth of a picture's time less than the
#: auto-hinter matplotlib uses by default.
TEXT_HINTING = "no_hinting"


def _print_png(canvas, filename_or_obj, *, metadata: dict | None = None, **_) -> None:
    """An Agg canvas's ``print_png`` (what ``savefig`` calls once it has set the figure up) through
    :func:`png_bytes`, with the metadata matplotlib writes, its letters drawn as :data:`TEXT_HINTING` says."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    settings = {}
    if matplotlib.rcParams["text.hinting"] == matplotlib.rcParamsDefault["text.hinting"]:
        settings["text.hinting"] = TEXT_HINTING
    with matplotlib.rc_context(settings):
        FigureCanvasAgg.draw(canvas)
    texts = {"Software": f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/", **(metadata or {})}
    data = png_bytes(canvas.buffer_rgba(), canvas.figure.dpi, texts)
    if isinstance(filename_or_obj, (str, os.PathLike)):
        Path(filename_or_obj).write_bytes(data)
    else:
        filename_or_obj.write(data)


def save_figure(fig, path: str | Path, **options) -> Path:
    """Save a matplotlib figure through :func:`written` (the format from ``path``'s suffix); a PNG of an Agg
    canvas through :func:`png_bytes`."""
    import functools

    path = Path(path)
    kind = path.suffix.lstrip(".").lower() or None
    fast = False
    if kind == "png" and "pil_kwargs" not in options:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        fast = isinstance(fig.canvas, FigureCanvasAgg) and "print_png" not in vars(fig.canvas)
        if fast:  # (savefig takes the canvas's own print_png)
            fig.canvas.print_png = functools.partial(_print_png, fig.canvas)
        else:  # zlib's level 3: three times faster than its default
            options["pil_kwargs"] = {"compress_level": PNG_COMPRESSION}  # for a fifth more bytes, the same pixels
    try:
        with written(path) as tmp:
            fig.savefig(tmp, format=kind, **options)
    finally:
        if fast:
            del fig.canvas.print_png
    return path


# ----------------------------------------------------------------------------------------------------
# A run's folder.


def _exchange(a: Path, b: Path) -> bool:
    """Swap the names ``a`` and ``b`` in one step (Linux ``renameat2(RENAME_EXCHANGE)``); False where the
    kernel, the C library or the file system cannot."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    if ctypes.get_errno() in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()), str(b))


def _siblings(out: Path, kind: str) -> list[Path]:
    parent = out.parent if str(out.parent) else Path(".")
    return sorted(parent.glob(f".{glob.escape(out.name)}.{kind}-*"))


@contextlib.contextmanager
def _held(folder: Path, wait: bool = True) -> Iterator[bool]:
    """Hold a lock on ``folder`` itself (:func:`fcntl.flock` on the folder), yielding whether it was got
    (``wait`` false: at once or not at all). A run holds the lock of its staging folder while it lives, so
    the staging folders whose lock can be got are those of killed runs."""
    import fcntl

    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except OSError:
            yield False
            return
        yield True
    finally:
        os.close(fd)


def clear_staged(out: str | Path) -> list[Path]:
    """Remove what killed runs into ``out`` left: their staging folders, and an old run renamed aside (put
    back first if ``out`` itself is missing: the kill came between the two renames of the swap). The
    folders of runs still going (whose lock is held) are left alone. Returns what was removed."""
    out = Path(out)
    removed = []
    for kind in ("old", "staging"):
        for leftover in _siblings(out, kind):
            with _held(leftover, wait=False) as stale:
                if not stale:
                    continue
                if kind == "old" and not out.exists():
                    os.rename(leftover, out)
                    continue
                shutil.rmtree(leftover, ignore_errors=True)
                removed.append(leftover)
    return removed


def _replaceable(out: Path, marks: Iterable[str]) -> bool:
    """Whether ``out`` may be replaced by a new run: it is empty or holds a run (one of ``marks``)."""
    try:
        entries = os.listdir(out)
    except FileNotFoundError:
        return True
    return not entries or any(name in entries for name in marks)


def check_folder(out: str | Path, inputs: Iterable[str | Path | None] = (), marks: Iterable[str] = RUN_FILES) -> None:
    """Raise :class:`UsageError` (one line) if :func:`staged_folder` may not replace ``out``: it is a file,
    holds one of ``inputs``, or holds files that are no run's (it is neither empty nor holds one of
    ``marks``)."""
    out = Path(out)
    check_output(out, inputs, folder=True)
    if not _replaceable(out, marks):
        raise UsageError(f"cannot write the output folder {out}: it holds files that are not an agentsim run's "
                         f"(name a new or empty folder)")


@contextlib.contextmanager
def staged_folder(out: str | Path, inputs: Iterable[str | Path | None] = (),
                  marks: Iterable[str] = RUN_FILES, before_swap: Callable[[], None] | None = None,
                  after_swap: Callable[[], None] | None = None) -> Iterator[Path]:
    """Stage a run's folder: the body writes into the folder yielded (beside ``out``), which replaces
    ``out`` once the body has returned; if it raises, the staging folder is removed and ``out`` is left as it
    was. ``out`` is refused (:class:`UsageError`) if it is a file, holds one of ``inputs``, or holds files
    that are no run's (a folder that is neither empty nor holds one of ``marks`` is never replaced).
    ``before_swap`` is called once the body has returned, just before the swap; ``after_swap`` once the new
    folder is in place, before the old one is removed."""
    out = Path(out)
    check_folder(out, inputs, marks)
    parent = out.parent if str(out.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        clear_staged(out)
        staging = Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name}.staging-"))
    except OSError as exc:
        raise UsageError(f"cannot write the output folder {out}: {exc.strerror or exc}") from None
    with _held(staging):
        try:
            yield staging
            os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it 0700; a run's folder is as mkdir makes it
            if before_swap is not None:
                before_swap()
            after = after_swap or (lambda: None)
            if not out.exists():
                os.rename(staging, out)
                after()
            elif _exchange(staging, out):
                after()
                shutil.rmtree(staging, ignore_errors=True)  # the old run, now under the staging name
            else:
                aside = Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name}.old-"))
                with _held(aside):
                    os.replace(out, aside)
                    os.rename(staging, out)
                    after()
                    shutil.rmtree(aside, ignore_errors=True)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise


@contextlib.contextmanager
def staged_page(page: str | Path, folder: str | Path, inputs: Iterable[str | Path | None] = (),
                marks: Iterable[str] = ()) -> Iterator[tuple[Path, Path]]:
    """Stage a page and the folder of the files it loads, so that the pair is whole or absent: the body
    writes the page to the temporary file and the files into the staging folder yielded (``(page, folder)``,
    as :func:`written` and :func:`staged_folder` make them). Once the body has returned, the old page is
    removed, the folder swapped in, and the new page renamed into place, in that order: a kill between two
    of these steps leaves no page (the report is absent), never a page over another run's files. If the
    body raises, both are removed and the old pair is left as it was. ``folder`` is refused as
    :func:`staged_folder` refuses it (``marks``: the files of which one marks it as such a folder)."""
    page, folder = Path(page), Path(folder)
    with _temporary(page) as tmp, staged_folder(folder, inputs, marks,
                                                before_swap=lambda: page.unlink(missing_ok=True),
                                                after_swap=lambda: os.replace(tmp, page)) as staging:
        yield tmp, staging


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
