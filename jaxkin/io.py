"""Files in and out of jaxkin: the results of a batch streamed to disk, and configurations read
from files or standard input.

* :class:`ResultWriter` streams named arrays, chunk by chunk, to an uncompressed ``.npz``, a CSV
  file (or standard output) or a directory of ``.npy`` files; the file appears whole under its
  name or not at all. :func:`jaxkin.batch.chunked_map` writes through it (``out=path``).
* :func:`csv_record` and :func:`csv_records` write and read the CSV records it produces (quoted
  names, escaped ``#`` comments) exactly.
* :func:`read_configurations` reads joint configurations ``q`` (and optionally velocities ``qd``)
  from an ``.npz`` or CSV file or standard input, as ``jaxkin velocities --configurations``
  does. Files are untrusted: at most :data:`MAX_INPUT_BYTES` is read from a CSV file or
  standard input, and an ``.npz`` member's declared sizes are checked before it is
  decompressed; every problem with a file is a :class:`~jaxkin.JaxkinError` naming it.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import math
import os
import pathlib
import re
import shutil
import signal
import sys
import threading
import time
import unicodedata
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from .errors import JaxkinError, ShapeError
from .model import Robot

__all__ = [
    "MAX_INPUT_BYTES",
    "ResultWriter",
    "csv_record",
    "csv_records",
    "npy_header",
    "read_configurations",
]

MAX_INPUT_BYTES = 1 << 30
"""The cap, in bytes, on configurations read by :func:`read_configurations` from a CSV file or
standard input (read up to it, never further), and on what a used ``.npz`` member may declare
(its uncompressed size, and its ``.npy`` header's shape x itemsize)."""
STDIN_BLOCK = 1 << 20  # bytes per read from standard input


# ---------------------------------------------------------------------- result files
RESULT_FORMATS = ("npz", "csv", "dir")


class ResultWriter:
    """Named arrays streamed to a file chunk by chunk, appearing complete under ``path`` or not
    at all.

    ``fields`` maps each name to ``(row_shape, dtype)``: the file holds, per name, an array of
    shape ``(n, *row_shape)``, appended in row order by :meth:`append`; ``meta`` adds small
    arrays written whole (labels, settings). Formats (``format=``, default from the suffix):

    * ``"npz"`` (``*.npz``): an uncompressed zip64 ``.npz``. Every member's size is known up
      front, so each is written in place into its own region of the file: no staging copy, the
      disk holds the file once;
    * ``"csv"`` (``*.csv``, or ``path="-"`` for standard output): one line per row; ``columns``
      maps the fields to write to their column names (default: every field, ``name`` or
      ``name_1 ... name_k``), quoted by the ``csv`` module where they hold ``,``, ``"`` or
      line breaks; ``comments`` become ``#`` lines above the header (default: ``meta``), each
      kept on its line: a backslash is doubled and line breaks and other control characters
      are written as Python's escapes (``\\n``, ``\\x1b``, ``\\u2028``).
      :func:`csv_records` reads names and comments back exactly;
    * ``"dir"`` (any other path): a new directory of ``name.npy`` files
      (``np.load(..., mmap_mode="r")`` reads them without loading).

    Everything is written to a temporary sibling of ``path``, named ``.<name>.<random>.tmp``
    (a file, or a directory for ``"dir"``), then flushed, ``fsync``-ed, given ordinary
    permissions (``0o666``/``0o777`` less the umask) and renamed onto ``path``. Use it as a
    context manager: leaving the block without :meth:`commit` (an exception, Ctrl-C, SIGTERM)
    removes the temporary. Inside the block SIGINT and SIGTERM run the handler installed
    before (Python's SIGINT handler raises ``KeyboardInterrupt``) or, where that was the
    default action, raise ``SystemExit(128 + signal)`` (143 for SIGTERM), so that this cleanup
    runs; an exception so raised where Python swallows it (inside a garbage-collector callback)
    is raised again by the next :meth:`append` or :meth:`commit`, so an interrupted run stops
    within a chunk and never commits. SIGXFSZ is ignored so that a file size limit is an
    ``OSError``. The handlers are restored on exit (main thread only; an ignored signal stays
    ignored). Only SIGKILL or a crash can leave the temporary behind.

    The temporary is created on entering the block, before any work: a directory that cannot
    be written (permissions, a read-only file system) raises :class:`~jaxkin.JaxkinError`
    naming it there (and at construction where ``os.access`` already says so).

    Example::

        with ResultWriter("r.npz", {"x": ((2,), "float64")}, n=3, meta={"note": "demo"}) as w:
            w.append({"x": np.ones((2, 2))})
            w.append({"x": np.zeros((1, 2))})
            w.commit()  # r.npz appears, holding x (3, 2) and note
    """

    def __init__(
        self,
        path: Any,
        fields: Mapping[str, tuple[Any, Any]],
        n: int,
        *,
        format: str | None = None,
        meta: Mapping[str, Any] | None = None,
        columns: Mapping[str, Sequence[str]] | None = None,
        comments: Sequence[str] | None = None,
    ) -> None:
        text = os.fspath(path)
        self.format = _result_format(text, format)
        self.path = text if text == "-" else os.path.abspath(text)
        self.fields = {k: (tuple(int(d) for d in s), np.dtype(t)) for k, (s, t) in fields.items()}
        self.meta = {k: np.asarray(v) for k, v in (meta or {}).items()}
        _check_names([*self.fields, *self.meta], self.format)
        self.n, self.rows, self.tmp = int(n), 0, None
        self._saved: list[tuple[int, Any]] = []
        self._pending: BaseException | None = None
        if self.format == "csv":
            columns = columns or {k: _default_columns(k, s) for k, (s, _) in self.fields.items()}
            if comments is None:
                comments = [f"{k} = {v}" for k, v in self.meta.items()]
            self._file: Any = _CsvFile(self.fields, self.n, columns, comments)
        elif self.format == "npz":
            self._file = _NpzFile(self.fields, self.n, self.meta)
        else:
            self._file = _DirFile(self.fields, self.n, self.meta)
        if self.path == "-":
            self._file.open(sys.stdout)
            return
        self._check_target()  # the temporary is created on entering the block (__enter__)

    def _check_target(self) -> None:
        parent = os.path.dirname(self.path)
        if not os.path.isdir(parent):
            raise JaxkinError(
                f"cannot write {self.path}: directory {parent} "
                + ("is not a directory" if os.path.lexists(parent) else "does not exist")
                + "; create it or choose another path."
            )
        if not os.access(parent, os.W_OK | os.X_OK):
            raise _unwritable(self.path, "permission denied")
        if self.format == "dir" and os.path.lexists(self.path):
            raise JaxkinError(f"out {self.path!r} already exists; choose a new path.")
        if os.path.isdir(self.path):
            raise JaxkinError(f"output path {self.path} is a directory; give a file name.")
        need, free = self._file.size_estimate(), shutil.disk_usage(parent).free
        if need > free:
            raise JaxkinError(
                f"cannot write {self.path}: it needs about {_size_text(need)} and {parent} has "
                f"{_size_text(free)} free; write fewer rows or elsewhere."
            )

    def _open(self) -> None:
        parent, name = os.path.split(self.path)
        try:
            for _ in range(100):
                # The name is recorded before the temporary exists: a SIGTERM at any point from
                # here on leaves abort() something to remove (tempfile's mkdtemp and mkstemp
                # return the name only after creating it).
                self.tmp = os.path.join(parent, f".{name}.{os.urandom(4).hex()}.tmp")
                try:
                    if self.format == "dir":
                        os.mkdir(self.tmp, 0o700)
                    else:
                        fd = os.open(self.tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
                    break
                except FileExistsError:  # someone else's: not ours to remove
                    self.tmp = None
            else:
                raise FileExistsError(errno.EEXIST, "no free temporary name", self.path)
            if self.format == "dir":
                self._file.open(self.tmp)
            else:
                self._file.open(os.fdopen(fd, "w+b"))
        except OSError as e:
            self.abort()
            if e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise _unwritable(self.path, e.strerror) from None
            raise OSError(e.errno, e.strerror, self.path) from None
        except BaseException:  # e.g. Ctrl-C: __exit__ does not run when __enter__ raises
            self.abort()
            raise

    def append(self, rows: Mapping[str, Any]) -> None:
        """Append the next rows: ``rows[name]`` of shape ``(k, *row_shape)`` for every field,
        one ``k`` for all."""
        self._check_signal()
        if self._file is None:
            raise JaxkinError(f"ResultWriter for {self.path}: append after commit or abort.")
        self._open_once()  # used without a with-block
        missing = set(self.fields) - set(rows)
        if missing:
            raise ShapeError(f"ResultWriter.append: no rows for field(s) {sorted(missing)}.")
        arrays = {k: np.ascontiguousarray(rows[k], dtype=t) for k, (_, t) in self.fields.items()}
        counts = {a.shape[0] if a.ndim else -1 for a in arrays.values()}
        bad = [k for k, a in arrays.items() if a.shape[1:] != self.fields[k][0]]
        if len(counts) != 1 or bad or self.rows + max(counts) > self.n:
            shapes = {k: a.shape for k, a in arrays.items()}
            raise ShapeError(
                f"ResultWriter.append: rows of shapes {shapes} do not fit fields "
                f"{ {k: s for k, (s, _) in self.fields.items()} } with {self.n - self.rows} of "
                f"{self.n} rows left; give (k, *row_shape) arrays, one k for all."
            )
        self._io(self._file.append, arrays)
        self.rows += counts.pop()

    def commit(self) -> str:
        """Finish the file and rename it onto ``path`` (replacing a previous file); returns
        ``path``. Every one of the ``n`` rows must have been appended."""
        self._check_signal()
        if self._file is None:
            raise JaxkinError(f"ResultWriter for {self.path}: commit after commit or abort.")
        if self.rows != self.n:
            raise JaxkinError(
                f"ResultWriter for {self.path}: {self.rows} of {self.n} rows were appended; "
                "nothing was written."
            )
        self._open_once()  # n == 0 without a with-block
        self._io(self._file.close)
        self._file = None
        if self.tmp is not None:
            self._io(self._publish)
        return self.path

    def _publish(self) -> None:
        mask = _umask()
        os.chmod(self.tmp, (0o777 if self.format == "dir" else 0o666) & ~mask)
        os.replace(self.tmp, self.path)
        self.tmp = None
        _fsync_dir(os.path.dirname(self.path))

    def _io(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run a write step; an OSError names ``path`` (not the temporary)."""
        try:
            return fn(*args)
        except OSError as e:
            raise OSError(e.errno, e.strerror, self.path) from None

    def abort(self) -> None:
        """Remove the temporary; ``path`` is left as it was (idempotent)."""
        if self._file is not None:
            with contextlib.suppress(OSError):
                self._file.discard()
            self._file = None
        if self.tmp is not None:
            if os.path.isdir(self.tmp):
                shutil.rmtree(self.tmp, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.remove(self.tmp)
            self.tmp = None

    def __enter__(self) -> ResultWriter:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._saved.append((sig, signal.getsignal(sig)))
                if self._saved[-1][1] != signal.SIG_IGN:
                    signal.signal(sig, self._interrupted)
            if hasattr(signal, "SIGXFSZ"):
                self._saved.append((signal.SIGXFSZ, signal.signal(signal.SIGXFSZ, signal.SIG_IGN)))
        # Only now, with the handlers in place: a SIGTERM can no longer find a temporary that
        # nothing would remove.
        try:
            self._open_once()
        except BaseException:  # __exit__ does not run when __enter__ raises: restore here
            self.__exit__(*sys.exc_info())
            raise
        return self

    def _open_once(self) -> None:
        if self.path != "-" and self.tmp is None and self._file is not None:
            self._open()

    def _interrupted(self, signum: int, frame: Any) -> None:
        """SIGINT and SIGTERM: run the handler installed before (SIGINT's raises
        KeyboardInterrupt), or raise ``SystemExit(128 + signum)`` where it was the default."""
        previous = dict(self._saved)[signum]
        try:
            if not callable(previous):
                raise SystemExit(128 + signum)
            previous(signum, frame)
        except BaseException as e:
            # Python may run this inside a gc or __del__ callback (JAX has some), which swallows
            # exceptions: kept, the next append or commit raises it again.
            self._pending = e
            raise

    def _check_signal(self) -> None:
        if self._pending is not None:
            raise self._pending

    def __exit__(self, *exc: Any) -> None:
        try:
            self.abort()
        finally:
            for sig, handler in reversed(self._saved):
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)
            self._saved = []


def _unwritable(path: str, why: str | None) -> JaxkinError:
    parent = os.path.dirname(path)
    return JaxkinError(
        f"cannot write {path}: directory {parent} is not writable ({why}); choose a directory "
        "you can write to, or make it writable."
    )


def _size_text(nbytes: float) -> str:
    """``nbytes`` in the unit that fits: ``"512 bytes"``, ``"1.5 kB"``, ``"2.3 MB"``, ``"4.0 GB"``,
    ``"1.2 TB"`` (decimal units: 1 kB = 1000 bytes, as ``df -H`` counts)."""
    if nbytes < 1000:
        return f"{int(nbytes)} bytes"
    for unit in ("kB", "MB", "GB"):
        nbytes /= 1000
        if nbytes < 999.95:
            return f"{nbytes:.1f} {unit}"
    return f"{nbytes / 1000:,.1f} TB"


def _result_format(path: str, format: str | None) -> str:
    suffix = "csv" if path == "-" else os.path.splitext(path)[1].lower().lstrip(".")
    if format is None:
        return suffix if suffix in ("npz", "csv") else "dir"
    if format not in RESULT_FORMATS:
        raise JaxkinError(f"format must be one of {RESULT_FORMATS}, got {format!r}.")
    if (suffix in ("npz", "csv") and suffix != format) or (path == "-" and format != "csv"):
        where = "standard output ('-')" if path == "-" else f"{path!r}"
        raise JaxkinError(
            f"format {format!r} contradicts {where}: "
            + ("only csv goes to standard output" if path == "-" else f"a .{suffix} name")
            + "; change the name or the format."
        )
    return format


def _check_names(names: list[str], fmt: str) -> None:
    seen: dict[str, str] = {}
    for name in names:
        if not name or not all(c.isalnum() or c in "_-." for c in name) or name[0] == ".":
            raise JaxkinError(
                f"cannot write an array named {name!r}: use letters, digits, '_', '-' and '.'."
            )
        key = name.lower() if fmt == "dir" else name  # case-insensitive file systems
        if key in seen:
            raise JaxkinError(f"two arrays would be written as {name!r} ({seen[key]!r}).")
        seen[key] = name


def _default_columns(name: str, shape: tuple[int, ...]) -> list[str]:
    k = math.prod(shape)
    return [name] if shape == () else [f"{name}_{i + 1}" for i in range(k)]


def _umask() -> int:
    """The process umask, read without changing it where /proc allows."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_dir(path: str) -> None:
    with contextlib.suppress(OSError):  # not every platform opens directories
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _npy_header(shape: tuple[int, ...], dtype: np.dtype) -> bytes:
    buf = io.BytesIO()
    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": shape}
    np.lib.format.write_array_header_2_0(buf, header)
    return buf.getvalue()


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array, allow_pickle=False)
    return buf.getvalue()


def _row_bytes(shape: tuple[int, ...], dtype: np.dtype) -> int:
    return math.prod(shape) * dtype.itemsize


class _NpzFile:
    """An uncompressed zip64 npz whose members are written in place: each member's local
    header and size are laid out when opened, chunks go to each member's next free offset,
    CRCs are patched into the headers and the central directory is appended at close."""

    def __init__(self, fields: dict, n: int, meta: dict[str, np.ndarray]) -> None:
        self.members = [(k, _npy_bytes(v), 0) for k, v in meta.items()]
        for k, (shape, dtype) in fields.items():
            self.members.append((k, _npy_header((n, *shape), dtype), n * _row_bytes(shape, dtype)))

    def size_estimate(self) -> int:
        return sum(len(head) + size + 200 for _, head, size in self.members)

    def open(self, f: Any) -> None:
        self.f, self.infos, self.at, self.crc, pos = f, [], {}, {}, 0
        stamp = time.localtime()[:6]
        for name, head, size in self.members:
            info = zipfile.ZipInfo(f"{name}.npy", date_time=stamp)
            info.file_size = info.compress_size = len(head) + size
            info.CRC = 0  # patched at close
            info.header_offset = pos
            local = info.FileHeader(zip64=True)
            f.seek(pos)
            f.write(local + head)
            self.infos.append(info)
            self.at[name], self.crc[name] = pos + len(local) + len(head), zlib.crc32(head)
            pos += len(local) + info.file_size
        self.end = pos

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        for name, a in arrays.items():
            self.f.seek(self.at[name])
            self.f.write(memoryview(a).cast("B"))
            self.at[name] += a.nbytes
            self.crc[name] = zlib.crc32(memoryview(a).cast("B"), self.crc[name])

    def close(self) -> None:
        for info, (name, _, _) in zip(self.infos, self.members, strict=True):
            info.CRC = self.crc[name]
            self.f.seek(info.header_offset)
            self.f.write(info.FileHeader(zip64=True))
        self.f.seek(self.end)
        zf = zipfile.ZipFile(self.f, "w", allowZip64=True)  # writes the central directory only
        zf.filelist.extend(self.infos)
        zf.NameToInfo.update({i.filename: i for i in self.infos})
        zf.close()
        _sync_close(self.f)

    def discard(self) -> None:
        if hasattr(self, "f"):  # not opened when the temporary could not be created
            self.f.close()


def csv_records(
    lines: Iterable[str], *, source: Any = "csv", comments: list[str] | None = None
) -> Iterator[tuple[int, list[str]]]:
    """The records of CSV text such as a :class:`ResultWriter` writes: ``(line, fields)``.

    ``lines``: a text file opened with ``newline=""`` (so that quoted fields keep their line
    breaks) or any iterable of lines with their ends. Records are parsed by the ``csv`` module
    (quoted fields may hold ``,``, ``"`` and line breaks) and ``fields`` are returned as
    written, not stripped; ``line`` is the number of the record's first line. Comments and
    blank lines are recognised only where a record starts, never inside a quoted field: a
    blank line is skipped; a line whose first non-blank character is ``#`` is a comment, and
    when ``comments`` is a list its text (after ``#`` and one space, escapes such as ``\\n``
    undone: see :class:`ResultWriter`) is appended to it.

    Raises:
      JaxkinError: malformed CSV (``strict`` parsing: a quoted field never closed, or text
        after a closing quote), naming ``source`` and the line.

    >>> list(csv_records(['# a note\\n', 'x,"y, z"\\n', '\\n', '1,2\\n']))
    [(2, ['x', 'y, z']), (4, ['1', '2'])]
    """
    at = {"start": True, "line": 0, "first": 0}

    def record_lines() -> Iterator[str]:
        for number, line in enumerate(lines, start=1):
            at["line"] = number
            if at["start"]:
                head = line.lstrip()
                if not head:
                    continue
                if head.startswith("#"):
                    if comments is not None:
                        comments.append(_comment_text(head))
                    continue
                at["start"], at["first"] = False, number
            yield line

    reader = csv.reader(record_lines(), strict=True)
    while True:
        try:
            fields = next(reader)
        except StopIteration:
            return
        except csv.Error as e:
            raise JaxkinError(f"{source} line {at['line']}: {e}; check its quotes.") from None
        at["start"] = True
        yield at["first"], fields


def csv_record(fields: Sequence[str]) -> str:
    """``fields`` as one CSV record ending in ``\\n``, which :func:`csv_records` reads back as
    they are (a :class:`ResultWriter`'s header is one).

    Quoted by the ``csv`` module where a field holds ``,``, ``"``, ``\\r`` or ``\\n``; every
    field is quoted where the record would otherwise read as a comment (``#`` first), a blank
    line or a byte order mark.

    >>> csv_record(["x", "y, z", "#"])
    'x,"y, z",#\\n'
    >>> csv_record(["#a", "b"])
    '"#a","b"\\n'
    """
    buf = io.StringIO()
    # "\r\n": the csv module quotes fields holding its line terminator's characters (not others)
    csv.writer(buf, lineterminator="\r\n").writerow(fields)
    text = buf.getvalue()
    if not text.strip() or text.lstrip().startswith("#") or text.startswith("\ufeff"):
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\r\n", quoting=csv.QUOTE_ALL).writerow(fields)
        text = buf.getvalue()
    return text[: -len("\r\n")] + "\n"


_ESCAPES = {"\\": "\\", "\n": "n", "\r": "r", "\t": "t"}
_UNESCAPES = {v: k for k, v in _ESCAPES.items()}
_ESCAPED = re.compile(r"\\(?:[\\nrt]|x[0-9a-fA-F]{2}|u[0-9a-fA-F]{4}|U[0-9a-fA-F]{8})")


def _escape_comment(text: str) -> str:
    """``text`` on one line, reversibly: a backslash is doubled; line breaks and other control
    or format characters (Unicode categories Cc, Cf, Zl, Zp, Cs) become Python's escapes
    ``\\n``, ``\\r``, ``\\t``, ``\\xNN``, ``\\uNNNN``, ``\\UNNNNNNNN``
    (:func:`_comment_text` undoes them)."""
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append("\\" + _ESCAPES[c])
        elif unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp", "Cs"):
            k = ord(c)
            width = 2 if k < 0x100 else 4 if k < 0x10000 else 8
            out.append(f"\\{'xuU'[width // 4]}{k:0{width}x}")
        else:
            out.append(c)
    return "".join(out)


def _comment_text(line: str) -> str:
    """The text of a ``#`` comment line as :func:`_escape_comment` wrote it."""
    text = line[1:].rstrip("\r\n")
    text = text[1:] if text.startswith(" ") else text

    def unescape(m: re.Match[str]) -> str:
        code = m.group()[1:]
        if code in _UNESCAPES:
            return _UNESCAPES[code]
        k = int(code[1:], 16)
        return chr(k) if k <= sys.maxunicode else m.group()

    return _ESCAPED.sub(unescape, text)


def _sync_close(f: Any) -> None:
    f.flush()
    os.fsync(f.fileno())
    f.close()


class _DirFile:
    """A directory of ``.npy`` files, one per field, each appended chunk by chunk."""

    def __init__(self, fields: dict, n: int, meta: dict[str, np.ndarray]) -> None:
        self.fields, self.n, self.meta, self.files = fields, n, meta, {}

    def size_estimate(self) -> int:
        rows = sum(self.n * _row_bytes(s, t) + 256 for s, t in self.fields.values())
        return rows + sum(v.nbytes + 256 for v in self.meta.values())

    def open(self, directory: str) -> None:
        self.directory = directory
        for name, value in self.meta.items():
            with open(os.path.join(directory, f"{name}.npy"), "wb") as f:
                f.write(_npy_bytes(value))
                f.flush()
                os.fsync(f.fileno())
        for name, (shape, dtype) in self.fields.items():
            self.files[name] = open(os.path.join(directory, f"{name}.npy"), "wb")
            self.files[name].write(_npy_header((self.n, *shape), dtype))

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        for name, a in arrays.items():
            self.files[name].write(memoryview(a).cast("B"))

    def close(self) -> None:
        for f in self.files.values():
            _sync_close(f)
        _fsync_dir(self.directory)

    def discard(self) -> None:
        for f in self.files.values():
            f.close()


class _CsvFile:
    """One text line per row: the ``columns`` fields side by side, ``%.17g`` (float64) or
    ``%.9g`` (float32), so values round-trip; ``comments`` as ``#`` lines on top, each escaped
    onto its line (:func:`_escape_comment`); the header quoted by the ``csv`` module
    (:func:`csv_record`). :func:`csv_records` reads all of it back as written."""

    def __init__(
        self, fields: dict, n: int, columns: Mapping[str, Sequence[str]], comments
    ) -> None:
        unknown = set(columns) - set(fields)
        if unknown:
            raise JaxkinError(f"csv columns name unknown fields {sorted(unknown)}.")
        for name, names in columns.items():
            if len(names) != math.prod(fields[name][0]):
                raise JaxkinError(
                    f"csv: field {name!r} has {math.prod(fields[name][0])} values per row, "
                    f"but {len(names)} column names."
                )
        self.columns, self.comments = dict(columns), [str(c) for c in comments]
        self.names = [str(c) for cols in self.columns.values() for c in cols]
        for c in self.names:
            try:
                c.encode("utf-8")
            except UnicodeEncodeError:
                raise JaxkinError(
                    f"csv: column name {c!r} holds a lone surrogate, which UTF-8 cannot "
                    "carry; rename the column."
                ) from None
        wide = any(fields[k][1] == np.float64 for k in self.columns)
        self.digits, self.n_values = (17 if wide else 9), sum(map(len, self.columns.values()))
        self.n = n

    def size_estimate(self) -> int:
        return self.n * self.n_values * (self.digits + 7)  # sign, point, exponent, comma

    def open(self, f: Any) -> None:
        self.f = f
        lines = [f"# {_escape_comment(c)}\n" for c in self.comments]
        self._write("".join(lines) + csv_record(self.names))

    def _write(self, text: str) -> None:
        self.f.write(text if isinstance(self.f, io.TextIOBase) else text.encode())

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        k = next(iter(arrays.values())).shape[0]
        if k == 0:  # reshape(0, -1) is ambiguous
            return
        table = np.concatenate([arrays[c].reshape(k, -1) for c in self.columns], axis=1)
        buf = io.StringIO()
        np.savetxt(buf, table, fmt=f"%.{self.digits}g", delimiter=",")
        self._write(buf.getvalue())

    def close(self) -> None:
        if isinstance(self.f, io.TextIOBase):  # standard output
            self.f.flush()
        else:
            _sync_close(self.f)

    def discard(self) -> None:
        if hasattr(self, "f") and not isinstance(self.f, io.TextIOBase):
            self.f.close()


# ---------------------------------------------------------------------- configuration files
def read_configurations(
    path: str, robot: Robot, dtype: Any = np.float64
) -> tuple[np.ndarray, np.ndarray | None]:
    """Joint configurations ``q`` and optionally joint velocities ``qd`` of ``robot``, read from
    a file or from standard input (``path="-"``), as ``jaxkin velocities --configurations``
    reads them.

    Layouts:

    * ``.npz`` (by suffix; on standard input, data starting like a zip): an array ``q`` of shape
      ``(N, dof)`` (or ``(dof,)`` for one configuration) and optionally ``qd`` of the same shape,
      numbers of any dtype. No other member is read and nothing is unpickled; each used
      member's declared sizes (the zip member's uncompressed size, its ``.npy`` header's shape x
      itemsize) must be at most :data:`MAX_INPUT_BYTES`, checked before it is decompressed.
    * CSV (any other suffix, at most :data:`MAX_INPUT_BYTES`): one configuration per record,
      read by :func:`csv_records` (quoted fields, ``#`` comments, a UTF-8 byte order mark).
      Without a header a record holds ``dof`` values (``q``) or ``2 dof`` values (``q`` then
      ``qd``) in ``robot.joint_names`` order. With a header its columns are joint names (or
      ``q_<joint>``) and optionally ``qd_<joint>`` for every joint, in any order, each once; a
      first column with an empty name (R's row names) is skipped.

    Values are used as given (outside the joint limits too) but must be finite.

    Args:
      path: a file path, or ``"-"`` for standard input (read up to :data:`MAX_INPUT_BYTES`,
        never further).
      robot: the robot whose joints the columns are.
      dtype: the dtype of the arrays returned.

    Returns:
      ``(q, qd)``: arrays of shape ``(N, dof)`` and ``dtype``, rows in file order, columns in
      ``robot.joint_names`` order; ``qd`` is None when the file holds none.

    Raises:
      JaxkinError: the file is missing, unreadable, over a cap, malformed, of the wrong shape
        or holds a non-finite value or no configuration; the message names the file (and the
        line, for CSV).

    >>> import pathlib, tempfile, jaxkin as jk
    >>> from jaxkin.io import read_configurations
    >>> robot = jk.robots.load("two_link_planar")  # joints joint1, joint2
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder, "q.csv")
    ...     _ = path.write_text("qd_joint2,joint1,joint2,qd_joint1\\n0.5,0.1,0.2,-1\\n")
    ...     q, qd = read_configurations(str(path), robot)
    >>> q.tolist(), qd.tolist()
    ([[0.1, 0.2]], [[-1.0, 0.5]])
    """
    if path == "-":
        data = _read_stdin()
        if data[:2] == b"PK":
            q, qd = _read_npz(io.BytesIO(data), "standard input", robot)
        else:
            text = io.StringIO(data.decode("utf-8-sig", errors="replace"), newline="")
            q, qd = _read_csv(text, "standard input", robot)
    else:
        q, qd = _read_file(pathlib.Path(path), robot)
    for name, a in (("q", q), ("qd", qd)):
        if a is None:
            continue
        bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
        if bad.size:
            raise JaxkinError(
                f"{path}: {name} of configuration {int(bad[0])} is not finite: {a[bad[0]].tolist()}"
            )
    if len(q) == 0:
        raise JaxkinError(f"{path} holds no configurations")
    return q.astype(dtype), None if qd is None else qd.astype(dtype)


def _read_stdin() -> bytes:
    """Standard input, read block by block: at most ``MAX_INPUT_BYTES`` (an endless stream is
    refused once it passes the cap, never held whole)."""
    stream = getattr(sys.stdin, "buffer", sys.stdin)
    blocks, size = [], 0
    while size <= MAX_INPUT_BYTES:
        block = stream.read(min(STDIN_BLOCK, MAX_INPUT_BYTES + 1 - size))
        if not block:
            break
        block = block.encode() if isinstance(block, str) else block
        blocks.append(block)
        size += len(block)
    if size > MAX_INPUT_BYTES:
        raise JaxkinError(
            f"standard input holds more than {_iec_size(MAX_INPUT_BYTES)} (the cap on "
            "configurations read, MAX_INPUT_BYTES); pass a file (--configurations PATH: a CSV up "
            "to the cap, an .npz whose q and qd are each up to it) or split the input"
        )
    return b"".join(blocks)


def _iec_size(n: int) -> str:
    """``n`` bytes in the binary unit that fits (``1 GiB``, ``12.5 MiB``, ``300 bytes``), as the
    caps on input are stated (:func:`_size_text` states disk space in decimal units)."""
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:,.1f}".removesuffix(".0") + f" {unit}"
    return f"{n:,} bytes"


def _read_file(p: pathlib.Path, robot: Robot):
    if not p.is_file():
        raise JaxkinError(
            f"configurations file {p} " + ("is not a file" if p.exists() else "does not exist")
        )
    try:
        if p.suffix.lower() == ".npz":
            return _read_npz(p, p, robot)
        size = p.stat().st_size
        if size > MAX_INPUT_BYTES:
            raise JaxkinError(
                f"configurations file {p} is {_iec_size(size)}, over the "
                f"{_iec_size(MAX_INPUT_BYTES)} cap on a CSV file (MAX_INPUT_BYTES); split it, or "
                "save q (and qd) with numpy.savez"
            )
        # utf-8-sig: Excel's byte order mark; newline="": quoted fields may hold line breaks
        with open(p, encoding="utf-8-sig", errors="replace", newline="") as f:
            return _read_csv(f, p, robot)
    except OSError as e:
        raise JaxkinError(f"cannot read {p}: {e.strerror or e}") from None


def _joint_shape_error(path, what: str, got: tuple, robot: Robot) -> JaxkinError:
    return JaxkinError(
        f"{path}: {what} has shape {got}; robot {robot.name!r} has {robot.dof} joints "
        f"({', '.join(robot.joint_names)}), so it must be (N, {robot.dof})"
    )


def _read_npz(source: Any, p: Any, robot: Robot):
    """``(q, qd or None)`` from the members ``q`` and ``qd`` of an .npz; no other member is
    read, and each used one is sized (:func:`_npz_member`) before it is decompressed."""
    if not zipfile.is_zipfile(source):
        raise JaxkinError(f"{p} is not an .npz file (numpy.savez writes one); or use a .csv file")
    try:
        with np.load(source, allow_pickle=False) as f:
            if "q" not in f.files:
                raise JaxkinError(
                    f"{p} has no array 'q' (it has {sorted(f.files) or 'none'}); save q of shape "
                    "(N, dof)"
                )
            arrays = {k: _npz_member(f, k, p) for k in ("q", "qd") if k in f.files}
    # zlib.error: corrupt data; RuntimeError: an encrypted member; NotImplementedError: a
    # compression method zipfile lacks
    except (ValueError, zipfile.BadZipFile, EOFError, zlib.error, RuntimeError,
            NotImplementedError) as e:  # fmt: skip
        raise JaxkinError(f"cannot read {p} as .npz: {e}") from None
    out = []
    for name in ("q", "qd"):
        a = arrays.get(name)
        if a is None:
            out.append(None)
            continue
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise JaxkinError(f"{p}: {name} must hold numbers, got dtype {a.dtype}")
        a = a.astype(np.float64)
        if a.ndim == 1:
            a = a[None]
        if a.ndim != 2 or a.shape[1] != robot.dof:
            raise _joint_shape_error(p, name, arrays[name].shape, robot)
        out.append(a)
    if out[1] is not None and out[1].shape != out[0].shape:
        raise JaxkinError(
            f"{p}: qd has shape {out[1].shape} but q has {out[0].shape}; they must match"
        )
    return out[0], out[1]


def npy_header(fp: Any) -> tuple[tuple[int, ...], bool, np.dtype]:
    """``(shape, fortran_order, dtype)`` that the ``.npy`` stream ``fp`` declares, read from its
    header alone (nothing is allocated: check sizes before numpy reads the data). Leaves ``fp``
    at the first data byte."""
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fp)
    return np.lib.format.read_array_header_2_0(fp)


def _npz_member(f: Any, key: str, p: Any) -> np.ndarray:
    """The array ``key`` of the open .npz ``f``, read only when its declared sizes fit: the
    zip's uncompressed size of the member and its .npy header's shape x itemsize, each at most
    ``MAX_INPUT_BYTES`` (numpy allocates what the header declares before reading)."""
    member = f"{key}.npy" if f"{key}.npy" in f.zip.namelist() else key
    declared = f.zip.getinfo(member).file_size
    with f.zip.open(member) as fp:
        shape, _, dtype = npy_header(fp)
    nbytes = math.prod(shape) * dtype.itemsize
    if max(declared, nbytes) > MAX_INPUT_BYTES:
        raise JaxkinError(
            f"{p}: array {key!r} declares {_iec_size(max(declared, nbytes))} (shape {shape}, "
            f"dtype {dtype}), over the {_iec_size(MAX_INPUT_BYTES)} cap on configurations read "
            "(MAX_INPUT_BYTES); split the configurations into several files"
        )
    if nbytes > declared:
        raise JaxkinError(
            f"{p}: array {key!r} declares shape {shape} ({_iec_size(nbytes)}) but its member holds "
            f"{_iec_size(declared)}; the file is corrupt"
        )
    return f[key]


def _read_csv(f: Any, p: Any, robot: Robot):
    """Rows of a CSV text stream (:func:`csv_records`: the ``csv`` module, so
    quoted fields as R and jaxkin write them; ``#`` comment lines and blank lines between
    records): ``(q, qd or None)``. Numbers may be surrounded by blanks."""
    header, rows = None, []
    for lineno, fields in csv_records(f, source=p):
        try:
            rows.append((lineno, [float(x) for x in fields]))
        except ValueError:
            if header is None and not rows:
                header = fields
                continue
            raise JaxkinError(
                f"{p} line {lineno}: not a row of numbers: {','.join(fields)[:80]!r}"
            ) from None
    if header and header[0].strip() == "":  # R's write.csv: a first column of row names
        header, rows = header[1:], [(i, r[1:]) for i, r in rows]
    order = None if header is None else _csv_columns(header, p, robot)
    width = None if header is None else len(header)
    table = []
    for lineno, values in rows:
        if width is not None and len(values) != width:
            raise JaxkinError(f"{p} line {lineno}: {len(values)} values, the header has {width}")
        if width is None and len(values) not in (robot.dof, 2 * robot.dof):
            raise JaxkinError(
                f"{p} line {lineno}: {len(values)} values; robot {robot.name!r} has {robot.dof} "
                f"joints ({', '.join(robot.joint_names)}): give {robot.dof} (q) or "
                f"{2 * robot.dof} (q, qd)"
            )
        table.append([values[k] for k in order] if order is not None else values)
    if not table:
        raise JaxkinError(f"{p} holds no configurations")
    if width is None and len({len(r) for r in table}) > 1:
        raise JaxkinError(f"{p}: rows mix {robot.dof} and {2 * robot.dof} values; use one layout")
    a = np.array(table, dtype=np.float64)
    if a.shape[1] == 2 * robot.dof:
        return a[:, : robot.dof], a[:, robot.dof :]
    return a, None


def _csv_columns(header: list[str], p: Any, robot: Robot) -> list[int]:
    """Column indices of q (then qd, if given) in joint order, from a header line: joint names
    or ``q_<joint>``, and optionally ``qd_<joint>``. A column matches as written, else with
    surrounding blanks removed; where every column reads as ``q_<joint>`` or ``qd_<joint>``
    (as jaxkin writes them), that reading wins over a joint named like the column."""
    names = list(robot.joint_names)

    def prefixed(h: str) -> tuple[str, str] | None:
        if h.startswith("qd_") and h[3:] in names:
            return ("qd", h[3:])
        return ("q", h[2:]) if h.startswith("q_") and h[2:] in names else None

    def named(h: str) -> tuple[str, str] | None:
        if h.startswith("qd_") and h[3:] in names:
            return ("qd", h[3:])
        return ("q", h) if h in names else prefixed(h)

    read = prefixed if all(prefixed(h) or prefixed(h.strip()) for h in header) else named
    columns: dict[tuple[str, str], int] = {}
    for k, h in enumerate(header):
        key = read(h) or read(h.strip())
        if key is None:
            raise JaxkinError(
                f"{p}: unknown column {h!r}; columns are joint names {names} (or q_<joint>) "
                "and optionally qd_<joint>"
            )
        if key in columns:
            raise JaxkinError(
                f"{p}: column {h!r} duplicates column {header[columns[key]]!r} (both give "
                f"{key[0]} of joint {key[1]!r}); keep one"
            )
        columns[key] = k
    missing = [n for n in names if ("q", n) not in columns]
    if missing:
        raise JaxkinError(f"{p}: no column for joint(s) {missing} of robot {robot.name!r}")
    has_qd = any(k[0] == "qd" for k in columns)
    if has_qd and not all(("qd", n) in columns for n in names):
        raise JaxkinError(f"{p}: give qd_<joint> for every joint {names} or for none")
    return [columns[("q", n)] for n in names] + (
        [columns[("qd", n)] for n in names] if has_qd else []
    )
